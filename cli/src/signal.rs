//! The signals that stop a long-running command: Ctrl-C (SIGINT) from a terminal, SIGTERM
//! from a service manager, `docker stop` or Kubernetes; and SIGUSR1, which asks a worker to
//! drain (Slurm sends it before a job's time limit with `--signal=USR1@SECONDS`).

/// Completes when the process receives SIGINT or SIGTERM.
pub async fn interrupted() {
    #[cfg(unix)]
    {
        use tokio::signal::unix::{signal, SignalKind};
        match signal(SignalKind::terminate()) {
            Ok(mut term) => {
                tokio::select! {
                    _ = tokio::signal::ctrl_c() => {}
                    _ = term.recv() => {}
                }
            }
            Err(_) => {
                let _ = tokio::signal::ctrl_c().await;
            }
        }
    }
    #[cfg(not(unix))]
    {
        let _ = tokio::signal::ctrl_c().await;
    }
}

/// Completes when the process receives SIGUSR1 (never where there is no such signal).
pub async fn drain_asked() {
    #[cfg(unix)]
    {
        use tokio::signal::unix::{signal, SignalKind};
        if let Ok(mut usr1) = signal(SignalKind::user_defined1()) {
            usr1.recv().await;
            return;
        }
    }
    std::future::pending::<()>().await
}

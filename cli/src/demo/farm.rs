//! The demo's farm on this machine: `tessera worker` child processes (stopped with their
//! parent, also on a panic) and the server on this process's runtime. `tessera bench`'s
//! farm measurements run on the same pieces.

use std::fs::File;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

use anyhow::Context;
use tokio::sync::oneshot;
use tokio::task::JoinHandle;

/// How long the server gets to finish its open requests after the workers are gone.
const SERVER_GRACE: Duration = Duration::from_secs(5);
/// The demo's lease: shorter than a farm's, so a crashed worker's tile is re-queued soon.
const DEMO_LEASE: Duration = Duration::from_secs(20);

/// One worker child process.
pub(super) struct WorkerProcess {
    pub(super) name: String,
    child: Child,
    pub(super) log: PathBuf,
    /// Set once it has exited (and been reaped).
    pub(super) exited: Option<ExitStatus>,
}

/// The demo's worker processes. Dropping it stops them, so that no worker outlives the demo
/// on an error or a panic; on Linux they also get SIGTERM if the demo itself is killed.
pub(crate) struct Workers {
    pub(super) procs: Vec<WorkerProcess>,
}

impl Workers {
    /// Starts `n` workers of `threads` threads each against `server`.
    pub(crate) fn spawn(
        server: &str,
        n: u32,
        threads: u32,
        cache: &Path,
        logs: &Path,
    ) -> anyhow::Result<Workers> {
        let mut workers = Workers { procs: Vec::new() };
        for k in 1..=n {
            let name = format!("demo-{k}");
            let log = logs.join(format!("worker-{k}.log"));
            let mut cmd = tessera_command(&log)?;
            cmd.arg("worker")
                .arg("--server")
                .arg(server)
                .arg("--threads")
                .arg(threads.to_string())
                .arg("--cache")
                .arg(cache)
                .arg("--name")
                .arg(&name);
            let child = cmd.spawn().with_context(|| {
                format!(
                    "starting worker {name} ({})",
                    cmd.get_program().to_string_lossy()
                )
            })?;
            workers.procs.push(WorkerProcess {
                name,
                child,
                log,
                exited: None,
            });
        }
        Ok(workers)
    }

    /// The process ids of the workers.
    pub(crate) fn pids(&self) -> Vec<u32> {
        self.procs.iter().map(|p| p.child.id()).collect()
    }

    /// Workers that have exited since the last call, reaped.
    pub(super) fn newly_exited(&mut self) -> Vec<&WorkerProcess> {
        let mut fresh = Vec::new();
        for (i, p) in self.procs.iter_mut().enumerate() {
            if p.exited.is_none() {
                if let Ok(Some(status)) = p.child.try_wait() {
                    p.exited = Some(status);
                    fresh.push(i);
                }
            }
        }
        fresh.into_iter().map(|i| &self.procs[i]).collect()
    }

    pub(super) fn running(&self) -> usize {
        self.procs.iter().filter(|p| p.exited.is_none()).count()
    }

    /// SIGTERM to every running worker (each gives its lease back and exits), then waits up
    /// to `grace`; whoever is still running after that is killed. Returns the names of the
    /// killed ones.
    pub(crate) fn stop(&mut self, grace: Duration) -> Vec<String> {
        for p in &mut self.procs {
            if p.exited.is_none() {
                if let Ok(Some(status)) = p.child.try_wait() {
                    p.exited = Some(status);
                } else {
                    terminate(&mut p.child);
                }
            }
        }
        let deadline = Instant::now() + grace;
        while self.running() > 0 && Instant::now() < deadline {
            self.newly_exited();
            std::thread::sleep(Duration::from_millis(25));
        }
        let mut killed = Vec::new();
        for p in &mut self.procs {
            if p.exited.is_none() {
                let _ = p.child.kill();
                p.exited = p.child.wait().ok();
                killed.push(p.name.clone());
            }
        }
        killed
    }
}

impl Drop for Workers {
    fn drop(&mut self) {
        self.stop(Duration::from_secs(2));
    }
}

/// A command running this `tessera` executable as a child of the demo or a benchmark: its
/// output goes to `log` as plain text, it sees none of a deployment's `TESSERA_*` settings
/// (the caller's own farm is not the deployment's), and it is set up by
/// [`configure_child`].
pub(crate) fn tessera_command(log: &Path) -> anyhow::Result<Command> {
    let exe = std::env::current_exe().context("finding the tessera executable")?;
    let out = File::create(log).with_context(|| format!("creating {}", log.display()))?;
    let err = out.try_clone()?;
    let mut cmd = Command::new(exe);
    for (name, _) in std::env::vars_os() {
        if name.to_string_lossy().starts_with("TESSERA_") {
            cmd.env_remove(name);
        }
    }
    cmd.env("NO_COLOR", "1")
        .stdin(Stdio::null())
        .stdout(out)
        .stderr(err);
    configure_child(&mut cmd);
    Ok(cmd)
}

/// Workers run in their own process group, so a Ctrl-C at the terminal reaches only the
/// demo, which then stops them in order; on Linux they are also sent SIGTERM when the demo
/// dies without cleaning up (SIGKILL, say).
#[cfg(unix)]
fn configure_child(cmd: &mut Command) {
    use std::os::unix::process::CommandExt;
    cmd.process_group(0);
    #[cfg(target_os = "linux")]
    // SAFETY: prctl is async-signal-safe and touches only the child's own settings. The
    // parent-death signal fires when the spawning *thread* exits: workers are spawned from
    // the main thread, which lives as long as the process.
    unsafe {
        cmd.pre_exec(|| {
            if libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGTERM) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            Ok(())
        });
    }
}

#[cfg(not(unix))]
fn configure_child(_cmd: &mut Command) {}

/// Asks a worker to stop: SIGTERM, so it gives its lease back first.
#[cfg(unix)]
pub(crate) fn terminate(child: &mut Child) {
    // SAFETY: kill(2) with a pid we spawned and have not reaped yet (so it cannot have been
    // reused).
    unsafe {
        libc::kill(child.id() as libc::pid_t, libc::SIGTERM);
    }
}

#[cfg(not(unix))]
pub(crate) fn terminate(child: &mut Child) {
    let _ = child.kill();
}

/// The last `n` lines of a log file, for an error message.
pub(super) fn tail(path: &Path, n: usize) -> String {
    let text = std::fs::read_to_string(path).unwrap_or_default();
    let lines: Vec<&str> = text.lines().collect();
    lines[lines.len().saturating_sub(n)..].join("\n")
}

/// The farm server, running on this process's runtime.
pub(crate) struct LocalServer {
    pub(crate) url: String,
    pub(super) task: JoinHandle<Result<(), server::StartError>>,
    stop: Option<oneshot::Sender<()>>,
}

impl LocalServer {
    pub(crate) async fn start(data: &Path) -> anyhow::Result<LocalServer> {
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0")
            .await
            .context("binding a loopback port for the demo server")?;
        let url = format!("http://{}", listener.local_addr()?);
        let mut config = server::Config::new(data);
        config.listen = listener.local_addr()?;
        config.lease = DEMO_LEASE;
        let (stop, stopped) = oneshot::channel::<()>();
        tracing::info!("Tessera demo farm on {url} (data in {})", data.display());
        let task = tokio::spawn(server::serve(listener, config, async {
            let _ = stopped.await;
        }));
        Ok(LocalServer {
            url,
            task,
            stop: Some(stop),
        })
    }

    /// Stops accepting, lets open requests finish for up to [`SERVER_GRACE`].
    pub(crate) async fn shutdown(mut self) -> anyhow::Result<()> {
        if let Some(stop) = self.stop.take() {
            let _ = stop.send(());
        }
        match tokio::time::timeout(SERVER_GRACE, &mut self.task).await {
            Ok(Ok(result)) => result.context("the demo server"),
            Ok(Err(join)) => Err(anyhow::anyhow!("the demo server panicked: {join}")),
            // A browser keeping the dashboard's event stream open, say.
            Err(_) => {
                self.task.abort();
                Ok(())
            }
        }
    }
}

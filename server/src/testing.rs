//! A server on a thread and runtime of its own, for the tests of the server and of the
//! worker (feature `test-server`): it can stop gracefully, or be killed as `kill -9` would
//! (every task dropped at once; only what SQLite committed survives).

use std::path::PathBuf;
use std::sync::mpsc;
use std::thread::JoinHandle;
use std::time::Duration;

use crate::Config;

/// How long a graceful stop may take before the runtime is dropped anyway.
const STOP_TIMEOUT: Duration = Duration::from_secs(5);

/// A running server; stopped gracefully when dropped unless [`TestServer::kill_on_drop`].
pub struct TestServer {
    /// `http://127.0.0.1:PORT`.
    pub base: String,
    /// Its data folder.
    pub data: PathBuf,
    kill_on_drop: bool,
    /// `true`: stop gracefully; `false`: kill.
    stop: Option<mpsc::Sender<bool>>,
    thread: Option<JoinHandle<()>>,
}

impl TestServer {
    /// Starts a server on 127.0.0.1 at a free port (`config.listen` is ignored).
    pub fn start(config: Config) -> TestServer {
        let listener = std::net::TcpListener::bind("127.0.0.1:0").expect("a free loopback port");
        TestServer::start_on(listener, config)
    }

    /// Starts a server on `listener` (to restart one on the port it had).
    pub fn start_on(listener: std::net::TcpListener, config: Config) -> TestServer {
        let addr = listener.local_addr().expect("a bound listener");
        listener
            .set_nonblocking(true)
            .expect("the listener goes non-blocking");
        let data = config.data_dir.clone();
        let (stop_tx, stop_rx) = mpsc::channel::<bool>();
        let thread = std::thread::spawn(move || {
            let rt = tokio::runtime::Builder::new_multi_thread()
                .worker_threads(2)
                .enable_all()
                .build()
                .expect("a tokio runtime");
            let (tx, rx) = tokio::sync::oneshot::channel::<()>();
            rt.spawn(async move {
                let listener =
                    tokio::net::TcpListener::from_std(listener).expect("a tokio listener");
                crate::serve(listener, config, async {
                    let _ = rx.await;
                })
                .await
                .expect("the test server serves");
            });
            if stop_rx.recv().unwrap_or(true) {
                let _ = tx.send(());
                rt.shutdown_timeout(STOP_TIMEOUT);
            } else {
                rt.shutdown_background();
            }
        });
        TestServer {
            base: format!("http://{addr}"),
            data,
            kill_on_drop: false,
            stop: Some(stop_tx),
            thread: Some(thread),
        }
    }

    /// Kill rather than stop it when dropped: a worker's open long poll would hold a
    /// graceful stop for up to [`STOP_TIMEOUT`].
    pub fn kill_on_drop(mut self) -> TestServer {
        self.kill_on_drop = true;
        self
    }

    /// Kills the server now: every connection drops at once.
    pub fn crash(mut self) {
        self.end(false);
    }

    /// The URL of an API route (`path` after `/api/v1`).
    pub fn url(&self, path: &str) -> String {
        format!("{}/api/v1{path}", self.base)
    }

    fn end(&mut self, graceful: bool) {
        if let Some(stop) = self.stop.take() {
            let _ = stop.send(graceful);
        }
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

impl Drop for TestServer {
    fn drop(&mut self) {
        self.end(!self.kill_on_drop);
    }
}

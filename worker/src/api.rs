//! The farm's worker routes as typed calls. Each call makes one attempt and answers with
//! an outcome enum for what the protocol table in [`proto::worker`] says can happen, or an
//! [`ApiError`]; `Api::retry` repeats a call through network errors and 5xx answers.
//!
//! Answers every call shares: 401 is [`ApiError::Unauthorized`] (the token is wrong: no
//! retry helps), 404 on a worker route is [`ApiError::UnknownWorker`] (the server forgot
//! this worker, e.g. its data folder was replaced: register again), a failed connection or
//! a 5xx is transient.

use std::error::Error as _;
use std::future::Future;
use std::path::Path;
use std::sync::Arc;
use std::time::Duration;

use anyhow::Context;
use proto::{
    ErrorBody, FailureAck, FailureReport, Heartbeat, HeartbeatAck, Lease, LeaseRequest, LogLine,
    ResultAck, ResultMetadata, TaskLogLines, TaskToken, WorkerLeft, WorkerRegistered,
    WorkerRegistration,
};
use reqwest::{RequestBuilder, Response, StatusCode};

use crate::backoff::{seconds, Backoff};
use crate::stop::Stop;

/// How long a connection may take to open.
const CONNECT_TIMEOUT: Duration = Duration::from_secs(10);
/// How long a short call (register, heartbeat, failure, leave) may take in all.
const CALL_TIMEOUT: Duration = Duration::from_secs(30);
/// How much longer than its wait a long-poll lease request may take.
const LEASE_SLACK: Duration = Duration::from_secs(30);
/// How long a scene download or a tile upload may take.
const TRANSFER_TIMEOUT: Duration = Duration::from_secs(600);

/// How long a call that is allowed to finish after shutdown began may still take.
pub const SHUTDOWN_GRACE: Duration = Duration::from_secs(5);

/// What `Api::retry` does with a try in flight when shutdown begins.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum InFlight {
    /// Drop it at once.
    Drop,
    /// Let it finish within [`SHUTDOWN_GRACE`].
    Finish,
}

/// Why a call did not get an answer the protocol expects.
#[derive(Debug, thiserror::Error)]
pub enum ApiError {
    /// No answer: connection refused or reset, timeout, DNS. Transient.
    #[error("server {server} unreachable ({cause})")]
    Unreachable {
        /// The server's base URL.
        server: String,
        /// What went wrong, shortly (`connection refused`).
        cause: String,
    },
    /// A 5xx (or 408/429) answer. Transient.
    #[error("server {server} answered {status}: {message}")]
    Server {
        /// The server's base URL.
        server: String,
        /// The HTTP status.
        status: StatusCode,
        /// The error body's message, if any.
        message: String,
    },
    /// 401: the worker token is missing or wrong.
    #[error(
        "server {server} refused the worker token (401 Unauthorized): pass the farm's \
         worker token with --token or TESSERA_WORKER_TOKEN"
    )]
    Unauthorized {
        /// The server's base URL.
        server: String,
    },
    /// 409 on registering: a live worker has this name. Transient: that worker may be
    /// this machine's previous process, gone silent.
    #[error("{message}")]
    NameInUse {
        /// The server's message.
        message: String,
    },
    /// 404 on a worker route: the server does not know this worker id (any more).
    #[error("{message}")]
    UnknownWorker {
        /// The server's message.
        message: String,
    },
    /// Any other answer: a bug on one side, or a resource that is gone (a scene 404).
    #[error("{what}: server answered {status}: {message}")]
    Unexpected {
        /// The call.
        what: &'static str,
        /// The HTTP status.
        status: StatusCode,
        /// The error body's message, if any.
        message: String,
    },
}

impl ApiError {
    /// Whether trying again later may succeed.
    pub fn is_transient(&self) -> bool {
        matches!(
            self,
            ApiError::Unreachable { .. } | ApiError::Server { .. } | ApiError::NameInUse { .. }
        )
    }
}

/// `POST /workers/{id}/lease`.
#[derive(Clone, Debug, PartialEq)]
pub enum LeaseAnswer {
    /// 200: a task to render.
    Assigned(Box<Lease>),
    /// 204: no work within the wait; ask again.
    NoWork,
}

/// `POST /workers/{id}/heartbeat`.
#[derive(Clone, Debug, PartialEq)]
pub enum HeartbeatAnswer {
    /// 200: the lease is extended.
    Extended(HeartbeatAck),
    /// 409: the lease is gone (paused, cancelled, expired): stop rendering.
    LeaseGone(String),
}

/// `POST /workers/{id}/tasks/{task}/result`.
#[derive(Clone, Debug, PartialEq)]
pub enum UploadAnswer {
    /// 200: stored (`accepted: false` for a repeat of a finished task, which is fine).
    Stored(ResultAck),
    /// 409: the lease is gone; the tile is dropped.
    LeaseGone(String),
    /// 413 or 422: the server refused the tile; the message says why.
    Refused(String),
}

/// `POST /workers/{id}/tasks/{task}/failure`.
#[derive(Clone, Debug, PartialEq)]
pub enum FailureAnswer {
    /// 200: recorded.
    Recorded(FailureAck),
    /// 409: the lease is gone anyway.
    LeaseGone(String),
}

/// An HTTP client for one server's worker routes.
#[derive(Clone, Debug)]
pub struct Api {
    http: reqwest::Client,
    /// Base URL plus `/api/v1`.
    base: Arc<str>,
    /// The server's base URL, for messages.
    server: Arc<str>,
    /// The join token: it registers.
    token: Option<Arc<str>>,
    /// This worker's own credential, once registered: every other call carries it.
    credential: Arc<std::sync::RwLock<Option<Arc<str>>>>,
}

/// An HTTP client for a farm server that says it is `user_agent`. An https:// server's
/// certificate must chain to a public root (Mozilla's, built in) or to a certificate in
/// `ca`, a PEM file: the private CA that signed the server's own certificate.
pub fn http_client(user_agent: &str, ca: Option<&Path>) -> anyhow::Result<reqwest::Client> {
    let mut builder = reqwest::Client::builder()
        .connect_timeout(CONNECT_TIMEOUT)
        .user_agent(user_agent);
    if let Some(ca) = ca {
        let pem = std::fs::read(ca).with_context(|| format!("--ca {}", ca.display()))?;
        let certs = reqwest::Certificate::from_pem_bundle(&pem)
            .with_context(|| format!("--ca {}: not PEM certificates", ca.display()))?;
        anyhow::ensure!(
            !certs.is_empty(),
            "--ca {}: no PEM certificate in it",
            ca.display()
        );
        for cert in certs {
            builder = builder.add_root_certificate(cert);
        }
    }
    builder.build().context("setting up the HTTP client")
}

impl Api {
    /// A client for `server` (base URL) whose API lives at `api_base`, trusting the
    /// certificates in `ca` besides the public roots ([`http_client`]).
    pub fn new(
        server: &str,
        api_base: &str,
        token: Option<&str>,
        ca: Option<&Path>,
    ) -> anyhow::Result<Api> {
        let http = http_client(concat!("tessera-worker/", env!("CARGO_PKG_VERSION")), ca)?;
        Ok(Api {
            http,
            base: api_base.into(),
            server: server.trim_end_matches('/').into(),
            token: token.map(Into::into),
            credential: Arc::default(),
        })
    }

    /// The server's base URL.
    pub fn server(&self) -> &str {
        &self.server
    }

    fn post(&self, path: &str, timeout: Duration) -> RequestBuilder {
        self.auth(
            self.http
                .post(format!("{}{path}", self.base))
                .timeout(timeout),
        )
    }

    /// Adds the worker's credential, or before it has one the join token.
    fn auth(&self, r: RequestBuilder) -> RequestBuilder {
        let credential = self
            .credential
            .read()
            .unwrap_or_else(|p| p.into_inner())
            .clone();
        match credential.or_else(|| self.token.clone()) {
            Some(t) => r.bearer_auth(t),
            None => r,
        }
    }

    async fn send(&self, r: RequestBuilder) -> Result<Response, ApiError> {
        let res = r.send().await.map_err(|e| self.unreachable(&e))?;
        let status = res.status();
        if status == StatusCode::UNAUTHORIZED {
            return Err(ApiError::Unauthorized {
                server: self.server.to_string(),
            });
        }
        if status.is_server_error()
            || status == StatusCode::REQUEST_TIMEOUT
            || status == StatusCode::TOO_MANY_REQUESTS
        {
            return Err(ApiError::Server {
                server: self.server.to_string(),
                status,
                message: message(res).await,
            });
        }
        Ok(res)
    }

    fn unreachable(&self, e: &reqwest::Error) -> ApiError {
        ApiError::Unreachable {
            server: self.server.to_string(),
            cause: explained(&self.server, e),
        }
    }

    async fn json<T: serde::de::DeserializeOwned>(
        &self,
        what: &'static str,
        res: Response,
    ) -> Result<T, ApiError> {
        let status = res.status();
        // A body cut short by a dropped connection is a network error, not a bug.
        let bytes = res.bytes().await.map_err(|e| self.unreachable(&e))?;
        serde_json::from_slice(&bytes).map_err(|e| ApiError::Unexpected {
            what,
            status,
            message: format!("unreadable answer: {e}"),
        })
    }

    /// `POST /workers` with the join token; from then on every call carries the
    /// credential it answers.
    pub async fn register(&self, reg: &WorkerRegistration) -> Result<WorkerRegistered, ApiError> {
        let mut req = self
            .http
            .post(format!("{}/workers", self.base))
            .timeout(CALL_TIMEOUT)
            .json(reg);
        if let Some(t) = &self.token {
            req = req.bearer_auth(t);
        }
        let res = self.send(req).await?;
        match res.status() {
            StatusCode::CREATED | StatusCode::OK => {
                let registered: WorkerRegistered = self.json("register", res).await?;
                *self.credential.write().unwrap_or_else(|p| p.into_inner()) =
                    Some(registered.credential.as_str().into());
                Ok(registered)
            }
            // Another live worker has this name: it may be this machine's previous
            // process, not yet gone; wait for it, saying why.
            StatusCode::CONFLICT => Err(ApiError::NameInUse {
                message: message(res).await,
            }),
            status => Err(unexpected("register", status, res).await),
        }
    }

    /// `POST /workers/{id}/lease`, waiting up to `wait` for work, with the previous lease's
    /// last log lines.
    pub async fn lease(
        &self,
        worker: u64,
        wait: Duration,
        last_task_log: Option<TaskLogLines>,
    ) -> Result<LeaseAnswer, ApiError> {
        let req = self
            .post(&format!("/workers/{worker}/lease"), wait + LEASE_SLACK)
            .json(&LeaseRequest {
                wait_seconds: wait.as_secs(),
                last_task_log,
            });
        let res = self.send(req).await?;
        match res.status() {
            StatusCode::OK => Ok(LeaseAnswer::Assigned(Box::new(
                self.json("lease", res).await?,
            ))),
            StatusCode::NO_CONTENT => Ok(LeaseAnswer::NoWork),
            StatusCode::NOT_FOUND => Err(unknown_worker(res).await),
            status => Err(unexpected("lease", status, res).await),
        }
    }

    /// `POST /workers/{id}/heartbeat` for the lease `token`, with the lines logged for it
    /// since the last one.
    pub async fn heartbeat(
        &self,
        worker: u64,
        token: TaskToken,
        log: Vec<LogLine>,
    ) -> Result<HeartbeatAnswer, ApiError> {
        let req = self
            .post(&format!("/workers/{worker}/heartbeat"), CALL_TIMEOUT)
            .json(&Heartbeat {
                token: Some(token),
                log,
            });
        let res = self.send(req).await?;
        match res.status() {
            StatusCode::OK => Ok(HeartbeatAnswer::Extended(
                self.json("heartbeat", res).await?,
            )),
            StatusCode::CONFLICT => Ok(HeartbeatAnswer::LeaseGone(message(res).await)),
            StatusCode::NOT_FOUND => Err(unknown_worker(res).await),
            status => Err(unexpected("heartbeat", status, res).await),
        }
    }

    /// `GET /scenes/{digest}`: the scene's GLB bytes (unverified).
    pub async fn scene(&self, digest: &str) -> Result<Vec<u8>, ApiError> {
        let req = self.auth(
            self.http
                .get(format!("{}/scenes/{digest}", self.base))
                .timeout(TRANSFER_TIMEOUT),
        );
        let res = self.send(req).await?;
        match res.status() {
            StatusCode::OK => Ok(res
                .bytes()
                .await
                .map_err(|e| self.unreachable(&e))?
                .to_vec()),
            status => Err(unexpected("scene download", status, res).await),
        }
    }

    /// `GET /workers/{id}/tasks/{task}/frame`: what a step after rendering reads, the
    /// assembled EXR of a denoise lease's frame, or the PNG of `frame` for an encode
    /// lease; `None` when the lease is gone.
    pub async fn frame(
        &self,
        worker: u64,
        token: TaskToken,
        frame: Option<i32>,
    ) -> Result<Option<Vec<u8>>, ApiError> {
        let frame = frame.map_or(String::new(), |f| format!("&frame={f}"));
        let req = self.auth(
            self.http
                .get(format!(
                    "{}/workers/{worker}/tasks/{}/frame?attempt={}{frame}",
                    self.base, token.task_id, token.attempt
                ))
                .timeout(TRANSFER_TIMEOUT),
        );
        let res = self.send(req).await?;
        match res.status() {
            StatusCode::OK => Ok(Some(
                res.bytes()
                    .await
                    .map_err(|e| self.unreachable(&e))?
                    .to_vec(),
            )),
            StatusCode::CONFLICT => Ok(None),
            StatusCode::NOT_FOUND => Err(unknown_worker(res).await),
            status => Err(unexpected("frame download", status, res).await),
        }
    }

    /// `POST /workers/{id}/tasks/{task}/result` with the tile's EXR bytes.
    pub async fn upload(
        &self,
        worker: u64,
        task: u64,
        meta: &ResultMetadata,
        exr: Vec<u8>,
    ) -> Result<UploadAnswer, ApiError> {
        let mut req = self
            .post(
                &format!("/workers/{worker}/tasks/{task}/result"),
                TRANSFER_TIMEOUT,
            )
            .header(reqwest::header::CONTENT_TYPE, "image/x-exr");
        for (name, value) in meta.to_headers() {
            req = req.header(name, value);
        }
        let res = self.send(req.body(exr)).await?;
        match res.status() {
            StatusCode::OK => Ok(UploadAnswer::Stored(self.json("upload", res).await?)),
            StatusCode::CONFLICT => Ok(UploadAnswer::LeaseGone(message(res).await)),
            StatusCode::UNPROCESSABLE_ENTITY | StatusCode::PAYLOAD_TOO_LARGE => {
                Ok(UploadAnswer::Refused(message(res).await))
            }
            StatusCode::NOT_FOUND => Err(unknown_worker(res).await),
            status => Err(unexpected("upload", status, res).await),
        }
    }

    /// `POST /workers/{id}/tasks/{task}/failure`, with the lines logged for the lease since
    /// its last heartbeat.
    pub async fn failure(
        &self,
        worker: u64,
        token: TaskToken,
        message_text: &str,
        log: Vec<LogLine>,
    ) -> Result<FailureAnswer, ApiError> {
        let req = self
            .post(
                &format!("/workers/{worker}/tasks/{}/failure", token.task_id),
                CALL_TIMEOUT,
            )
            .json(&FailureReport {
                attempt: token.attempt,
                message: message_text.to_string(),
                log,
            });
        let res = self.send(req).await?;
        match res.status() {
            StatusCode::OK => Ok(FailureAnswer::Recorded(self.json("failure", res).await?)),
            StatusCode::CONFLICT => Ok(FailureAnswer::LeaseGone(message(res).await)),
            StatusCode::NOT_FOUND => Err(unknown_worker(res).await),
            status => Err(unexpected("failure report", status, res).await),
        }
    }

    /// `POST /workers/{id}/leave`: every lease the worker holds is queued again.
    pub async fn leave(&self, worker: u64) -> Result<WorkerLeft, ApiError> {
        let res = self
            .send(self.post(&format!("/workers/{worker}/leave"), CALL_TIMEOUT))
            .await?;
        match res.status() {
            StatusCode::OK => self.json("leave", res).await,
            StatusCode::NOT_FOUND => Err(unknown_worker(res).await),
            status => Err(unexpected("leave", status, res).await),
        }
    }

    /// Runs `call` until it answers or fails for a reason other than a transient one,
    /// waiting with [`Backoff`] between tries; `Ok(None)` when shutdown began first.
    /// Logs one line per failed try (the waits grow, so the lines slow down) and one when
    /// the server answers again.
    ///
    /// Shutdown drops a try in flight at once, except with [`InFlight::Finish`], which
    /// gives it [`SHUTDOWN_GRACE`] more and makes a first try even after shutdown began
    /// (an upload of a finished tile is worth one try; it is not repeated after shutdown).
    pub(crate) async fn retry<T, F, Fut>(
        &self,
        what: &str,
        stop: &Stop,
        in_flight: InFlight,
        mut call: F,
    ) -> Result<Option<T>, ApiError>
    where
        F: FnMut() -> Fut,
        Fut: Future<Output = Result<T, ApiError>>,
    {
        let mut backoff = Backoff::new();
        let mut first = true;
        loop {
            if stop.is_set() && !(first && in_flight == InFlight::Finish) {
                return Ok(None);
            }
            first = false;
            let stopped = async {
                stop.wait().await;
                if in_flight == InFlight::Finish {
                    tokio::time::sleep(SHUTDOWN_GRACE).await;
                }
            };
            let result = tokio::select! {
                r = call() => r,
                _ = stopped => return Ok(None),
            };
            match result {
                Err(e) if e.is_transient() => {
                    let delay = backoff.next_delay();
                    tracing::warn!("{what}: {e}; retrying in {}", seconds(delay));
                    tokio::select! {
                        _ = tokio::time::sleep(delay) => {}
                        _ = stop.wait() => return Ok(None),
                    }
                }
                other => {
                    if backoff.failures() > 0 {
                        tracing::info!(
                            "server {} answers again (after {} failed tries)",
                            self.server,
                            backoff.failures()
                        );
                    }
                    return other.map(Some);
                }
            }
        }
    }
}

/// The message of an error body, or the status text when the body is not one.
async fn message(res: Response) -> String {
    let status = res.status();
    match res.bytes().await {
        Ok(bytes) => match serde_json::from_slice::<ErrorBody>(&bytes) {
            Ok(body) => body.message,
            Err(_) if !bytes.is_empty() => {
                String::from_utf8_lossy(&bytes).chars().take(300).collect()
            }
            Err(_) => status.to_string(),
        },
        Err(_) => status.to_string(),
    }
}

async fn unknown_worker(res: Response) -> ApiError {
    ApiError::UnknownWorker {
        message: message(res).await,
    }
}

async fn unexpected(what: &'static str, status: StatusCode, res: Response) -> ApiError {
    ApiError::Unexpected {
        what,
        status,
        message: message(res).await,
    }
}

/// A short cause for a failed request: `connection refused`, `timed out`, or the
/// innermost error's words.
/// What to do about a connection that failed with `cause` on the way to `server`, when it
/// is a TLS mix-up: an untrusted certificate, or plain HTTP spoken to an HTTPS port.
pub fn tls_hint(server: &str, cause: &str) -> Option<&'static str> {
    if cause.contains("certificate") {
        Some(
            "the server's certificate is not trusted here: if a private CA signed it, pass \
             that CA's certificate with --ca (or TESSERA_CA)",
        )
    } else if server.starts_with("http://") && cause.contains("invalid HTTP version") {
        Some("the server may be serving HTTPS (--tls-cert): use an https:// URL")
    } else {
        None
    }
}

/// [`cause`] with its [`tls_hint`], if any.
fn explained(server: &str, e: &reqwest::Error) -> String {
    let cause = cause(e);
    match tls_hint(server, &cause) {
        Some(hint) => format!("{cause}; {hint}"),
        None => cause,
    }
}

fn cause(e: &reqwest::Error) -> String {
    if e.is_timeout() {
        return "timed out".into();
    }
    let mut innermost = e.to_string();
    let mut source = e.source();
    while let Some(s) = source {
        if let Some(io) = s.downcast_ref::<std::io::Error>() {
            use std::io::ErrorKind::*;
            return match io.kind() {
                ConnectionRefused => "connection refused".into(),
                ConnectionReset => "connection reset".into(),
                ConnectionAborted => "connection aborted".into(),
                TimedOut => "timed out".into(),
                _ => io.to_string(),
            };
        }
        innermost = s.to_string();
        source = s.source();
    }
    innermost
}

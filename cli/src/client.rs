//! A small client of the farm's REST API (`/api/v1`), for `submit`, `status`, the job
//! controls, `workers` and `demo`: one method per route, typed with the `proto` wire types.
//! Every failure becomes a [`ClientError`] whose message a person can act on: the server's
//! own `message` (and the field at fault) for an error answer, and a hint to start
//! `tessera server` when nothing answers.

use std::fmt;
use std::path::{Path, PathBuf};
use std::time::Duration;

use proto::{
    ErrorBody, FailureList, FrameList, GcReport, GcRequest, JobEvent, JobEventList, JobList,
    JobSpec, JobStatus, PriorityChange, Rerender, SceneInfo, TaskLog, WorkerInfo, WorkerList,
};
use reqwest::{Method, RequestBuilder, StatusCode};
use serde::de::DeserializeOwned;

/// A job as the command line names it: by id, or by the name it was given.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum JobRef {
    /// Its id.
    Id(u64),
    /// Its name (`--name` at submission, or `job <id>`).
    Name(String),
}

impl std::str::FromStr for JobRef {
    type Err = String;

    fn from_str(s: &str) -> Result<JobRef, String> {
        let s = s.trim();
        if s.is_empty() {
            return Err("give a job id or name".into());
        }
        if s.bytes().all(|b| b.is_ascii_digit()) {
            return s
                .parse()
                .map(JobRef::Id)
                .map_err(|_| format!("job id {s} is too large"));
        }
        Ok(JobRef::Name(s.to_string()))
    }
}

impl fmt::Display for JobRef {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            JobRef::Id(id) => write!(f, "{id}"),
            JobRef::Name(name) => write!(f, "`{name}`"),
        }
    }
}

/// The value of the unlabelled gauge `name` in Prometheus' text format, as a count.
fn parse_gauge(text: &str, name: &str) -> Option<u64> {
    text.lines().find_map(|line| {
        let value = line.strip_prefix(name)?.strip_prefix(' ')?;
        let value: f64 = value.split_whitespace().next()?.parse().ok()?;
        (value.is_finite() && value >= 0.0).then_some(value as u64)
    })
}

/// Where `submit`, `status` and the rest look for the server when not told.
pub const DEFAULT_SERVER: &str = "http://127.0.0.1:8700";

/// The longest a JSON request may take. Uploads and downloads have no total limit: a
/// large scene on a slow link may take minutes, and the connection itself reports death.
const JSON_TIMEOUT: Duration = Duration::from_secs(60);

/// Why a request failed.
#[derive(Debug)]
pub enum ClientError {
    /// Nothing answered at the server's address (refused, unresolvable, timed out).
    Unreachable {
        /// The server's base URL.
        server: String,
        /// What the network layer said.
        detail: String,
    },
    /// The server answered with an error status.
    Api {
        /// The HTTP status.
        status: StatusCode,
        /// The JSON error body, when the answer had one.
        body: Option<ErrorBody>,
        /// What was asked, e.g. `POST /api/v1/jobs`.
        request: String,
    },
    /// The request failed after connecting, or the answer could not be read.
    Transport {
        /// What was asked.
        request: String,
        /// What went wrong.
        detail: String,
    },
}

impl ClientError {
    /// The HTTP status of an error answer.
    pub fn status(&self) -> Option<StatusCode> {
        match self {
            ClientError::Api { status, .. } => Some(*status),
            _ => None,
        }
    }
}

impl fmt::Display for ClientError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ClientError::Unreachable { server, detail } => write!(
                f,
                "cannot reach the Tessera server at {server}: {detail}; is `tessera server` \
                 running? (set the address with --server or TESSERA_SERVER)"
            ),
            ClientError::Api {
                status: StatusCode::UNAUTHORIZED,
                ..
            } => write!(
                f,
                "the server refused the client token (401 Unauthorized): pass the server's \
                 --client-token with --token or TESSERA_CLIENT_TOKEN"
            ),
            ClientError::Api {
                status,
                body: Some(body),
                ..
            } => {
                write!(f, "{}", body.message)?;
                // The server's message usually starts with the field already.
                if let Some(field) = &body.field {
                    if !body.message.starts_with(field.as_str()) {
                        write!(f, " (field `{field}`)")?;
                    }
                }
                write!(f, " [{}]", status.as_u16())
            }
            ClientError::Api {
                status,
                body: None,
                request,
            } => write!(f, "{request}: the server answered {status}"),
            ClientError::Transport { request, detail } => write!(f, "{request}: {detail}"),
        }
    }
}

impl std::error::Error for ClientError {}

/// The innermost cause of an error: for a refused connection "Connection refused (os
/// error 111)" rather than reqwest's "error sending request for url ...".
fn root_cause(e: &(dyn std::error::Error + 'static)) -> String {
    let mut cause = e;
    while let Some(next) = cause.source() {
        cause = next;
    }
    cause.to_string()
}

/// Where the server is and how to prove who we are: the flags every client command takes.
#[derive(clap::Args, Clone, Debug)]
pub struct ServerOpts {
    /// The farm server's URL.
    #[arg(long, env = "TESSERA_SERVER", default_value = DEFAULT_SERVER)]
    pub server: String,
    /// The server's client token (its --client-token), sent as a bearer token.
    #[arg(long, env = "TESSERA_CLIENT_TOKEN", hide_env_values = true)]
    pub token: Option<String>,
    /// A PEM file of certificate authorities to trust besides the public ones: the
    /// private CA that signed an https:// server's certificate.
    #[arg(long, env = "TESSERA_CA")]
    pub ca: Option<PathBuf>,
}

impl ServerOpts {
    /// A client of that server.
    pub fn client(&self) -> anyhow::Result<Client> {
        Client::with_ca(&self.server, self.token.clone(), self.ca.as_deref())
    }
}

/// A job control: `POST /jobs/{id}/{control}`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Control {
    /// Unfinished tasks will not run.
    Cancel,
    /// Nothing more is leased until it resumes.
    Pause,
    /// Leasing starts again.
    Resume,
    /// Failed tasks are queued again with fresh attempts.
    Retry,
}

impl Control {
    /// The last path segment of its route.
    pub fn verb(self) -> &'static str {
        match self {
            Control::Cancel => "cancel",
            Control::Pause => "pause",
            Control::Resume => "resume",
            Control::Retry => "retry",
        }
    }
}

/// A frame file the server serves.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FrameFile {
    /// The assembled multi-layer EXR.
    Exr,
    /// The tone-mapped PNG preview.
    Png,
}

impl FrameFile {
    /// The file extension, which is also the route's last segment.
    pub fn extension(self) -> &'static str {
        match self {
            FrameFile::Exr => "exr",
            FrameFile::Png => "png",
        }
    }
}

/// The farm's API at one server, with an optional client token.
#[derive(Clone, Debug)]
pub struct Client {
    http: reqwest::Client,
    /// The server's base URL without a trailing slash, e.g. `http://127.0.0.1:8700`.
    base: String,
    token: Option<String>,
}

impl Client {
    /// A client of the server at `base` (`http://host:port`; a missing scheme means http).
    pub fn new(base: &str, token: Option<String>) -> anyhow::Result<Client> {
        Self::with_ca(base, token, None)
    }

    /// [`Client::new`], trusting the certificates in the PEM file `ca` besides the public
    /// roots.
    pub fn with_ca(base: &str, token: Option<String>, ca: Option<&Path>) -> anyhow::Result<Client> {
        let base = base.trim();
        if base.is_empty() {
            anyhow::bail!("--server is empty; give the server's URL, e.g. {DEFAULT_SERVER}");
        }
        let base = if base.contains("://") {
            base.to_string()
        } else {
            format!("http://{base}")
        };
        let url = reqwest::Url::parse(&base)
            .map_err(|e| anyhow::anyhow!("--server {base}: not a URL ({e})"))?;
        if !matches!(url.scheme(), "http" | "https") || url.host_str().is_none_or(str::is_empty) {
            anyhow::bail!("--server {base}: expected http://HOST:PORT, e.g. {DEFAULT_SERVER}");
        }
        let base = base.trim_end_matches('/').to_string();
        let http = worker::http_client(concat!("tessera-cli/", env!("CARGO_PKG_VERSION")), ca)?;
        Ok(Client {
            http,
            base,
            token: token.filter(|t| !t.is_empty()),
        })
    }

    /// The server's base URL.
    pub fn base(&self) -> &str {
        &self.base
    }

    /// The web dashboard's address.
    pub fn dashboard_url(&self) -> String {
        format!("{}/", self.base)
    }

    fn request(&self, method: Method, path: &str) -> (RequestBuilder, String) {
        let path = format!("{}{path}", proto::API_PREFIX);
        let what = format!("{method} {path}");
        let mut req = self.http.request(method, format!("{}{path}", self.base));
        if let Some(token) = &self.token {
            req = req.bearer_auth(token);
        }
        (req, what)
    }

    /// Sends a request and turns every failure into a [`ClientError`].
    async fn send(
        &self,
        req: RequestBuilder,
        what: &str,
    ) -> Result<reqwest::Response, ClientError> {
        let answer = req.send().await.map_err(|e| {
            let mut detail = root_cause(&e);
            if let Some(hint) = worker::tls_hint(&self.base, &detail) {
                detail = format!("{detail}; {hint}");
            }
            if e.is_connect() || (e.is_timeout() && e.status().is_none()) {
                ClientError::Unreachable {
                    server: self.base.clone(),
                    detail,
                }
            } else {
                ClientError::Transport {
                    request: what.to_string(),
                    detail,
                }
            }
        })?;
        let status = answer.status();
        if status.is_success() {
            return Ok(answer);
        }
        let bytes = answer.bytes().await.unwrap_or_default();
        Err(ClientError::Api {
            status,
            body: serde_json::from_slice::<ErrorBody>(&bytes).ok(),
            request: what.to_string(),
        })
    }

    /// The whole answer to a short request (at most [`JSON_TIMEOUT`]).
    async fn short_answer(
        &self,
        req: RequestBuilder,
        what: &str,
    ) -> Result<impl AsRef<[u8]>, ClientError> {
        let answer = self.send(req.timeout(JSON_TIMEOUT), what).await?;
        answer.bytes().await.map_err(|e| ClientError::Transport {
            request: what.to_string(),
            detail: format!("reading the answer: {}", root_cause(&e)),
        })
    }

    async fn json<T: DeserializeOwned>(
        &self,
        req: RequestBuilder,
        what: &str,
    ) -> Result<T, ClientError> {
        let bytes = self.short_answer(req, what).await?;
        serde_json::from_slice(bytes.as_ref()).map_err(|e| ClientError::Transport {
            request: what.to_string(),
            detail: format!(
                "the answer is not what this version of tessera expects ({e}); are the \
                 server and the CLI the same version?"
            ),
        })
    }

    async fn get<T: DeserializeOwned>(&self, path: &str) -> Result<T, ClientError> {
        let (req, what) = self.request(Method::GET, path);
        self.json(req, &what).await
    }

    /// `POST /scenes`: uploads a GLB; the server checks and summarises it.
    pub async fn upload_scene(&self, glb: Vec<u8>) -> Result<SceneInfo, ClientError> {
        let (req, what) = self.request(Method::POST, "/scenes");
        let req = req
            .header(reqwest::header::CONTENT_TYPE, "model/gltf-binary")
            .body(glb);
        let answer = self.send(req, &what).await?;
        answer.json().await.map_err(|e| ClientError::Transport {
            request: what,
            detail: format!("reading the answer: {}", root_cause(&e)),
        })
    }

    /// `POST /jobs`: creates a job.
    pub async fn create_job(&self, spec: &JobSpec) -> Result<JobStatus, ClientError> {
        let (req, what) = self.request(Method::POST, "/jobs");
        self.json(req.json(spec), &what).await
    }

    /// `GET /jobs`: every job, newest first.
    pub async fn jobs(&self) -> Result<JobList, ClientError> {
        self.get("/jobs").await
    }

    /// `GET /jobs/{id}`.
    pub async fn job(&self, id: u64) -> Result<JobStatus, ClientError> {
        self.get(&format!("/jobs/{id}")).await
    }

    /// `POST /jobs/{id}/{cancel,pause,resume,retry}`.
    pub async fn control(&self, id: u64, control: Control) -> Result<JobStatus, ClientError> {
        let (req, what) = self.request(Method::POST, &format!("/jobs/{id}/{}", control.verb()));
        self.json(req, &what).await
    }

    /// `POST /jobs/{id}/priority`.
    pub async fn set_priority(&self, id: u64, priority: i32) -> Result<JobStatus, ClientError> {
        let (req, what) = self.request(Method::POST, &format!("/jobs/{id}/priority"));
        self.json(req.json(&PriorityChange { priority }), &what)
            .await
    }

    /// `POST /jobs/{id}/rerender`: renders `frames` again from scratch.
    pub async fn rerender(&self, id: u64, frames: Vec<i32>) -> Result<JobStatus, ClientError> {
        let (req, what) = self.request(Method::POST, &format!("/jobs/{id}/rerender"));
        self.json(req.json(&Rerender { frames }), &what).await
    }

    /// `DELETE /jobs/{id}`: the job and every file it made.
    pub async fn delete_job(&self, id: u64) -> Result<(), ClientError> {
        let (req, what) = self.request(Method::DELETE, &format!("/jobs/{id}"));
        self.send(req, &what).await.map(|_| ())
    }

    /// `GET /scenes/{digest}/info`.
    pub async fn scene_info(&self, digest: &str) -> Result<SceneInfo, ClientError> {
        self.get(&format!("/scenes/{digest}/info")).await
    }

    /// The id of the job `job` names: its id, or the one job of that name.
    pub async fn resolve(&self, job: &JobRef) -> anyhow::Result<u64> {
        let name = match job {
            JobRef::Id(id) => return Ok(*id),
            JobRef::Name(name) => name,
        };
        let ids: Vec<u64> = self
            .jobs()
            .await?
            .jobs
            .iter()
            .filter(|j| &j.name == name)
            .map(|j| j.id)
            .collect();
        match ids.as_slice() {
            [id] => Ok(*id),
            [] => anyhow::bail!(
                "no job named `{name}` on {} (`tessera status` lists the jobs)",
                self.base()
            ),
            _ => anyhow::bail!(
                "{} jobs are named `{name}` (ids {}): give the id",
                ids.len(),
                ids.iter()
                    .map(u64::to_string)
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        }
    }

    /// `GET /jobs/{id}/failures`: why its attempts failed, grouped by reason.
    pub async fn failures(&self, id: u64) -> Result<FailureList, ClientError> {
        self.get(&format!("/jobs/{id}/failures")).await
    }

    /// `GET /jobs/{id}/tasks/{task}/log`: what the workers logged while they held it.
    pub async fn task_log(&self, id: u64, task: u64) -> Result<TaskLog, ClientError> {
        self.get(&format!("/jobs/{id}/tasks/{task}/log")).await
    }

    /// `GET /jobs/{id}/log`: every event of the job, oldest first (every page).
    pub async fn job_log(&self, id: u64) -> Result<Vec<JobEvent>, ClientError> {
        let (mut events, mut after) = (Vec::new(), 0);
        loop {
            let page: JobEventList = self.get(&format!("/jobs/{id}/log?after={after}")).await?;
            events.extend(page.events);
            match page.next_after {
                Some(next) => after = next,
                None => return Ok(events),
            }
        }
    }

    /// `GET /jobs/{id}/frames`.
    pub async fn frames(&self, id: u64) -> Result<FrameList, ClientError> {
        self.get(&format!("/jobs/{id}/frames")).await
    }

    /// `GET /jobs/{id}/frames/{frame}/{exr,png}`: the file's bytes.
    pub async fn frame_file(
        &self,
        id: u64,
        frame: i32,
        file: FrameFile,
    ) -> Result<Vec<u8>, ClientError> {
        let path = format!("/jobs/{id}/frames/{frame}/{}", file.extension());
        let (req, what) = self.request(Method::GET, &path);
        let answer = self.send(req, &what).await?;
        let bytes = answer.bytes().await.map_err(|e| ClientError::Transport {
            request: what,
            detail: format!("downloading: {}", root_cause(&e)),
        })?;
        Ok(bytes.to_vec())
    }

    /// `GET /jobs/{id}/video`: the job's MP4.
    pub async fn video(&self, id: u64) -> Result<Vec<u8>, ClientError> {
        let (req, what) = self.request(Method::GET, &format!("/jobs/{id}/video"));
        let answer = self.send(req, &what).await?;
        let bytes = answer.bytes().await.map_err(|e| ClientError::Transport {
            request: what,
            detail: format!("downloading: {}", root_cause(&e)),
        })?;
        Ok(bytes.to_vec())
    }

    /// The farm's demand, read from `GET /metrics` (no token needed): the tasks that want
    /// a worker now, as autoscalers see them (`server::metrics::DEMAND`).
    pub async fn demand(&self) -> Result<u64, ClientError> {
        let what = "GET /metrics";
        let req = self.http.get(format!("{}/metrics", self.base));
        let text = self.short_answer(req, what).await?;
        parse_gauge(
            &String::from_utf8_lossy(text.as_ref()),
            server::metrics::DEMAND,
        )
        .ok_or_else(|| ClientError::Transport {
            request: what.to_string(),
            detail: format!(
                "no `{}` gauge in the answer; are the server and the CLI the same version?",
                server::metrics::DEMAND
            ),
        })
    }

    /// `GET /workers`.
    pub async fn workers(&self) -> Result<WorkerList, ClientError> {
        self.get("/workers").await
    }

    /// `GET /workers?all=true`: also those gone for more than a day.
    pub async fn all_workers(&self) -> Result<WorkerList, ClientError> {
        self.get("/workers?all=true").await
    }

    /// `POST /gc`: retention now, or with `dry_run` what it would remove.
    pub async fn gc(&self, request: &GcRequest) -> Result<GcReport, ClientError> {
        let (req, what) = self.request(Method::POST, "/gc");
        self.json(req.json(request), &what).await
    }

    /// `POST /workers/{id}/clear`: lifts a worker's quarantine.
    pub async fn clear_worker(&self, id: u64) -> Result<WorkerInfo, ClientError> {
        let (req, what) = self.request(Method::POST, &format!("/workers/{id}/clear"));
        self.json(req, &what).await
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn error_answers_show_the_servers_message_and_field() {
        let e = ClientError::Api {
            status: StatusCode::UNPROCESSABLE_ENTITY,
            body: Some(ErrorBody {
                error: "invalid_field".into(),
                message: "spp: must be 1 to 65536, got 0".into(),
                field: Some("spp".into()),
            }),
            request: "POST /api/v1/jobs".into(),
        };
        assert_eq!(e.to_string(), "spp: must be 1 to 65536, got 0 [422]");
        let e = ClientError::Api {
            status: StatusCode::NOT_FOUND,
            body: Some(ErrorBody {
                error: "not_found".into(),
                message: "no job 7".into(),
                field: Some("id".into()),
            }),
            request: "GET /api/v1/jobs/7".into(),
        };
        assert_eq!(e.to_string(), "no job 7 (field `id`) [404]");
        let e = ClientError::Api {
            status: StatusCode::UNAUTHORIZED,
            body: None,
            request: "GET /api/v1/jobs".into(),
        };
        assert!(e.to_string().contains("--token"), "{e}");
    }

    #[test]
    fn a_job_is_named_by_id_or_by_name() {
        assert_eq!("12".parse(), Ok(JobRef::Id(12)));
        assert_eq!(" 12 ".parse(), Ok(JobRef::Id(12)));
        assert_eq!("shot 12".parse(), Ok(JobRef::Name("shot 12".into())));
        assert_eq!("-3".parse(), Ok(JobRef::Name("-3".into())));
        assert!("99999999999999999999".parse::<JobRef>().is_err());
        assert!("".parse::<JobRef>().is_err());
    }

    #[test]
    fn base_urls_are_normalised() {
        let c = Client::new("127.0.0.1:8700/", None).unwrap();
        assert_eq!(c.base(), "http://127.0.0.1:8700");
        assert_eq!(c.dashboard_url(), "http://127.0.0.1:8700/");
        assert!(Client::new("  ", None).is_err());
        assert!(Client::new("http://", None).is_err());
        assert!(Client::new("ftp://farm:21", None).is_err());
        let c = Client::new("https://farm.example:443", Some(String::new())).unwrap();
        assert!(c.token.is_none());
    }

    #[test]
    fn the_demand_gauge_is_read_by_its_whole_name() {
        let text = "# TYPE tessera_demand_tasks gauge\ntessera_demand_tasks_total 9\n\
                    tessera_demand_tasks 12\n";
        assert_eq!(parse_gauge(text, "tessera_demand_tasks"), Some(12));
        assert_eq!(
            parse_gauge("tessera_demand_tasks 3.0\n", "tessera_demand_tasks"),
            Some(3)
        );
        assert_eq!(
            parse_gauge("tessera_demand_tasks_total 9\n", "tessera_demand_tasks"),
            None
        );
        assert_eq!(
            parse_gauge("tessera_demand_tasks NaN\n", "tessera_demand_tasks"),
            None
        );
    }
}

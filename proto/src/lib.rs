//! Tessera's wire types. Every JSON shape exchanged between the CLI, the server and the
//! workers is defined here once, as serde types; the server derives its OpenAPI document
//! from them (feature `openapi`), and nothing here knows how the server stores anything.
//!
//! | module | what it holds |
//! |---|---|
//! | [`scene`] | what an uploaded scene holds ([`SceneInfo`]) |
//! | [`job`] | the job spec a client submits and the status it reads back, frames |
//! | [`task`] | a job's tasks and why their attempts failed |
//! | [`worker`] | registration, lease, heartbeat, result upload headers, failure reports |
//! | [`log`] | the lines a worker logged per task, a job's event log |
//! | [`event`] | server-sent events for jobs, frames and workers |
//! | [`gc`] | retention: what `POST /gc` removed or would remove |
//! | [`error`] | the JSON error body every failed request answers with |
//!
//! Times on the wire are Unix milliseconds (`*_ms`); durations are seconds (`*_seconds`).
#![warn(missing_docs)]

pub mod error;
pub mod event;
pub mod gc;
pub mod job;
pub mod log;
pub mod scene;
pub mod task;
pub mod worker;

pub use error::ErrorBody;
pub use event::{Event, Notification, NotificationKind};
pub use gc::{GcJob, GcReport, GcRequest};
pub use job::{
    BudgetPlan, CameraSpec, FrameList, FrameRange, FrameState, FrameStatus, JobList, JobSpec,
    JobState, JobStatus, OutputLayer, PriorityChange, Rerender, TaskCounts,
};
pub use log::{AttemptLog, JobEvent, JobEventList, LogLevel, LogLine, TaskLog};
pub use scene::{AnimationInfo, CameraInfo, SceneInfo};
pub use task::{
    FailureGroup, FailureKind, FailureList, TaskFailure, TaskInfo, TaskList, TaskState,
};
pub use worker::{
    FailureAck, FailureReport, Heartbeat, HeartbeatAck, Lease, LeaseRequest, Rect, ResultAck,
    ResultMetadata, SampleSpan, TaskKind, TaskLogLines, TaskToken, WorkerInfo, WorkerLeft,
    WorkerList, WorkerRegistered, WorkerRegistration,
};

/// Every path of the API starts with this.
pub const API_PREFIX: &str = "/api/v1";

/// The largest id of a job, task or worker: ids are the server's SQLite row ids.
pub const MAX_ID: u64 = i64::MAX as u64;

/// Reads an id, refusing one past [`MAX_ID`] (it can name nothing) with a message that
/// says so, for `#[serde(deserialize_with)]`.
pub fn deserialize_id<'de, D: serde::Deserializer<'de>>(d: D) -> Result<u64, D::Error> {
    let id = <u64 as serde::Deserialize>::deserialize(d)?;
    if id > MAX_ID {
        return Err(serde::de::Error::custom(format!(
            "id {id} is past the largest id, {MAX_ID}"
        )));
    }
    Ok(id)
}

/// The answer of `GET /healthz`.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct Health {
    /// `ok` while the server answers and its database opens.
    pub status: String,
    /// The server's version.
    pub version: String,
}

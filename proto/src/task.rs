//! A job's tasks as clients read them (`GET /jobs/{id}/tasks`) and why attempts failed
//! (`GET /jobs/{id}/failures`): every failed attempt keeps the reason its worker gave, or
//! says that its lease expired.

use serde::{Deserialize, Serialize};

use crate::worker::{Rect, SampleSpan, TaskKind};

/// Where a task stands.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(rename_all = "snake_case")]
pub enum TaskState {
    /// Waiting for a worker.
    Queued,
    /// Held by a worker until its lease deadline.
    Leased,
    /// Its tile is accepted.
    Done,
    /// Out of attempts.
    Failed,
    /// Its job was cancelled.
    Cancelled,
}

impl TaskState {
    /// Every state.
    pub const ALL: [TaskState; 5] = [
        TaskState::Queued,
        TaskState::Leased,
        TaskState::Done,
        TaskState::Failed,
        TaskState::Cancelled,
    ];

    /// Its name on the wire (and in the server's database).
    pub fn as_str(self) -> &'static str {
        match self {
            TaskState::Queued => "queued",
            TaskState::Leased => "leased",
            TaskState::Done => "done",
            TaskState::Failed => "failed",
            TaskState::Cancelled => "cancelled",
        }
    }

    /// The state named `s`.
    pub fn parse(s: &str) -> Option<TaskState> {
        TaskState::ALL.into_iter().find(|t| t.as_str() == s)
    }
}

/// How an attempt failed.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(rename_all = "snake_case")]
pub enum FailureKind {
    /// The worker reported that it could not render the task (the reason is its error).
    Reported,
    /// The lease ran out without a heartbeat (the worker died, hung or lost the network).
    Expired,
}

impl FailureKind {
    /// Its name on the wire: `reported` or `expired`.
    pub fn as_str(self) -> &'static str {
        match self {
            FailureKind::Reported => "reported",
            FailureKind::Expired => "expired",
        }
    }
}

/// One failed attempt of a task.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct TaskFailure {
    /// The attempt (the lease's number).
    pub attempt: u32,
    /// The worker that held it.
    pub worker_id: u64,
    /// That worker's name.
    pub worker: String,
    /// Reported or expired.
    pub kind: FailureKind,
    /// The reason, word for word: the worker's error chain, or why the lease expired.
    pub reason: String,
    /// When, Unix ms.
    pub at_ms: i64,
}

/// One task of a job.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct TaskInfo {
    /// The task's id.
    pub id: u64,
    /// Render a tile, or denoise a frame.
    #[serde(default)]
    pub kind: TaskKind,
    /// Its frame.
    pub frame: i32,
    /// Its tile's index in the frame.
    pub tile: u32,
    /// Its sample pass.
    pub pass: u32,
    /// The tile.
    pub rect: Rect,
    /// The samples.
    pub samples: SampleSpan,
    /// Where it stands.
    pub state: TaskState,
    /// Leases granted so far.
    pub attempt: u32,
    /// The worker holding it, or that rendered it once done.
    pub worker_id: Option<u64>,
    /// For a check task, the task whose tile it renders again.
    pub check_of: Option<u64>,
    /// Its failed attempts since its job was last retried, oldest first.
    pub failures: Vec<TaskFailure>,
}

/// A page of a job's tasks, by id.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct TaskList {
    /// The tasks.
    pub tasks: Vec<TaskInfo>,
    /// Pass as `after` for the next page; absent on the last one.
    pub next_after: Option<u64>,
}

/// The failed attempts of a job that share a reason.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct FailureGroup {
    /// Reported or expired.
    pub kind: FailureKind,
    /// The reason, word for word.
    pub reason: String,
    /// Failed attempts with it.
    pub attempts: u64,
    /// Tasks that failed with it at least once.
    pub tasks: u64,
    /// The names of the workers it happened on.
    pub workers: Vec<String>,
    /// One task it happened to (for `GET /jobs/{id}/tasks`).
    pub example_task: u64,
    /// When it last happened, Unix ms.
    pub last_ms: i64,
}

/// Why a job's attempts failed, most frequent reason first.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct FailureList {
    /// One group per reason.
    pub groups: Vec<FailureGroup>,
}

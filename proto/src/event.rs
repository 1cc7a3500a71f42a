//! Server-sent events (`GET /api/v1/events`): the SSE event name is the variant's `type`,
//! the data is the JSON of the whole enum.

use serde::{Deserialize, Serialize};

use crate::job::{FrameStatus, JobStatus};
use crate::worker::WorkerInfo;

/// A change somewhere on the farm.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum Event {
    /// A job changed: created, progressed, paused, resumed, cancelled, finished, deleted.
    Job {
        /// The job as it is now (boxed: it is much larger than the other variants).
        job: Box<JobStatus>,
    },
    /// A job was deleted with its outputs.
    JobDeleted {
        /// The job's id.
        job_id: u64,
    },
    /// A frame changed state; `Done` means its EXR and PNG can be downloaded.
    Frame {
        /// The job.
        job_id: u64,
        /// The frame as it is now.
        frame: FrameStatus,
    },
    /// A worker registered, took a task, finished one or was last seen.
    Worker {
        /// The worker as it is now.
        worker: WorkerInfo,
    },
}

impl Event {
    /// The SSE event name: `job`, `job_deleted`, `frame` or `worker`.
    pub fn name(&self) -> &'static str {
        match self {
            Event::Job { .. } => "job",
            Event::JobDeleted { .. } => "job_deleted",
            Event::Frame { .. } => "frame",
            Event::Worker { .. } => "worker",
        }
    }
}

/// What a webhook is told: the JSON body of each delivery, signed by the server in the
/// [`Notification::SIGNATURE`] header.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct Notification {
    /// Its id: the same on every retry of it, so a receiver can drop repeats.
    pub id: u64,
    /// What happened.
    pub event: NotificationKind,
    /// When, Unix ms.
    pub at_ms: i64,
    /// The job, as it was when the delivery was made (job events).
    pub job: Option<Box<JobStatus>>,
    /// The worker (`worker_quarantined`).
    pub worker: Option<WorkerInfo>,
}

impl Notification {
    /// The header holding `sha256=` and the hex HMAC-SHA256 of the body, keyed with the
    /// server's webhook secret.
    pub const SIGNATURE: &'static str = "x-tessera-signature";
    /// The header holding the notification's id.
    pub const DELIVERY: &'static str = "x-tessera-delivery";
}

/// What a notification is about.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(rename_all = "snake_case")]
pub enum NotificationKind {
    /// A job finished with every frame done.
    JobDone,
    /// A job finished with frames failed.
    JobFailed,
    /// A time-budget job's time is up: it finished what its budget allowed.
    JobBudgetReached,
    /// Checks proved a worker's tiles wrong: it gets no more work.
    WorkerQuarantined,
}

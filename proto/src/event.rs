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

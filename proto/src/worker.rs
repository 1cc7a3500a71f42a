//! The worker protocol: register, lease (long poll), heartbeat, upload a tile, report a
//! failure. Outcomes a worker must handle are HTTP statuses with typed bodies:
//!
//! | call | 200 | 204 | 409 |
//! |---|---|---|---|
//! | lease | [`Lease`] | no work now: lease again | — |
//! | heartbeat | [`HeartbeatAck`] | — | lease gone (paused, cancelled, expired): stop |
//! | result | [`ResultAck`] (also for a duplicate, ignored) | — | lease gone: drop the tile |
//! | failure | [`FailureAck`] | — | lease gone |
//! | leave | [`WorkerLeft`] | — | — |

use serde::{Deserialize, Serialize};

use crate::job::CameraSpec;
use crate::log::LogLine;

/// `POST /workers`: a worker introduces itself.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct WorkerRegistration {
    /// A name for people (host name, usually).
    pub name: String,
    /// Render threads it will use.
    pub threads: u32,
    /// Its Tessera version.
    pub version: String,
    /// The credential an earlier registration answered, kept on the worker's disk: with
    /// it the worker is that worker again (its quarantine, job blocks and history stay).
    /// Without it, a name no live worker holds takes over the worker that last had it.
    #[serde(default)]
    pub credential: Option<String>,
    /// The machine and build: architecture, CPU model and features, OS, Tessera version
    /// and build profile. Kept so that a check that finds two tiles differing says which
    /// platforms disagreed.
    #[serde(default)]
    pub platform: Option<String>,
    /// What the machine offers, as words a job can require (`gpu`, `studio-a`): it takes
    /// only jobs whose every required tag it has.
    #[serde(default)]
    pub tags: Vec<String>,
    /// The denoiser it has loaded (Open Image Denoise and its version), if any: only such
    /// a worker is given denoise tasks.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub denoiser: Option<String>,
    /// The video encoder it has (FFmpeg with libx264), if any: only such a worker is given
    /// encode tasks.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub encoder: Option<String>,
    /// What its denoiser took per megapixel of frame when it started (milliseconds): the
    /// time-budget planner's figure for the denoise step until the worker has denoised.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub denoise_ms_per_megapixel: Option<u64>,
    /// What its encoder took per megapixel of frames when it started (milliseconds), the
    /// same for the encode step.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub encode_ms_per_megapixel: Option<u64>,
}

/// The answer to a registration: the worker's id and the timing it must keep.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct WorkerRegistered {
    /// Id to use in every later call.
    pub worker_id: u64,
    /// This worker's own secret: the bearer token of every later call on its routes (the
    /// join token only registers). Keep it to come back as the same worker.
    pub credential: String,
    /// A lease lasts this long unless a heartbeat extends it.
    pub lease_seconds: u64,
    /// Send a heartbeat at least this often while rendering.
    pub heartbeat_seconds: u64,
    /// The longest a lease request waits for work before answering 204.
    pub max_wait_seconds: u64,
}

/// A worker as `GET /workers` lists it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct WorkerInfo {
    /// Its id.
    pub id: u64,
    /// Its name.
    pub name: String,
    /// Render threads.
    pub threads: u32,
    /// Tessera version.
    pub version: String,
    /// The task it holds a lease on, if any.
    pub current_task: Option<TaskToken>,
    /// Job of the current task.
    pub current_job: Option<u64>,
    /// Frame of the current task.
    pub current_frame: Option<i32>,
    /// When it last called the server.
    pub last_seen_ms: i64,
    /// Whether it called within the last two lease periods and has not left.
    pub online: bool,
    /// Tasks it has finished.
    pub tasks_done: u64,
    /// A check found one of its tiles differing from another worker's, undecided yet.
    #[serde(default)]
    pub suspect: bool,
    /// Why it is quarantined (a check proved a tile of it wrong): it gets no work until an
    /// operator clears it (`POST /workers/{id}/clear`, `tessera workers --clear ID`).
    #[serde(default)]
    pub quarantined: Option<String>,
    /// The machine and build it registered with ([`WorkerRegistration::platform`]).
    #[serde(default)]
    pub platform: Option<String>,
    /// Its tags ([`WorkerRegistration::tags`]).
    #[serde(default)]
    pub tags: Vec<String>,
    /// Its denoiser ([`WorkerRegistration::denoiser`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub denoiser: Option<String>,
    /// Its video encoder ([`WorkerRegistration::encoder`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub encoder: Option<String>,
    /// Camera samples per second over its last tasks (none done yet: absent).
    #[serde(default)]
    pub samples_per_second: Option<f64>,
    /// Attempts it failed in the last hour.
    #[serde(default)]
    pub recent_failures: u64,
    /// Why its last failed attempt failed, word for word.
    #[serde(default)]
    pub last_failure: Option<String>,
}

/// `GET /workers`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct WorkerList {
    /// Workers by id.
    pub workers: Vec<WorkerInfo>,
}

/// `POST /workers/{id}/lease` body.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct LeaseRequest {
    /// Wait up to this long for work (capped by the server's `max_wait_seconds`;
    /// default 0: answer at once).
    #[serde(default)]
    pub wait_seconds: u64,
    /// The lines the worker logged for its previous lease after that lease's last
    /// heartbeat: a task that ends before its first heartbeat sends them all here.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub last_task_log: Option<TaskLogLines>,
}

/// Log lines of one lease.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct TaskLogLines {
    /// The lease they were logged for.
    pub token: TaskToken,
    /// The lines, oldest first.
    pub lines: Vec<LogLine>,
}

/// A fencing token: the task and which attempt at it this lease is. A heartbeat, result or
/// failure with a token that is no longer current is answered 409 and changes nothing.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct TaskToken {
    /// The task's id.
    #[serde(deserialize_with = "crate::deserialize_id")]
    pub task_id: u64,
    /// The attempt (1 for the first lease).
    pub attempt: u32,
}

/// A rectangle of pixels (the tracer's `TileRect`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct Rect {
    /// Left column.
    pub x: u32,
    /// Top row.
    pub y: u32,
    /// Width.
    pub width: u32,
    /// Height.
    pub height: u32,
}

/// Samples `[start, end)` (the tracer's `SampleRange`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct SampleSpan {
    /// First sample index.
    pub start: u32,
    /// One past the last.
    pub end: u32,
}

/// What a task asks of its worker.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(rename_all = "snake_case")]
pub enum TaskKind {
    /// Render the lease's tile and samples; upload the tile.
    #[default]
    Render,
    /// Denoise the lease's assembled frame (`GET /workers/{id}/tasks/{task}/frame`, the
    /// whole frame as its tile); upload the denoised RGB as the beauty of an EXR of the
    /// whole frame, with 0 samples and 0 rays.
    Denoise,
    /// Encode the job's finished frames (their PNG previews, `GET
    /// /workers/{id}/tasks/{task}/frame?frame=F&file=png` for each frame of the lease's
    /// `sequence`) into an H.264 MP4 at the job's fps; upload the MP4, with 0 samples and
    /// 0 rays.
    Encode,
}

impl TaskKind {
    /// Every kind.
    pub const ALL: [TaskKind; 3] = [TaskKind::Render, TaskKind::Denoise, TaskKind::Encode];

    /// Its name on the wire (and in the server's database).
    pub fn as_str(self) -> &'static str {
        match self {
            TaskKind::Render => "render",
            TaskKind::Denoise => "denoise",
            TaskKind::Encode => "encode",
        }
    }

    /// The kind named `s`.
    pub fn parse(s: &str) -> Option<TaskKind> {
        TaskKind::ALL.into_iter().find(|k| k.as_str() == s)
    }
}

/// Everything a worker needs to render one task with the tracer: `FrameOptions` (frame,
/// fps, size, camera, shutter, motion steps, animation), `RenderSettings` (max depth,
/// seed, noise target), the tile and the sample range.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct Lease {
    /// The fencing token to send back with heartbeats, the result or a failure.
    pub token: TaskToken,
    /// What to do: render the tile, or denoise the assembled frame.
    #[serde(default)]
    pub kind: TaskKind,
    /// The job.
    pub job_id: u64,
    /// Scene digest: `GET /scenes/{digest}` (cache it).
    pub scene: String,
    /// Frame number.
    pub frame: i32,
    /// Frames per second.
    pub fps: f64,
    /// Frame width.
    pub width: u32,
    /// Frame height.
    pub height: u32,
    /// The camera.
    pub camera: CameraSpec,
    /// Shutter open and close, in frames relative to the frame.
    pub shutter: [f64; 2],
    /// Motion steps across the shutter, if the job set them.
    pub motion_steps: Option<u32>,
    /// The animation that plays, if the job picked one.
    pub animation: Option<String>,
    /// Maximum bounces.
    pub max_depth: u32,
    /// Seed.
    pub seed: u32,
    /// The same sampling pattern on every frame.
    #[serde(default)]
    pub fixed_pattern: bool,
    /// The clamp on indirect light, if the job set one.
    #[serde(default)]
    pub clamp_indirect: Option<f32>,
    /// Adaptive sampling's error target, if the job set one.
    #[serde(default)]
    pub noise_threshold: Option<f64>,
    /// With a noise threshold, the samples every pixel takes before it may stop.
    #[serde(default)]
    pub min_spp: u32,
    /// The tile to render.
    pub tile: Rect,
    /// The samples to render.
    pub samples: SampleSpan,
    /// For an encode lease, the job's frames, in the video's order.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sequence: Option<crate::job::FrameRange>,
    /// The lease ends at this time unless a heartbeat extends it.
    pub deadline_ms: i64,
}

/// `POST /workers/{id}/heartbeat` body.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct Heartbeat {
    /// The lease being worked on; `None` for an idle worker saying it is alive.
    #[serde(default)]
    pub token: Option<TaskToken>,
    /// Lines the worker logged for the lease since its last heartbeat (at most
    /// [`crate::log::MAX_TASK_LOG_LINES`] are kept per attempt).
    #[serde(default)]
    pub log: Vec<LogLine>,
}

/// The answer to a heartbeat that extended the lease.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct HeartbeatAck {
    /// The new deadline (absent for an idle heartbeat).
    pub deadline_ms: Option<i64>,
}

/// `POST /workers/{id}/tasks/{task}/failure` body.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct FailureReport {
    /// The attempt that failed.
    pub attempt: u32,
    /// What went wrong, for the job's event log.
    pub message: String,
    /// Lines the worker logged for the lease since its last heartbeat.
    #[serde(default)]
    pub log: Vec<LogLine>,
}

/// What the server did with a failure.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct FailureAck {
    /// The task went back to the queue.
    pub requeued: bool,
    /// The task ran out of attempts and failed (its job is marked failed).
    pub task_failed: bool,
    /// This worker has now failed too many tasks of the job and gets no more of them.
    pub blocked_from_job: bool,
}

/// The answer to `POST /workers/{id}/leave`: the worker is gone and the leases it held
/// are queued again.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct WorkerLeft {
    /// Jobs whose tasks it gave back.
    pub jobs: Vec<u64>,
}

/// What the server did with an uploaded tile.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct ResultAck {
    /// `true` the first time; `false` for a second upload of a finished task (ignored).
    pub accepted: bool,
    /// This tile completed its frame, which is now assembled.
    pub frame_done: bool,
}

/// The headers that go with a result upload (`POST /workers/{id}/tasks/{task}/result`,
/// body: the tile as EXR bytes, as `tracer::output::encode_exr_layers` writes the resolved
/// `TileBuffer`, ZIP-compressed or not, with `tessera/spp` set to the samples rendered).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ResultMetadata {
    /// The lease's attempt (the fencing token's second half).
    pub attempt: u32,
    /// Lower-case hex SHA-256 of the body.
    pub sha256: String,
    /// Samples per pixel rendered (the lease's sample range length).
    pub samples: u32,
    /// Rays traced, for throughput figures.
    pub rays: u64,
    /// Wall-clock milliseconds the render took on the worker.
    pub render_ms: u64,
}

impl ResultMetadata {
    /// Header carrying [`ResultMetadata::attempt`].
    pub const ATTEMPT: &'static str = "x-tessera-attempt";
    /// Header carrying [`ResultMetadata::sha256`].
    pub const SHA256: &'static str = "x-tessera-sha256";
    /// Header carrying [`ResultMetadata::samples`].
    pub const SAMPLES: &'static str = "x-tessera-samples";
    /// Header carrying [`ResultMetadata::rays`].
    pub const RAYS: &'static str = "x-tessera-rays";
    /// Header carrying [`ResultMetadata::render_ms`].
    pub const RENDER_MS: &'static str = "x-tessera-render-ms";

    /// The headers to send, as (name, value).
    pub fn to_headers(&self) -> [(&'static str, String); 5] {
        [
            (Self::ATTEMPT, self.attempt.to_string()),
            (Self::SHA256, self.sha256.clone()),
            (Self::SAMPLES, self.samples.to_string()),
            (Self::RAYS, self.rays.to_string()),
            (Self::RENDER_MS, self.render_ms.to_string()),
        ]
    }

    /// Reads the headers through `get(name)`; the error names the header missing or
    /// malformed.
    pub fn from_headers<'a>(
        get: impl Fn(&str) -> Option<&'a str>,
    ) -> Result<Self, (&'static str, String)> {
        fn number<T: std::str::FromStr>(
            name: &'static str,
            v: Option<&str>,
        ) -> Result<T, (&'static str, String)> {
            let v = v.ok_or((name, format!("header `{name}` is missing")))?;
            v.trim()
                .parse()
                .map_err(|_| (name, format!("header `{name}` is not a number: `{v}`")))
        }
        let sha256 = get(Self::SHA256)
            .ok_or((
                Self::SHA256,
                format!("header `{}` is missing", Self::SHA256),
            ))?
            .trim()
            .to_ascii_lowercase();
        if sha256.len() != 64 || !sha256.bytes().all(|b| b.is_ascii_hexdigit()) {
            return Err((
                Self::SHA256,
                format!("header `{}` must be 64 hex digits", Self::SHA256),
            ));
        }
        Ok(ResultMetadata {
            attempt: number(Self::ATTEMPT, get(Self::ATTEMPT))?,
            sha256,
            samples: number(Self::SAMPLES, get(Self::SAMPLES))?,
            rays: number(Self::RAYS, get(Self::RAYS))?,
            render_ms: number(Self::RENDER_MS, get(Self::RENDER_MS))?,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn result_headers_round_trip() {
        let m = ResultMetadata {
            attempt: 2,
            sha256: "ab".repeat(32),
            samples: 16,
            rays: 12345,
            render_ms: 7,
        };
        let headers = m.to_headers();
        let get = |n: &str| {
            headers
                .iter()
                .find(|(k, _)| *k == n)
                .map(|(_, v)| v.as_str())
        };
        assert_eq!(ResultMetadata::from_headers(get), Ok(m));
    }

    #[test]
    fn result_headers_name_the_bad_one() {
        let get = |n: &str| match n {
            ResultMetadata::SHA256 => Some("zz"),
            _ => Some("1"),
        };
        let (name, _) = ResultMetadata::from_headers(get).unwrap_err();
        assert_eq!(name, ResultMetadata::SHA256);
        let sha = "0".repeat(64);
        let get = |n: &str| match n {
            ResultMetadata::SHA256 => Some(sha.as_str()),
            ResultMetadata::SAMPLES => Some("many"),
            _ => Some("1"),
        };
        let (name, msg) = ResultMetadata::from_headers(get).unwrap_err();
        assert_eq!(name, ResultMetadata::SAMPLES);
        assert!(msg.contains("many"));
    }
}

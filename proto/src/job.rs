//! Jobs: the spec a client submits, the status it reads back, and frames.

use serde::{Deserialize, Serialize};

/// Which camera renders a job (the tracer's `CameraChoice`).
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(rename_all = "snake_case")]
pub enum CameraSpec {
    /// The scene's first camera, or one that frames the scene when it has none.
    #[default]
    Default,
    /// glTF camera index.
    Index(u32),
    /// glTF camera name.
    Name(String),
}

/// Frames `start, start + step, ...` up to and including `end`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct FrameRange {
    /// First frame (frame f is at time f / fps).
    pub start: i32,
    /// Last frame, included when the step lands on it.
    pub end: i32,
    /// Distance between rendered frames (at least 1).
    #[serde(default = "one")]
    pub step: u32,
}

impl FrameRange {
    /// The frame numbers, in order.
    pub fn frames(&self) -> impl Iterator<Item = i32> {
        let step = self.step.max(1) as usize;
        (self.start..=self.end).step_by(step)
    }

    /// How many frames the range holds (0 when `end < start`).
    pub fn count(&self) -> u64 {
        if self.end < self.start {
            return 0;
        }
        (self.end as i64 - self.start as i64) as u64 / self.step.max(1) as u64 + 1
    }

    /// The last frame rendered: `end`, or the last step before it.
    pub fn last(&self) -> i32 {
        (self.start as i64 + (self.count().max(1) as i64 - 1) * self.step.max(1) as i64) as i32
    }

    /// The file name of `frame` in this sequence ([`frame_file_name`]).
    pub fn file_name(&self, frame: i32, extension: &str) -> String {
        frame_file_name(frame, self.last(), extension)
    }
}

/// A named quality preset: the settings `--quality` stands for, each of which an explicit
/// option overrides. The price of each (time, and error against a converged reference) is
/// measured by `tessera bench` (BENCHMARKS.md).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(rename_all = "snake_case")]
pub enum Quality {
    /// Blocking and timing: 16 spp at most, 4 bounces, stop at error 0.1.
    Draft,
    /// Judging light and materials: 128 spp at most, 8 bounces, stop at error 0.03,
    /// denoised.
    Preview,
    /// Delivery: 1024 spp at most, 12 bounces, stop at error 0.01 (Cycles' default),
    /// denoised.
    Final,
}

/// Samples a pixel takes before adaptive sampling may stop it, unless a job, the command
/// line or a preset says otherwise (at most the job's spp).
pub const DEFAULT_MIN_SPP: u32 = 16;

/// The first pass's samples of a time-budget job, unless the job says otherwise (at most
/// the job's spp): few, so that every frame exists early.
pub const DEFAULT_BUDGET_MIN_SPP: u32 = 4;

/// What a [`Quality`] preset sets.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct QualitySettings {
    /// Samples per pixel at most.
    pub spp: u32,
    /// Maximum bounces.
    pub max_depth: u32,
    /// Adaptive sampling's error target.
    pub noise_threshold: f64,
    /// Samples every pixel takes before it may stop.
    pub min_spp: u32,
    /// Frames are denoised.
    pub denoise: bool,
}

impl Quality {
    /// Every preset, from fastest to best.
    pub const ALL: [Quality; 3] = [Quality::Draft, Quality::Preview, Quality::Final];

    /// The preset's name, as the CLI and the job spec spell it.
    pub fn name(self) -> &'static str {
        match self {
            Quality::Draft => "draft",
            Quality::Preview => "preview",
            Quality::Final => "final",
        }
    }

    /// The settings the preset stands for.
    pub fn settings(self) -> QualitySettings {
        let (spp, max_depth, noise_threshold, min_spp, denoise) = match self {
            Quality::Draft => (16, 4, 0.1, 4, false),
            Quality::Preview => (128, 8, 0.03, 16, true),
            Quality::Final => (1024, 12, 0.01, 32, true),
        };
        QualitySettings {
            spp,
            max_depth,
            noise_threshold,
            min_spp,
            denoise,
        }
    }
}

impl std::str::FromStr for Quality {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        Quality::ALL
            .into_iter()
            .find(|q| q.name().eq_ignore_ascii_case(s))
            .ok_or_else(|| format!("unknown quality {s:?}: draft, preview or final"))
    }
}

/// An image layer of the output EXR.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(rename_all = "snake_case")]
pub enum OutputLayer {
    /// Linear RGBA radiance (`R G B A`); always written.
    Beauty,
    /// Albedo of the first non-specular hit (`albedo.R G B`).
    Albedo,
    /// World-space shading normal (`N.X Y Z`).
    Normal,
    /// Depth along the view axis (`Z`).
    Depth,
    /// Samples taken per pixel (`samples`).
    Samples,
    /// Estimated relative error per pixel (`noise`; 1e10 where a pixel had too few
    /// samples to tell).
    Noise,
    /// Screen-space motion over the shutter in pixels, x right and y down (`motion.X Y`;
    /// zero where nothing moves or the shutter is closed).
    Motion,
    /// Estimated variance of each pixel's value, the square of its standard error
    /// (`variance.R G B`; 1e10 where a pixel had too few samples to tell).
    Variance,
}

impl OutputLayer {
    /// Every layer, in file order.
    pub const ALL: [OutputLayer; 8] = [
        OutputLayer::Beauty,
        OutputLayer::Albedo,
        OutputLayer::Normal,
        OutputLayer::Depth,
        OutputLayer::Samples,
        OutputLayer::Noise,
        OutputLayer::Motion,
        OutputLayer::Variance,
    ];
}

/// What a client asks the farm to render. Fields left out take the defaults shown; unknown
/// fields are refused (a typo is an error, not a silently ignored setting).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct JobSpec {
    /// SHA-256 digest of an uploaded scene (or its first 8 or more hex digits; the job
    /// keeps the whole digest).
    pub scene: String,
    /// A name for people; defaults to `job <id>`.
    #[serde(default)]
    pub name: Option<String>,
    /// Frames to render; default: the scene's animation range at `fps` (frame 0 for a
    /// still scene).
    #[serde(default)]
    pub frames: Option<FrameRange>,
    /// Frames per second (default 24).
    #[serde(default = "default_fps")]
    pub fps: f64,
    /// Image width in pixels (default 1280).
    #[serde(default = "default_width")]
    pub width: u32,
    /// Image height in pixels (default 720).
    #[serde(default = "default_height")]
    pub height: u32,
    /// The camera (default: the scene's first).
    #[serde(default)]
    pub camera: CameraSpec,
    /// Samples per pixel (default 64).
    #[serde(default = "default_spp")]
    pub spp: u32,
    /// Maximum bounces (default 8).
    #[serde(default = "default_max_depth")]
    pub max_depth: u32,
    /// Adaptive sampling: each pixel stops once its estimated relative error is at most
    /// this (0 < e <= 1; default: off, every pixel takes `spp`). Needs `sample_passes` 1.
    #[serde(default)]
    pub noise_threshold: Option<f64>,
    /// With a noise threshold, the samples every pixel takes before it may stop (1 to
    /// `spp`; default 16, or `spp` if lower). With a time budget, the first pass's samples:
    /// every frame is rendered at this before any is refined (default 4, or `spp`).
    #[serde(default)]
    pub min_spp: Option<u32>,
    /// A time budget in seconds from submission: every frame is rendered at `min_spp`
    /// first, then sample passes go to the frames with the highest estimated error for as
    /// long as the workers' measured speed says they end in time (`spp` caps any pixel).
    /// Needs `sample_passes` 1 and no `noise_threshold` (default: off).
    #[serde(default)]
    pub time_budget: Option<f64>,
    /// Seed mixed into every random number (default 0).
    #[serde(default)]
    pub seed: u32,
    /// The same sampling pattern on every frame (the frame number leaves the random
    /// numbers' key): the noise stays in place across the animation, so denoised frames
    /// flicker less (default: off, each frame its own pattern).
    #[serde(default)]
    pub fixed_pattern: bool,
    /// Clamp light that reaches the camera after two or more surfaces to at most this in
    /// its largest RGB channel (Cycles' "clamp indirect"): fewer fireflies, a little less
    /// light; a finite number above 0 (default: off).
    #[serde(default)]
    pub clamp_indirect: Option<f32>,
    /// Shutter open and close, in frames relative to each frame (default `[0, 0]`: no
    /// motion blur).
    #[serde(default)]
    pub shutter: [f64; 2],
    /// Transform samples across the shutter for motion blur (default: the tracer decides).
    #[serde(default)]
    pub motion_steps: Option<u32>,
    /// The animation that plays, by name (default: all of them).
    #[serde(default)]
    pub animation: Option<String>,
    /// Only workers with every one of these tags take the job's tasks (default: any).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub require_tags: Vec<String>,
    /// Tile side in pixels (default: chosen so one task is a few seconds of work).
    #[serde(default)]
    pub tile_size: Option<u32>,
    /// Each tile's samples split into this many passes, for progressive previews
    /// (default 1).
    #[serde(default = "one")]
    pub sample_passes: u32,
    /// Preview first: every Nth frame of the range (the first, the N+1th, ...) is rendered
    /// before the others fill in, so the whole shot can be seen early (2 or more; default:
    /// frame order). A time budget already renders every frame first.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub preview_every: Option<u32>,
    /// Also tell this URL when the job ends (as the server's `--webhook`s are told; the
    /// server must have a webhook secret to sign with).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub webhook: Option<String>,
    /// Higher runs first (default 0).
    #[serde(default)]
    pub priority: i32,
    /// Attempts per task before it fails (default 3).
    #[serde(default = "default_max_attempts")]
    pub max_attempts: u32,
    /// Layers written to the frames (default all; `beauty` is always written).
    #[serde(default = "default_layers")]
    pub layers: Vec<OutputLayer>,
    /// Denoise each frame once it is assembled (Intel Open Image Denoise, guided by the
    /// albedo and normal): a task that a worker with the library leases; the frame's EXR
    /// gets a `denoised` layer beside the noisy beauty, and its PNG preview shows it
    /// (default: off; on in the `preview` and `final` presets).
    #[serde(default)]
    pub denoise: bool,
    /// When every frame is finished, encode them (their PNG previews) into an H.264 MP4
    /// at `fps`, on a worker with FFmpeg (`GET /jobs/{id}/video`; default: off).
    #[serde(default)]
    pub video: bool,
}

impl JobSpec {
    /// A spec for `scene` with every other field at its default.
    pub fn new(scene: impl Into<String>) -> Self {
        JobSpec {
            scene: scene.into(),
            name: None,
            frames: None,
            fps: default_fps(),
            width: default_width(),
            height: default_height(),
            camera: CameraSpec::Default,
            spp: default_spp(),
            max_depth: default_max_depth(),
            noise_threshold: None,
            min_spp: None,
            time_budget: None,
            seed: 0,
            fixed_pattern: false,
            clamp_indirect: None,
            shutter: [0.0, 0.0],
            motion_steps: None,
            animation: None,
            require_tags: Vec::new(),
            tile_size: None,
            sample_passes: 1,
            preview_every: None,
            webhook: None,
            priority: 0,
            max_attempts: default_max_attempts(),
            layers: default_layers(),
            denoise: false,
            video: false,
        }
    }
}

fn one() -> u32 {
    1
}
fn default_fps() -> f64 {
    24.0
}
fn default_width() -> u32 {
    1280
}
fn default_height() -> u32 {
    720
}
fn default_spp() -> u32 {
    64
}
fn default_max_depth() -> u32 {
    8
}
fn default_max_attempts() -> u32 {
    3
}
fn default_layers() -> Vec<OutputLayer> {
    OutputLayer::ALL.to_vec()
}

/// Where a job stands.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(rename_all = "snake_case")]
pub enum JobState {
    /// No task has been leased yet.
    Queued,
    /// Tasks are being rendered.
    Running,
    /// Paused by a client: nothing is leased until it resumes.
    Paused,
    /// Cancelled by a client; unfinished tasks will not run.
    Cancelled,
    /// A task ran out of attempts; the other frames still finish.
    Failed,
    /// Every frame is assembled.
    Done,
}

/// Tasks of a job by state.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct TaskCounts {
    /// Waiting for a worker.
    pub queued: u64,
    /// Held by a worker.
    pub leased: u64,
    /// Rendered and accepted.
    pub done: u64,
    /// Out of attempts.
    pub failed: u64,
    /// Cancelled with their job.
    pub cancelled: u64,
}

impl TaskCounts {
    /// All tasks.
    pub fn total(&self) -> u64 {
        self.queued + self.leased + self.done + self.failed + self.cancelled
    }
}

/// A job as the server sees it now.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct JobStatus {
    /// The job's id.
    pub id: u64,
    /// Its name.
    pub name: String,
    /// Where it stands.
    pub state: JobState,
    /// The spec with every default filled in (frames and tile size resolved).
    pub spec: JobSpec,
    /// When it was created.
    pub created_ms: i64,
    /// When it reached done, failed or cancelled with nothing left running.
    pub finished_ms: Option<i64>,
    /// Tasks by state.
    pub tasks: TaskCounts,
    /// Frames in the job.
    pub frames_total: u64,
    /// Frames assembled.
    pub frames_done: u64,
    /// Frames with a failed task.
    pub frames_failed: u64,
    /// Finished samples over the job's pixel samples, 0 to 1.
    pub progress: f64,
    /// Pixel samples per second over the accepted tiles, measured from the first lease.
    pub samples_per_second: f64,
    /// Seconds left at that rate, when there is one (for a time-budget job: until the
    /// plan's predicted end).
    pub eta_seconds: Option<f64>,
    /// A time-budget job's plan, as of its last planning.
    pub budget: Option<BudgetPlan>,
    /// Attempts of its tasks that failed since the job was last retried; why, in
    /// `GET /jobs/{id}/failures`.
    #[serde(default)]
    pub attempts_failed: u64,
    /// Why the job cannot go on as things stand (every live worker is blocked from it or
    /// quarantined), and what to do; absent while it can.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stuck: Option<String>,
    /// What the job waits for that no live worker offers now (frames to denoise and no
    /// worker with Open Image Denoise), and what to do. Unlike `stuck`, the job goes on by
    /// itself once such a worker comes; absent while nothing waits.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub waiting: Option<String>,
    /// Its MP4 is made (`GET /jobs/{id}/video`).
    #[serde(default)]
    pub video: bool,
}

/// Where a time-budget job's plan stands. The server plans again whenever a frame is
/// assembled and every few seconds: it measures each live worker's speed on the job, predicts when the work
/// queued and leased ends, and adds a sample pass to the frame with the highest estimated
/// error while the prediction stays inside the deadline.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct BudgetPlan {
    /// The budget, seconds.
    pub budget_seconds: f64,
    /// Submission plus the budget, Unix ms: no work is issued that is predicted to end
    /// after it.
    pub deadline_ms: i64,
    /// When the plan was last made, Unix ms.
    pub planned_ms: i64,
    /// The farm's measured speed on this job: pixel samples per second, summed over the
    /// live workers that have finished one of its tiles.
    pub samples_per_second: f64,
    /// Workers in that sum.
    pub workers: u32,
    /// When the queued and leased work is predicted to end, Unix ms (absent before the
    /// first speed is measured).
    pub predicted_end_ms: Option<i64>,
    /// Sample passes added after the first, over all frames.
    pub passes_added: u32,
    /// What the planner is doing, in words (first pass, refining, or why it stopped).
    pub stage: String,
}

/// `POST /jobs/{id}/priority`: the job's new priority (higher runs first).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct PriorityChange {
    /// The priority, as [`JobSpec::priority`].
    pub priority: i32,
}

/// `POST /jobs/{id}/rerender`: the frames to render again from scratch.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct Rerender {
    /// Frame numbers of the job (at least one; each once).
    pub frames: Vec<i32>,
}

/// `GET /jobs`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct JobList {
    /// Jobs, newest first.
    pub jobs: Vec<JobStatus>,
}

/// Where a frame stands.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(rename_all = "snake_case")]
pub enum FrameState {
    /// No tile accepted yet.
    Queued,
    /// Some tiles accepted.
    Rendering,
    /// A tile ran out of attempts.
    Failed,
    /// Cancelled before it finished.
    Cancelled,
    /// Assembled, and its denoise step is still to run (the job denoises): the EXR has
    /// the noisy layers only so far.
    Denoising,
    /// Finished (assembled, and denoised where the job asks): EXR and PNG can be
    /// downloaded.
    Done,
}

impl FrameState {
    /// Its name on the wire.
    pub fn as_str(self) -> &'static str {
        match self {
            FrameState::Queued => "queued",
            FrameState::Rendering => "rendering",
            FrameState::Failed => "failed",
            FrameState::Cancelled => "cancelled",
            FrameState::Denoising => "denoising",
            FrameState::Done => "done",
        }
    }
}

/// One frame of a job.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct FrameStatus {
    /// Frame number.
    pub frame: i32,
    /// Where it stands.
    pub state: FrameState,
    /// Tasks (tiles × sample passes) in the frame.
    pub tasks_total: u64,
    /// Tasks accepted.
    pub tasks_done: u64,
    /// Mean samples per pixel the frame reached, once assembled.
    pub spp_mean: Option<f64>,
    /// Mean estimated relative error of its pixels, once assembled (absent where no
    /// pixel had enough samples to tell).
    pub noise: Option<f64>,
    /// The EXR's file name in the job's output folder (`frame_0001.exr`).
    pub file: String,
    /// Why its assembly failed, if it did (it is assembled again when the job is retried).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub failure: Option<String>,
}

/// `GET /jobs/{id}/frames`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct FrameList {
    /// Frames in order.
    pub frames: Vec<FrameStatus>,
}

/// The file name of frame `frame` of a sequence whose last frame is `last`: zero padded to
/// four digits, or to as many as `last` has, so the names of a sequence all have one width
/// and sort in frame order (`frame_0001.exr`; `frame_00001.exr` in a sequence that reaches
/// frame 10000).
pub fn frame_file_name(frame: i32, last: i32, extension: &str) -> String {
    let digits = last
        .unsigned_abs()
        .checked_ilog10()
        .map_or(1, |d| d as usize + 1);
    let width = digits.max(4);
    format!("frame_{frame:0width$}.{extension}")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spec_defaults_fill_missing_fields() {
        let spec: JobSpec = serde_json::from_str(r#"{"scene":"abc"}"#).unwrap();
        assert_eq!(spec, JobSpec::new("abc"));
        assert_eq!(spec.layers, OutputLayer::ALL);
    }

    #[test]
    fn unknown_field_is_named() {
        let err = serde_json::from_str::<JobSpec>(r#"{"scene":"a","sppp":4}"#).unwrap_err();
        assert!(err.to_string().contains("sppp"), "{err}");
    }

    #[test]
    fn frame_range_counts_with_step() {
        let r = FrameRange {
            start: 1,
            end: 10,
            step: 3,
        };
        assert_eq!(r.frames().collect::<Vec<_>>(), vec![1, 4, 7, 10]);
        assert_eq!(r.count(), 4);
        assert_eq!(
            FrameRange {
                start: 5,
                end: 4,
                step: 1
            }
            .count(),
            0
        );
    }

    #[test]
    fn camera_spec_json_forms() {
        let c: CameraSpec = serde_json::from_str(r#"{"index":2}"#).unwrap();
        assert_eq!(c, CameraSpec::Index(2));
        let c: CameraSpec = serde_json::from_str(r#"{"name":"Cam"}"#).unwrap();
        assert_eq!(c, CameraSpec::Name("Cam".into()));
        let c: CameraSpec = serde_json::from_str(r#""default""#).unwrap();
        assert_eq!(c, CameraSpec::Default);
    }

    #[test]
    fn frame_files_of_a_sequence_sort_in_frame_order() {
        assert_eq!(frame_file_name(1, 48, "exr"), "frame_0001.exr");
        assert_eq!(frame_file_name(9999, 9999, "exr"), "frame_9999.exr");
        assert_eq!(frame_file_name(12345, 12345, "png"), "frame_12345.png");
        let range = FrameRange {
            start: 9_990,
            end: 10_010,
            step: 3,
        };
        assert_eq!(range.last(), 10_008);
        let names: Vec<String> = range.frames().map(|f| range.file_name(f, "exr")).collect();
        assert_eq!(names[0], "frame_09990.exr");
        let mut sorted = names.clone();
        sorted.sort();
        assert_eq!(sorted, names);
        let big = FrameRange {
            start: 0,
            end: 9_999_999,
            step: 1,
        };
        assert_eq!(big.file_name(7, "png"), "frame_0000007.png");
        let one = FrameRange {
            start: 5,
            end: 5,
            step: 1,
        };
        assert_eq!(one.last(), 5);
    }
}

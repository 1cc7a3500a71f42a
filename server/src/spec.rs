//! Job specs: every field checked against `limits.rs` (the error names the field),
//! defaults resolved against the scene, and the job split into tasks
//! (frame × tile × sample pass).

use proto::{CameraSpec, FrameRange, JobSpec, OutputLayer, SceneInfo};
use tracer::film::{SampleRange, TileRect};

use crate::limits::*;

/// A spec field that is out of bounds or does not fit the scene.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FieldError {
    /// The field, as named in the JSON (`width`, `frames.end`, ...).
    pub field: String,
    /// What is wrong, for a person.
    pub message: String,
}

fn bad<T>(field: &str, message: impl Into<String>) -> Result<T, FieldError> {
    Err(FieldError {
        field: field.to_string(),
        message: message.into(),
    })
}

/// A checked job: the spec with its defaults resolved, and how it splits into tasks.
#[derive(Clone, Debug, PartialEq)]
pub struct Plan {
    /// The spec, every optional field filled in.
    pub spec: JobSpec,
    /// Frame numbers.
    pub frames: Vec<i32>,
    /// Tiles of one frame, row by row.
    pub tiles: Vec<TileRect>,
    /// Sample passes of one tile, in order.
    pub passes: Vec<SampleRange>,
}

/// One task of a plan.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PlannedTask {
    /// Frame number.
    pub frame: i32,
    /// Index into [`Plan::tiles`].
    pub tile: u32,
    /// Index into [`Plan::passes`].
    pub pass: u32,
    /// The tile.
    pub rect: TileRect,
    /// The samples.
    pub samples: SampleRange,
    /// Tasks of round 0 are leased before those of round 1 ([`JobSpec::preview_every`]).
    pub round: u32,
}

impl Plan {
    /// Number of tasks.
    pub fn task_count(&self) -> u64 {
        self.frames.len() as u64 * self.tiles.len() as u64 * self.passes.len() as u64
    }

    /// Tasks per frame.
    pub fn tasks_per_frame(&self) -> u64 {
        self.tiles.len() as u64 * self.passes.len() as u64
    }

    /// Pixel samples of the tasks planned (a time budget adds more as it goes).
    pub fn pixel_samples(&self) -> u64 {
        let per_pixel: u64 = self.passes.iter().map(|p| u64::from(p.len())).sum();
        self.frames.len() as u64 * self.spec.width as u64 * self.spec.height as u64 * per_pixel
    }

    /// The round of the `index`th frame: 0 for every `preview_every`th, else 1 (all 0
    /// without it).
    pub fn round(&self, index: usize) -> u32 {
        match self.spec.preview_every {
            Some(n) if !index.is_multiple_of(n as usize) => 1,
            _ => 0,
        }
    }

    /// Every task, frame by frame, pass by pass, tile by tile.
    pub fn tasks(&self) -> impl Iterator<Item = PlannedTask> + '_ {
        self.frames.iter().enumerate().flat_map(move |(i, &frame)| {
            let round = self.round(i);
            self.passes
                .iter()
                .enumerate()
                .flat_map(move |(p, &samples)| {
                    self.tiles
                        .iter()
                        .enumerate()
                        .map(move |(t, &rect)| PlannedTask {
                            frame,
                            tile: t as u32,
                            pass: p as u32,
                            rect,
                            samples,
                            round,
                        })
                })
        })
    }
}

/// The tile side that makes one task about [`TARGET_TASK_PIXEL_SAMPLES`]: a power of two
/// between 16 and 256.
pub fn default_tile_size(spp_per_pass: u32) -> u32 {
    let side = (TARGET_TASK_PIXEL_SAMPLES as f64 / spp_per_pass.max(1) as f64).sqrt();
    let mut s = 16u32;
    while s < 256 && ((s * 2) as f64) <= side {
        s *= 2;
    }
    s
}

/// Tags (a worker's, or those a job requires) are at most [`MAX_TAGS`] words of 1 to
/// [`MAX_TAG_BYTES`] ASCII letters, digits, `-`, `_` and `.`; `field` names them.
pub fn check_tags(field: &str, tags: &[String]) -> Result<(), FieldError> {
    if tags.len() > MAX_TAGS {
        return bad(
            field,
            format!("at most {MAX_TAGS} tags, got {}", tags.len()),
        );
    }
    for tag in tags {
        let fine = |b: u8| b.is_ascii_alphanumeric() || matches!(b, b'-' | b'_' | b'.');
        if tag.is_empty() || tag.len() > MAX_TAG_BYTES || !tag.bytes().all(fine) {
            return bad(
                field,
                format!(
                    "`{tag}`: a tag is 1 to {MAX_TAG_BYTES} ASCII letters, digits, `-`, `_` \
                     and `.`"
                ),
            );
        }
    }
    Ok(())
}

/// A job's priority is within [`MAX_PRIORITY`] either way.
pub fn check_priority(priority: i32) -> Result<(), FieldError> {
    if priority.abs() > MAX_PRIORITY {
        return bad(
            "priority",
            format!("must be -{MAX_PRIORITY} to {MAX_PRIORITY}, got {priority}"),
        );
    }
    Ok(())
}

/// Checks `spec` against the limits and `scene`, and plans its tasks.
pub fn plan(mut spec: JobSpec, scene: &SceneInfo, max_tasks: u64) -> Result<Plan, FieldError> {
    if spec.scene != scene.digest {
        return bad("scene", "internal: spec checked against another scene");
    }
    if let Some(name) = &spec.name {
        if name.len() > MAX_NAME_BYTES {
            return bad(
                "name",
                format!("is {} bytes; at most {MAX_NAME_BYTES}", name.len()),
            );
        }
    }
    if !(spec.fps.is_finite() && spec.fps > 0.0 && spec.fps <= MAX_FPS) {
        return bad(
            "fps",
            format!("must be above 0 and at most {MAX_FPS}, got {}", spec.fps),
        );
    }
    for (field, v) in [("width", spec.width), ("height", spec.height)] {
        if v == 0 || v > MAX_RESOLUTION {
            return bad(
                field,
                format!("must be 1 to {MAX_RESOLUTION} pixels, got {v}"),
            );
        }
    }
    if spec.spp == 0 || spec.spp > MAX_SPP {
        return bad("spp", format!("must be 1 to {MAX_SPP}, got {}", spec.spp));
    }
    if spec.max_depth > MAX_DEPTH {
        return bad(
            "max_depth",
            format!("must be at most {MAX_DEPTH}, got {}", spec.max_depth),
        );
    }
    let [open, close] = spec.shutter;
    if !(open.is_finite() && close.is_finite())
        || open > close
        || open.abs() > MAX_SHUTTER_FRAMES
        || close.abs() > MAX_SHUTTER_FRAMES
    {
        return bad(
            "shutter",
            format!(
                "must be [open, close] in frames with open <= close, both within \
                 ±{MAX_SHUTTER_FRAMES}; got [{open}, {close}]"
            ),
        );
    }
    if let Some(steps) = spec.motion_steps {
        if steps == 0 || steps > MAX_MOTION_STEPS {
            return bad(
                "motion_steps",
                format!("must be 1 to {MAX_MOTION_STEPS}, got {steps}"),
            );
        }
    }
    let animation = match &spec.animation {
        None => None,
        Some(name) => match scene
            .animations
            .iter()
            .find(|a| a.name.as_deref() == Some(name))
        {
            Some(a) => Some(a),
            None => {
                return bad(
                    "animation",
                    format!(
                        "the scene has no animation named `{name}`{}",
                        names_of(scene.animations.iter().filter_map(|a| a.name.as_deref()))
                    ),
                )
            }
        },
    };
    match &spec.camera {
        CameraSpec::Default => {}
        CameraSpec::Index(i) => {
            if *i as usize >= scene.cameras.len() {
                return bad(
                    "camera",
                    format!(
                        "camera {i} does not exist: the scene has {} camera(s)",
                        scene.cameras.len()
                    ),
                );
            }
        }
        CameraSpec::Name(name) => {
            if !scene
                .cameras
                .iter()
                .any(|c| c.name.as_deref() == Some(name))
            {
                return bad(
                    "camera",
                    format!(
                        "the scene has no camera named `{name}`{}",
                        names_of(scene.cameras.iter().filter_map(|c| c.name.as_deref()))
                    ),
                );
            }
        }
    }
    let frames = match spec.frames {
        Some(r) => r,
        None => {
            // The animation range at the job's fps: frame f shows time f / fps.
            let (start, end) = match animation {
                Some(a) => (a.start_seconds, a.end_seconds),
                None => (0.0, scene.duration_seconds),
            };
            FrameRange {
                start: (start * spec.fps).floor().max(0.0) as i32,
                end: (end * spec.fps).ceil().min(MAX_FRAME_NUMBER as f64) as i32,
                step: 1,
            }
        }
    };
    if frames.step == 0 {
        return bad("frames.step", "must be at least 1");
    }
    if frames.start < 0 || frames.start > MAX_FRAME_NUMBER {
        return bad(
            "frames.start",
            format!("must be 0 to {MAX_FRAME_NUMBER}, got {}", frames.start),
        );
    }
    if frames.end < frames.start || frames.end > MAX_FRAME_NUMBER {
        return bad(
            "frames.end",
            format!(
                "must be from frames.start ({}) to {MAX_FRAME_NUMBER}, got {}",
                frames.start, frames.end
            ),
        );
    }
    if frames.count() > MAX_FRAMES {
        return bad(
            "frames",
            format!("{} frames; at most {MAX_FRAMES} per job", frames.count()),
        );
    }
    spec.frames = Some(frames);
    if spec.sample_passes == 0 || spec.sample_passes > MAX_SAMPLE_PASSES.min(spec.spp) {
        return bad(
            "sample_passes",
            format!(
                "must be 1 to {} (at most {MAX_SAMPLE_PASSES} and at most spp), got {}",
                MAX_SAMPLE_PASSES.min(spec.spp),
                spec.sample_passes
            ),
        );
    }
    if let Some(n) = spec.preview_every {
        if n < 2 {
            return bad("preview_every", format!("must be 2 or more, got {n}"));
        }
        if spec.time_budget.is_some() {
            return bad(
                "preview_every",
                "cannot be combined with a time_budget, which renders every frame first",
            );
        }
    }
    if let Some(budget) = spec.time_budget {
        if !(budget.is_finite() && budget > 0.0 && budget <= MAX_TIME_BUDGET_SECONDS) {
            return bad(
                "time_budget",
                format!(
                    "must be above 0 and at most {MAX_TIME_BUDGET_SECONDS} seconds, got {budget}"
                ),
            );
        }
        if spec.noise_threshold.is_some() {
            return bad(
                "time_budget",
                "cannot be combined with a noise_threshold: the budget decides the samples",
            );
        }
        if spec.sample_passes != 1 {
            return bad(
                "time_budget",
                format!(
                    "needs sample_passes 1 (the budget adds the passes), got {}",
                    spec.sample_passes
                ),
            );
        }
        match spec.min_spp {
            Some(m) if m == 0 || m > spec.spp => {
                return bad(
                    "min_spp",
                    format!("must be 1 to spp ({}), got {m}", spec.spp),
                )
            }
            Some(_) => {}
            None => spec.min_spp = Some(proto::job::DEFAULT_BUDGET_MIN_SPP.min(spec.spp)),
        }
    }
    if let Some(limit) = spec.clamp_indirect {
        if let Err(e) = tracer::settings::check_clamp(limit) {
            return bad("clamp_indirect", e);
        }
    }
    match (spec.noise_threshold, spec.min_spp) {
        (Some(t), _) if !(t.is_finite() && t > 0.0 && t <= 1.0) => {
            return bad(
                "noise_threshold",
                format!("must be above 0 and at most 1 (0.01 is clean, 0.1 rough), got {t}"),
            );
        }
        (Some(_), _) if spec.sample_passes != 1 => {
            return bad(
                "noise_threshold",
                format!(
                    "needs sample_passes 1 (a pixel decides when to stop over all its \
                     samples), got {}",
                    spec.sample_passes
                ),
            );
        }
        (Some(_), Some(m)) if m == 0 || m > spec.spp => {
            return bad(
                "min_spp",
                format!("must be 1 to spp ({}), got {m}", spec.spp),
            );
        }
        (Some(_), None) => spec.min_spp = Some(proto::job::DEFAULT_MIN_SPP.min(spec.spp)),
        (None, Some(_)) if spec.time_budget.is_none() => {
            return bad("min_spp", "needs a noise_threshold or a time_budget")
        }
        _ => {}
    }
    let tile_size = match spec.tile_size {
        Some(s) if !(MIN_TILE_SIZE..=MAX_TILE_SIZE).contains(&s) => {
            return bad(
                "tile_size",
                format!("must be {MIN_TILE_SIZE} to {MAX_TILE_SIZE} pixels, got {s}"),
            )
        }
        Some(s) => s,
        // A time budget's passes grow from min_spp towards spp: tiles sized for a middle
        // pass keep the first pass's tasks from being tiny and the last ones from being long.
        None if spec.time_budget.is_some() => default_tile_size(spec.spp.min(BUDGET_TILE_SPP)),
        None => default_tile_size(spec.spp.div_ceil(spec.sample_passes)),
    };
    spec.tile_size = Some(tile_size);
    check_priority(spec.priority)?;
    check_tags("require_tags", &spec.require_tags)?;
    if spec.max_attempts == 0 || spec.max_attempts > MAX_ATTEMPTS {
        return bad(
            "max_attempts",
            format!("must be 1 to {MAX_ATTEMPTS}, got {}", spec.max_attempts),
        );
    }
    if !spec.layers.contains(&OutputLayer::Beauty) {
        return bad("layers", "must include `beauty`");
    }
    for (i, l) in spec.layers.iter().enumerate() {
        if spec.layers[..i].contains(l) {
            return bad("layers", format!("`{}` is listed twice", layer_name(*l)));
        }
    }
    spec.layers = OutputLayer::ALL
        .into_iter()
        .filter(|l| spec.layers.contains(l))
        .collect();

    // Counted before anything is built: a 16384² frame in 8-pixel tiles is 4M tiles.
    let tile_count = spec.width.div_ceil(tile_size) as u64 * spec.height.div_ceil(tile_size) as u64;
    let n = spec.sample_passes as u64;
    let task_count = frames.count() * tile_count * n;
    if task_count > max_tasks {
        return bad(
            "tile_size",
            format!(
                "{} frames × {tile_count} tiles × {n} sample passes = {task_count} tasks, over \
                 this server's limit of {max_tasks}; use a larger tile_size, fewer \
                 sample_passes or fewer frames",
                frames.count(),
            ),
        );
    }

    let tiles = TileRect::new(0, 0, spec.width, spec.height).tiles(tile_size);
    let passes = match (spec.time_budget, spec.min_spp) {
        // A time budget starts with one pass of min_spp; it plans the rest as it goes.
        (Some(_), Some(first)) => vec![SampleRange::new(0, first)],
        _ => (0..n)
            .map(|p| {
                let at = |k: u64| (spec.spp as u64 * k / n) as u32;
                SampleRange::new(at(p), at(p + 1))
            })
            .collect(),
    };
    let plan = Plan {
        frames: frames.frames().collect(),
        tiles,
        passes,
        spec,
    };
    debug_assert_eq!(plan.task_count(), task_count);
    Ok(plan)
}

/// `OutputLayer` as written in JSON.
pub fn layer_name(l: OutputLayer) -> &'static str {
    match l {
        OutputLayer::Beauty => "beauty",
        OutputLayer::Albedo => "albedo",
        OutputLayer::Normal => "normal",
        OutputLayer::Depth => "depth",
        OutputLayer::Samples => "samples",
        OutputLayer::Noise => "noise",
        OutputLayer::Motion => "motion",
        OutputLayer::Variance => "variance",
    }
}

/// `; it has: a, b` (or `; it has none`).
fn names_of<'a>(names: impl Iterator<Item = &'a str>) -> String {
    let names: Vec<&str> = names.collect();
    if names.is_empty() {
        "; it has no named ones".to_string()
    } else {
        format!("; it has: {}", names.join(", "))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proto::{AnimationInfo, CameraInfo};

    fn scene() -> SceneInfo {
        SceneInfo {
            digest: "d".repeat(64),
            size: 1,
            cameras: vec![CameraInfo {
                index: 0,
                name: Some("Main".into()),
            }],
            animations: vec![AnimationInfo {
                index: 0,
                name: Some("Walk".into()),
                start_seconds: 0.5,
                end_seconds: 2.0,
            }],
            duration_seconds: 2.0,
            triangles: 12,
            meshes: 1,
            instances: 1,
            materials: 1,
            ..Default::default()
        }
    }

    fn spec() -> JobSpec {
        JobSpec::new("d".repeat(64))
    }

    fn field_of(spec: JobSpec) -> String {
        plan(spec, &scene(), 1_000_000).unwrap_err().field
    }

    #[test]
    fn frames_default_to_the_animation_range_at_the_job_fps() {
        let p = plan(spec(), &scene(), 1_000_000).unwrap();
        // 0 s to 2 s at 24 fps.
        assert_eq!(
            p.spec.frames,
            Some(FrameRange {
                start: 0,
                end: 48,
                step: 1
            })
        );
        let mut s = spec();
        s.animation = Some("Walk".into());
        s.fps = 10.0;
        let p = plan(s, &scene(), 1_000_000).unwrap();
        assert_eq!(
            p.spec.frames,
            Some(FrameRange {
                start: 5,
                end: 20,
                step: 1
            })
        );
    }

    #[test]
    fn split_is_frames_times_tiles_times_passes() {
        let mut s = spec();
        s.frames = Some(FrameRange {
            start: 1,
            end: 3,
            step: 1,
        });
        s.width = 100;
        s.height = 50;
        s.tile_size = Some(32);
        s.spp = 10;
        s.sample_passes = 3;
        let p = plan(s, &scene(), 1_000_000).unwrap();
        // 4 × 2 tiles, 3 passes, 3 frames.
        assert_eq!(p.tiles.len(), 8);
        assert_eq!(
            p.passes,
            vec![
                SampleRange::new(0, 3),
                SampleRange::new(3, 6),
                SampleRange::new(6, 10)
            ]
        );
        assert_eq!(p.task_count(), 72);
        assert_eq!(p.tasks().count(), 72);
        assert_eq!(p.tiles[7], TileRect::new(96, 32, 4, 18));
        assert_eq!(p.pixel_samples(), 3 * 100 * 50 * 10);
    }

    #[test]
    fn default_tile_is_a_few_seconds_of_work() {
        assert_eq!(default_tile_size(64), 128);
        assert_eq!(default_tile_size(256), 64);
        assert_eq!(default_tile_size(1), 256);
        assert_eq!(default_tile_size(1_000_000), 16);
    }

    #[test]
    fn each_limit_names_its_field() {
        type Change = Box<dyn Fn(&mut JobSpec)>;
        let cases: Vec<(&str, Change)> = vec![
            ("width", Box::new(|s| s.width = MAX_RESOLUTION + 1)),
            ("height", Box::new(|s| s.height = 0)),
            ("spp", Box::new(|s| s.spp = MAX_SPP + 1)),
            ("spp", Box::new(|s| s.spp = 0)),
            ("fps", Box::new(|s| s.fps = f64::NAN)),
            ("fps", Box::new(|s| s.fps = MAX_FPS * 2.0)),
            ("max_depth", Box::new(|s| s.max_depth = MAX_DEPTH + 1)),
            ("clamp_indirect", Box::new(|s| s.clamp_indirect = Some(0.0))),
            (
                "clamp_indirect",
                Box::new(|s| s.clamp_indirect = Some(f32::INFINITY)),
            ),
            (
                "noise_threshold",
                Box::new(|s| s.noise_threshold = Some(0.0)),
            ),
            (
                "noise_threshold",
                Box::new(|s| s.noise_threshold = Some(f64::NAN)),
            ),
            (
                "noise_threshold",
                Box::new(|s| s.noise_threshold = Some(1.5)),
            ),
            (
                "noise_threshold",
                Box::new(|s| {
                    s.noise_threshold = Some(0.1);
                    s.sample_passes = 2;
                }),
            ),
            (
                "min_spp",
                Box::new(|s| {
                    s.noise_threshold = Some(0.1);
                    s.min_spp = Some(s.spp + 1);
                }),
            ),
            (
                "min_spp",
                Box::new(|s| {
                    s.noise_threshold = Some(0.1);
                    s.min_spp = Some(0);
                }),
            ),
            ("min_spp", Box::new(|s| s.min_spp = Some(4))),
            ("preview_every", Box::new(|s| s.preview_every = Some(1))),
            (
                "preview_every",
                Box::new(|s| {
                    s.preview_every = Some(4);
                    s.time_budget = Some(60.0);
                }),
            ),
            ("time_budget", Box::new(|s| s.time_budget = Some(0.0))),
            (
                "time_budget",
                Box::new(|s| s.time_budget = Some(f64::INFINITY)),
            ),
            (
                "time_budget",
                Box::new(|s| s.time_budget = Some(MAX_TIME_BUDGET_SECONDS + 1.0)),
            ),
            (
                "time_budget",
                Box::new(|s| {
                    s.time_budget = Some(60.0);
                    s.noise_threshold = Some(0.1);
                }),
            ),
            (
                "time_budget",
                Box::new(|s| {
                    s.time_budget = Some(60.0);
                    s.sample_passes = 2;
                }),
            ),
            (
                "min_spp",
                Box::new(|s| {
                    s.time_budget = Some(60.0);
                    s.min_spp = Some(s.spp + 1);
                }),
            ),
            ("shutter", Box::new(|s| s.shutter = [0.5, 0.0])),
            (
                "shutter",
                Box::new(|s| s.shutter = [0.0, MAX_SHUTTER_FRAMES + 1.0]),
            ),
            ("motion_steps", Box::new(|s| s.motion_steps = Some(0))),
            (
                "motion_steps",
                Box::new(|s| s.motion_steps = Some(MAX_MOTION_STEPS + 1)),
            ),
            ("animation", Box::new(|s| s.animation = Some("Run".into()))),
            ("camera", Box::new(|s| s.camera = CameraSpec::Index(1))),
            (
                "camera",
                Box::new(|s| s.camera = CameraSpec::Name("Side".into())),
            ),
            (
                "frames.step",
                Box::new(|s| {
                    s.frames = Some(FrameRange {
                        start: 0,
                        end: 1,
                        step: 0,
                    })
                }),
            ),
            (
                "frames.start",
                Box::new(|s| {
                    s.frames = Some(FrameRange {
                        start: -1,
                        end: 1,
                        step: 1,
                    })
                }),
            ),
            (
                "frames.end",
                Box::new(|s| {
                    s.frames = Some(FrameRange {
                        start: 5,
                        end: 4,
                        step: 1,
                    })
                }),
            ),
            (
                "frames",
                Box::new(|s| {
                    s.frames = Some(FrameRange {
                        start: 0,
                        end: MAX_FRAMES as i32,
                        step: 1,
                    })
                }),
            ),
            ("sample_passes", Box::new(|s| s.sample_passes = 0)),
            (
                "sample_passes",
                Box::new(|s| {
                    s.spp = 4;
                    s.sample_passes = 5
                }),
            ),
            (
                "tile_size",
                Box::new(|s| s.tile_size = Some(MIN_TILE_SIZE - 1)),
            ),
            (
                "tile_size",
                Box::new(|s| s.tile_size = Some(MAX_TILE_SIZE + 1)),
            ),
            ("priority", Box::new(|s| s.priority = -MAX_PRIORITY - 1)),
            ("max_attempts", Box::new(|s| s.max_attempts = 0)),
            (
                "max_attempts",
                Box::new(|s| s.max_attempts = MAX_ATTEMPTS + 1),
            ),
            ("layers", Box::new(|s| s.layers = vec![OutputLayer::Depth])),
            (
                "layers",
                Box::new(|s| s.layers = vec![OutputLayer::Beauty, OutputLayer::Beauty]),
            ),
            (
                "name",
                Box::new(|s| s.name = Some("x".repeat(MAX_NAME_BYTES + 1))),
            ),
        ];
        for (field, change) in cases {
            let mut s = spec();
            change(&mut s);
            assert_eq!(field_of(s.clone()), field, "{s:?}");
        }
    }

    #[test]
    fn limits_themselves_are_accepted() {
        let mut s = spec();
        s.width = MAX_RESOLUTION;
        s.height = 8;
        s.spp = MAX_SPP;
        s.max_depth = MAX_DEPTH;
        s.tile_size = Some(MAX_TILE_SIZE);
        s.frames = Some(FrameRange {
            start: 0,
            end: 0,
            step: 1,
        });
        s.camera = CameraSpec::Name("Main".into());
        s.layers = vec![OutputLayer::Depth, OutputLayer::Beauty];
        let p = plan(s, &scene(), 1_000_000).unwrap();
        assert_eq!(p.tiles.len(), 16);
        assert_eq!(p.spec.layers, vec![OutputLayer::Beauty, OutputLayer::Depth]);
        let mut s = spec();
        s.time_budget = Some(MAX_TIME_BUDGET_SECONDS);
        s.min_spp = Some(s.spp);
        plan(s, &scene(), 1_000_000).unwrap();
    }

    /// The render bounds are the tracer's own: a spec at every one of them is accepted
    /// here and its frame options pass the tracer's check; one past fails both.
    #[test]
    fn a_spec_at_the_tracers_bounds_is_one_the_tracer_renders() {
        let options = |p: &JobSpec| tracer::render::FrameOptions {
            fps: p.fps,
            shutter: tracer::motion::Shutter {
                open: p.shutter[0],
                close: p.shutter[1],
            },
            motion_steps: p.motion_steps,
            width: p.width,
            height: p.height,
            ..Default::default()
        };
        let mut s = spec();
        (s.width, s.height) = (MAX_RESOLUTION, MAX_RESOLUTION);
        s.fps = MAX_FPS;
        s.shutter = [-MAX_SHUTTER_FRAMES, MAX_SHUTTER_FRAMES];
        s.motion_steps = Some(MAX_MOTION_STEPS);
        let p = plan(s.clone(), &scene(), u64::MAX).unwrap();
        assert_eq!(options(&p.spec).check(), Ok(()));
        type Change = fn(&mut JobSpec);
        let past: [(&str, Change); 4] = [
            ("width", |s| s.width += 1),
            ("fps", |s| s.fps *= 1.5),
            ("shutter", |s| s.shutter[1] *= 1.5),
            ("motion_steps", |s| {
                s.motion_steps = Some(MAX_MOTION_STEPS + 1)
            }),
        ];
        for (field, change) in past {
            let mut s = s.clone();
            change(&mut s);
            assert!(options(&s).check().is_err(), "{field}");
            assert_eq!(field_of(s), field);
        }
    }

    /// A time budget starts with one pass of min_spp (default 4) per tile; the rest is
    /// planned as the job runs.
    #[test]
    fn a_time_budget_plans_only_the_first_pass() {
        let mut s = spec();
        s.spp = 1024;
        s.time_budget = Some(20.0);
        let p = plan(s.clone(), &scene(), 1_000_000).unwrap();
        assert_eq!(p.spec.min_spp, Some(proto::job::DEFAULT_BUDGET_MIN_SPP));
        assert_eq!(p.passes, vec![SampleRange::new(0, 4)]);
        assert_eq!(p.spec.tile_size, Some(default_tile_size(BUDGET_TILE_SPP)));
        assert_eq!(
            p.pixel_samples(),
            p.frames.len() as u64 * u64::from(s.width * s.height) * 4
        );
        s.min_spp = Some(16);
        let p = plan(s, &scene(), 1_000_000).unwrap();
        assert_eq!(p.passes, vec![SampleRange::new(0, 16)]);
    }

    /// Bytes allocated by the current thread, for the test below: a wrapper around the
    /// system allocator that counts in a thread-local, so tests running beside it on other
    /// threads do not disturb the count.
    mod counting {
        use std::alloc::{GlobalAlloc, Layout, System};
        use std::cell::Cell;

        thread_local! {
            static BYTES: Cell<u64> = const { Cell::new(0) };
        }

        fn add(n: usize) {
            let _ = BYTES.try_with(|b| b.set(b.get() + n as u64));
        }

        /// Bytes this thread has allocated so far.
        pub fn allocated() -> u64 {
            BYTES.with(|b| b.get())
        }

        struct Counting;

        unsafe impl GlobalAlloc for Counting {
            unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
                add(layout.size());
                System.alloc(layout)
            }
            unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
                System.dealloc(ptr, layout)
            }
            unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
                add(new_size);
                System.realloc(ptr, layout, new_size)
            }
        }

        #[global_allocator]
        static COUNTING: Counting = Counting;
    }

    /// Found by `fuzz/job_spec`: a 16384² frame in 8-pixel tiles (4M tasks) built its 64 MB
    /// of tiles before the task limit refused it.
    #[test]
    fn task_limit_refuses_before_building_tiles() {
        let mut s = spec();
        s.width = MAX_RESOLUTION;
        s.height = MAX_RESOLUTION;
        s.tile_size = Some(MIN_TILE_SIZE);
        s.frames = Some(FrameRange {
            start: 0,
            end: 0,
            step: 1,
        });
        let scene = scene();
        let before = counting::allocated();
        let err = plan(s, &scene, DEFAULT_MAX_TASKS_PER_JOB).unwrap_err();
        let allocated = counting::allocated() - before;
        assert_eq!(err.field, "tile_size");
        assert!(err.message.contains("4194304 tasks"), "{}", err.message);
        assert!(
            allocated < 64 << 10,
            "{allocated} bytes allocated to refuse"
        );
    }

    #[test]
    fn task_limit_is_configurable_and_named() {
        let mut s = spec();
        s.frames = Some(FrameRange {
            start: 0,
            end: 9,
            step: 1,
        });
        s.width = 64;
        s.height = 64;
        s.tile_size = Some(32);
        assert_eq!(plan(s.clone(), &scene(), 40).unwrap().task_count(), 40);
        let err = plan(s, &scene(), 39).unwrap_err();
        assert_eq!(err.field, "tile_size");
        assert!(err.message.contains("40 tasks"), "{}", err.message);
    }
}

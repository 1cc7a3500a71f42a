//! `tessera submit`: pack a scene into a GLB, upload it, create a job; with `--wait`, follow
//! it with a progress bar and download the frames. [`JobArgs::to_spec`] is the one place
//! where command-line settings become a [`JobSpec`] (the demo builds its job with it too).

use std::path::{Path, PathBuf};

use anyhow::Context;
use clap::Args;
use proto::job::Quality;
use proto::{CameraSpec, JobSpec, SceneInfo};
use tracer::motion::Shutter;
use tracer::render::CameraChoice;

use crate::args::{parse_camera, parse_frames, parse_shutter, parse_size, FrameRange};
use crate::client::{Client, ServerOpts};
use crate::progress::{self, Followed};

/// The render settings of a job. Every one left out keeps the server's default
/// (`JobSpec::new`): frames = the scene's animation range, 24 fps, 1280x720, 64 spp.
#[derive(Args, Clone, Debug, Default, PartialEq)]
pub struct JobArgs {
    /// Frames A-B or A-B:STEP (default: the scene's animation range at --fps; frame 0 for
    /// a still scene).
    #[arg(long, value_parser = parse_frames)]
    pub frames: Option<FrameRange>,
    /// Frames per second: frame f shows time f / fps [default: 24].
    #[arg(long, allow_hyphen_values = true)]
    pub fps: Option<f64>,
    /// A quality preset: draft, preview or final (README.md lists what each sets);
    /// --spp, --max-depth, --noise-threshold, --min-spp and --no-denoise override its
    /// parts.
    #[arg(long)]
    pub quality: Option<Quality>,
    /// Denoise each frame once it is assembled, on a worker with Intel Open Image Denoise
    /// (`tessera install oidn`): the EXR gets a `denoised` layer beside the noisy beauty
    /// and the PNG shows it [default: off; on in the preview and final presets].
    #[arg(long, conflicts_with = "no_denoise")]
    pub denoise: bool,
    /// Do not denoise, whatever the preset says.
    #[arg(long)]
    pub no_denoise: bool,
    /// When every frame is finished, encode them into an H.264 MP4 at --fps on a worker
    /// with FFmpeg (`tessera install ffmpeg`); `--wait --out DIR` downloads it as
    /// DIR/video.mp4 [default: off].
    #[arg(long)]
    pub video: bool,
    /// Samples per pixel; with a noise threshold, the most a pixel takes [default: 64].
    #[arg(long)]
    pub spp: Option<u32>,
    /// Adaptive sampling: a pixel stops once its estimated relative error is at most
    /// this (0.01 is clean, 0.1 rough) [default: off].
    #[arg(long, allow_hyphen_values = true)]
    pub noise_threshold: Option<f64>,
    /// With a noise threshold, the samples every pixel takes before it may stop
    /// [default: 16, or the preset's; at most --spp]. With a time budget, the first
    /// pass's samples [default: 4].
    #[arg(long)]
    pub min_spp: Option<u32>,
    /// Finish within this many seconds of submission on the workers there are: every
    /// frame first at --min-spp, then more samples for the noisiest frames while the
    /// farm's measured speed says they end in time (--spp caps a pixel; a preset gives
    /// the cap and the bounces, not its noise threshold) [default: off].
    #[arg(long, allow_hyphen_values = true)]
    pub time_budget: Option<f64>,
    /// Image size WIDTHxHEIGHT [default: 1280x720].
    #[arg(long, value_parser = parse_size)]
    pub size: Option<(u32, u32)>,
    /// Tile side in pixels [default: the server picks one so a task is a few seconds].
    #[arg(long)]
    pub tile: Option<u32>,
    /// Shutter OPEN,CLOSE in frames around each frame's time, e.g. -0.25,0.25 (a 180°
    /// shutter) for motion blur [default: 0,0].
    #[arg(long, value_parser = parse_shutter, allow_hyphen_values = true)]
    pub shutter: Option<Shutter>,
    /// Split each tile's samples into this many passes, for progressive previews
    /// [default: 1].
    #[arg(long)]
    pub passes: Option<u32>,
    /// Preview first: render every Nth frame of the range before the others fill in, so
    /// the whole shot can be seen early [default: frame order].
    #[arg(long, value_name = "N")]
    pub preview_every: Option<u32>,
    /// Also tell this URL when the job ends (the server signs it with its webhook secret).
    #[arg(long, value_name = "URL")]
    pub webhook: Option<String>,
    /// Higher runs first [default: 0].
    #[arg(long, allow_hyphen_values = true)]
    pub priority: Option<i32>,
    /// Attempts each task gets before it fails for good (a worker that fails 3 of the
    /// job's tasks is kept off it) [default: 3].
    #[arg(long)]
    pub max_attempts: Option<u32>,
    /// Camera by glTF index or name [default: the scene's first].
    #[arg(long, value_parser = parse_camera)]
    pub camera: Option<CameraChoice>,
    /// Maximum bounces [default: 8].
    #[arg(long)]
    pub max_depth: Option<u32>,
    /// Seed mixed into every random number [default: 0].
    #[arg(long)]
    pub seed: Option<u32>,
    /// The same sampling pattern on every frame: the noise stays in place across the
    /// animation, so denoised frames flicker less [default: each frame its own].
    #[arg(long)]
    pub fixed_pattern: bool,
    /// Clamp light that reaches the camera after two or more surfaces to at most this in
    /// its largest RGB channel: fewer fireflies, a little less light [default: off].
    #[arg(long, value_parser = crate::args::parse_clamp)]
    pub clamp_indirect: Option<f32>,
    /// Motion steps across an open shutter [default: the tracer decides].
    #[arg(long)]
    pub motion_steps: Option<u32>,
    /// Play only this animation, by glTF name or index [default: all of them].
    #[arg(long)]
    pub animation: Option<String>,
    /// A name for the job [default: `job <id>`].
    #[arg(long)]
    pub name: Option<String>,
    /// Only workers with every one of these tags (comma-separated, as given to
    /// `tessera worker --tags`) take the job [default: any worker].
    #[arg(long, value_delimiter = ',')]
    pub require_tags: Option<Vec<String>>,
}

impl JobArgs {
    /// The job spec for `scene` (as the server described it on upload): the given
    /// settings, the spec's defaults for the rest. An `--animation` given as an index is
    /// turned into that animation's name (the spec names animations).
    pub fn to_spec(&self, scene: &SceneInfo) -> anyhow::Result<JobSpec> {
        let mut spec = JobSpec::new(scene.digest.clone());
        self.overlay(&mut spec, scene)?;
        Ok(spec)
    }

    /// Changes in `spec` (of a job of `scene`) what these settings give, and nothing else:
    /// how `tessera clone` changes a job's settings.
    pub fn overlay(&self, spec: &mut JobSpec, scene: &SceneInfo) -> anyhow::Result<()> {
        if self.name.is_some() {
            spec.name = self.name.clone();
        }
        if self.frames.is_some() {
            spec.frames = self.frames;
        }
        if let Some(fps) = self.fps {
            spec.fps = fps;
        }
        if let Some((w, h)) = self.size {
            (spec.width, spec.height) = (w, h);
        }
        if let Some(q) = self.quality {
            let preset = q.settings();
            spec.spp = preset.spp;
            spec.max_depth = preset.max_depth;
            spec.noise_threshold = Some(preset.noise_threshold);
            spec.min_spp = Some(preset.min_spp);
            spec.denoise = preset.denoise;
        }
        if let Some(spp) = self.spp {
            spec.spp = spp;
            // A preset's minimum is cut to an explicit maximum.
            spec.min_spp = spec.min_spp.map(|m| m.min(spp));
        }
        if let Some(t) = self.noise_threshold {
            spec.noise_threshold = Some(t);
        }
        if self.min_spp.is_some() {
            spec.min_spp = self.min_spp;
        }
        if let Some(budget) = self.time_budget {
            spec.time_budget = Some(budget);
            // The budget decides the samples: a preset's threshold and minimum stand down.
            if self.noise_threshold.is_none() {
                spec.noise_threshold = None;
            }
            spec.min_spp = self.min_spp;
            // Nor does a preset's denoising, which a budget job cannot do yet.
            spec.denoise = false;
        }
        if self.denoise || self.no_denoise {
            spec.denoise = self.denoise;
        }
        if self.video {
            spec.video = true;
        }
        if let Some(depth) = self.max_depth {
            spec.max_depth = depth;
        }
        if let Some(seed) = self.seed {
            spec.seed = seed;
        }
        if self.fixed_pattern {
            spec.fixed_pattern = true;
        }
        if self.clamp_indirect.is_some() {
            spec.clamp_indirect = self.clamp_indirect;
        }
        if let Some(s) = self.shutter {
            spec.shutter = [s.open, s.close];
        }
        if let Some(passes) = self.passes {
            spec.sample_passes = passes;
        }
        if self.preview_every.is_some() {
            spec.preview_every = self.preview_every;
        }
        if self.webhook.is_some() {
            spec.webhook = self.webhook.clone();
        }
        if let Some(priority) = self.priority {
            spec.priority = priority;
        }
        if let Some(attempts) = self.max_attempts {
            spec.max_attempts = attempts;
        }
        match &self.camera {
            None => {}
            Some(CameraChoice::Default) => spec.camera = CameraSpec::Default,
            Some(CameraChoice::Index(i)) => {
                spec.camera = CameraSpec::Index(
                    u32::try_from(*i).with_context(|| format!("--camera {i}: index too large"))?,
                )
            }
            Some(CameraChoice::Name(n)) => spec.camera = CameraSpec::Name(n.clone()),
        }
        if self.motion_steps.is_some() {
            spec.motion_steps = self.motion_steps;
        }
        if self.tile.is_some() {
            spec.tile_size = self.tile;
        }
        if let Some(a) = &self.animation {
            spec.animation = Some(animation_name(a, scene)?);
        }
        if let Some(tags) = &self.require_tags {
            spec.require_tags = tags.clone();
        }
        Ok(())
    }
}

/// `--animation` as the spec wants it: a name. A number that is not itself a name is the
/// animation's glTF index.
fn animation_name(given: &str, scene: &SceneInfo) -> anyhow::Result<String> {
    let by_name = scene
        .animations
        .iter()
        .any(|a| a.name.as_deref() == Some(given));
    match given.parse::<u32>() {
        Ok(index) if !by_name => {
            let a = scene
                .animations
                .iter()
                .find(|a| a.index == index)
                .with_context(|| {
                    format!(
                        "--animation {index}: the scene has {} animation(s)",
                        scene.animations.len()
                    )
                })?;
            a.name.clone().with_context(|| {
                format!(
                    "--animation {index}: that animation has no name, and a job names the \
                     animation it plays; leave --animation out to play all of them"
                )
            })
        }
        _ => Ok(given.to_string()),
    }
}

/// Pack a scene, upload it to the farm and create a render job.
#[derive(Args, Debug)]
pub struct SubmitArgs {
    /// The scene: a .gltf (its .bin and images are packed in) or a .glb; or the digest of
    /// a scene already on the farm (its first 8 or more hex digits, as submit prints them),
    /// which is not uploaded again.
    pub scene: PathBuf,
    #[command(flatten)]
    pub server: ServerOpts,
    #[command(flatten)]
    pub job: JobArgs,
    /// Wait for the job with a progress bar, then download its frames.
    #[arg(long)]
    pub wait: bool,
    /// With --wait: where the frames go [default: ./<job name>, or ./job-<id>].
    #[arg(long, requires = "wait")]
    pub out: Option<PathBuf>,
}

/// A folder name from a job name: letters, digits, `-`, `_` and `.` kept, the rest `_`.
pub fn folder_name(name: &str) -> String {
    let s: String = name
        .trim()
        .chars()
        .map(|c| {
            if c.is_alphanumeric() || matches!(c, '-' | '_' | '.') {
                c
            } else {
                '_'
            }
        })
        .collect();
    let s = s.trim_matches('.').to_string();
    if s.is_empty() {
        "job".into()
    } else {
        s
    }
}

/// Packs the scene at `path` into one GLB, with a message that names the file.
pub fn pack_scene(path: &Path) -> anyhow::Result<Vec<u8>> {
    if !path.exists() {
        anyhow::bail!(
            "{}: no such file; give a .gltf (with its .bin and images beside it) or a .glb",
            path.display()
        );
    }
    tracer::loader::pack_glb(path).map_err(|e| anyhow::anyhow!("packing {}: {e}", path.display()))
}

/// Checks the job against the scene here, with the server's own rules, before a large
/// upload: a bad setting (spp, fps, size, tile, frames, camera, animation) is reported at
/// once. The one bound that depends on the server's settings, tasks per job, is left to
/// it.
pub fn check_locally(glb: &[u8], job: &JobArgs, what: &str) -> anyhow::Result<()> {
    let (scene, _) =
        server::scene::inspect(glb).map_err(|e| anyhow::anyhow!("loading {what}: {e}"))?;
    let spec = job.to_spec(&scene)?;
    server::spec::plan(spec, &scene, u64::MAX)
        .map_err(|e| anyhow::anyhow!("the job's `{}`: {}", e.field, e.message))?;
    Ok(())
}

/// Uploads `glb` and creates the job `job` describes; prints what was found and the job id.
pub async fn upload_and_create(
    client: &Client,
    glb: Vec<u8>,
    job: &JobArgs,
    what: &str,
) -> anyhow::Result<proto::JobStatus> {
    let size = glb.len();
    check_locally(&glb, job, what)?;
    let scene = client
        .upload_scene(glb)
        .await
        .with_context(|| format!("uploading {what}"))?;
    for warning in &scene.warnings {
        eprintln!("warning: {what}: {warning}");
    }
    create(client, &scene, size, job).await
}

/// Creates the job `job` describes for a scene already on the farm (by its digest or the
/// digest's start).
pub async fn create_for_stored(
    client: &Client,
    digest: &str,
    job: &JobArgs,
) -> anyhow::Result<proto::JobStatus> {
    let scene = client
        .scene_info(digest)
        .await
        .with_context(|| format!("finding scene {digest} on the farm"))?;
    create(client, &scene, scene.size as usize, job).await
}

/// Creates the job for `scene`; prints what was found and the job id.
async fn create(
    client: &Client,
    scene: &proto::SceneInfo,
    size: usize,
    job: &JobArgs,
) -> anyhow::Result<proto::JobStatus> {
    let spec = job.to_spec(scene)?;
    let status = client.create_job(&spec).await.context("creating the job")?;
    let frames = status.spec.frames.map_or(String::new(), |f| {
        if f.step == 1 {
            format!("{}-{}", f.start, f.end)
        } else {
            format!("{}-{}:{}", f.start, f.end, f.step)
        }
    });
    let samples = match status.spec.time_budget {
        Some(budget) => format!(
            "at most {} spp within {budget} s, {} tasks in the first pass of {} spp",
            status.spec.spp,
            status.tasks.total(),
            status.spec.min_spp.unwrap_or(1)
        ),
        None => format!("{} spp, {} tasks", status.spec.spp, status.tasks.total()),
    };
    println!(
        "scene {} ({:.1} MB, {} triangles); job {} \"{}\": frames {frames} ({}), {}x{} at \
         {samples}",
        &scene.digest[..scene.digest.len().min(12)],
        size as f64 / 1e6,
        scene.triangles,
        status.id,
        status.name,
        status.frames_total,
        status.spec.width,
        status.spec.height,
    );
    Ok(status)
}

pub fn run(args: SubmitArgs) -> anyhow::Result<()> {
    // The scene is checked before the server is asked anything; a digest names one it has.
    let arg = args.scene.to_string_lossy().to_string();
    let stored = !args.scene.exists() && server::store::is_digest_prefix(&arg);
    let glb = if stored {
        None
    } else {
        Some(pack_scene(&args.scene)?)
    };
    let client = args.server.client()?;
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .context("starting the async runtime")?;
    runtime.block_on(async {
        let what = args.scene.display().to_string();
        let job = match glb {
            Some(glb) => upload_and_create(&client, glb, &args.job, &what).await?,
            None => create_for_stored(&client, &arg, &args.job).await?,
        };
        let id = job.id;
        println!("job {id} submitted; dashboard: {}", client.dashboard_url());
        if !args.wait {
            println!(
                "follow it with `tessera status {id}{}`",
                server_flag(&args.server)
            );
            return Ok(());
        }
        let out = args.out.clone().unwrap_or_else(|| {
            PathBuf::from(match &args.job.name {
                Some(name) => folder_name(name),
                None => format!("job-{id}"),
            })
        });
        match progress::follow(&client, job, &out, |_| Ok(None)).await? {
            Followed::Interrupted(status) => {
                eprintln!(
                    "stopped waiting; job {id} keeps running on the farm ({}, frames {}/{}). \
                     Check on it with `tessera status {id}{}`",
                    progress::state_name(status.state),
                    status.frames_done,
                    status.frames_total,
                    server_flag(&args.server)
                );
                // The conventional status of a command ended by Ctrl-C.
                std::process::exit(130);
            }
            Followed::Ended { status, downloaded } => {
                println!("{}", downloaded.summary());
                progress::require_done(&status, &downloaded, client.base())
            }
        }
    })
}

/// ` --server URL` when the server is not the default, for commands we suggest.
pub fn server_flag(opts: &ServerOpts) -> String {
    if opts.server.trim_end_matches('/') == crate::client::DEFAULT_SERVER {
        String::new()
    } else {
        format!(" --server {}", opts.server)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;
    use proto::AnimationInfo;

    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        job: JobArgs,
    }

    fn parse(args: &[&str]) -> JobArgs {
        Cli::try_parse_from([&["submit"], args].concat())
            .map_err(|e| e.to_string())
            .unwrap()
            .job
    }

    fn scene() -> SceneInfo {
        SceneInfo {
            digest: "ab".repeat(32),
            size: 1,
            animations: vec![
                AnimationInfo {
                    index: 0,
                    name: Some("Walk".into()),
                    start_seconds: 0.0,
                    end_seconds: 1.0,
                },
                AnimationInfo {
                    index: 1,
                    name: None,
                    start_seconds: 0.0,
                    end_seconds: 1.0,
                },
            ],
            duration_seconds: 1.0,
            triangles: 12,
            meshes: 1,
            instances: 1,
            materials: 1,
            ..Default::default()
        }
    }

    #[test]
    fn negative_numbers_are_values_for_the_server_to_check() {
        let spec = parse(&["--fps", "-5", "--time-budget", "-1", "--priority", "-3"])
            .to_spec(&scene())
            .unwrap();
        assert_eq!(
            (spec.fps, spec.time_budget, spec.priority),
            (-5.0, Some(-1.0), -3)
        );
    }

    #[test]
    fn a_clone_changes_only_the_settings_given() {
        let mut spec = parse(&[
            "--spp", "16", "--frames", "3-9", "--tile", "32", "--seed", "4",
        ])
        .to_spec(&scene())
        .unwrap();
        spec.name = Some("shot".into());
        spec.camera = CameraSpec::Name("Main".into());
        let before = spec.clone();
        parse(&[]).overlay(&mut spec, &scene()).unwrap();
        assert_eq!(spec, before, "no flag changes nothing");
        parse(&["--spp", "64", "--name", "shot v2"])
            .overlay(&mut spec, &scene())
            .unwrap();
        let mut want = before;
        want.spp = 64;
        want.name = Some("shot v2".into());
        assert_eq!(spec, want);
    }

    #[test]
    fn no_flags_keep_every_default() {
        let spec = parse(&[]).to_spec(&scene()).unwrap();
        assert_eq!(spec, JobSpec::new("ab".repeat(32)));
        assert_eq!(spec.frames, None, "the server picks the animation range");
    }

    #[test]
    fn every_flag_lands_in_its_field() {
        let spec = parse(&[
            "--frames",
            "1-48:2",
            "--fps",
            "30",
            "--spp",
            "16",
            "--size",
            "320x240",
            "--tile",
            "64",
            "--shutter",
            "-0.25,0.25",
            "--passes",
            "4",
            "--preview-every",
            "8",
            "--webhook",
            "https://hooks.example.com/t",
            "--priority",
            "-3",
            "--max-attempts",
            "7",
            "--camera",
            "Main",
            "--max-depth",
            "5",
            "--seed",
            "9",
            "--motion-steps",
            "3",
            "--animation",
            "Walk",
            "--name",
            "shot 1",
        ])
        .to_spec(&scene())
        .unwrap();
        let mut want = JobSpec::new("ab".repeat(32));
        want.frames = Some(proto::FrameRange {
            start: 1,
            end: 48,
            step: 2,
        });
        want.fps = 30.0;
        want.spp = 16;
        (want.width, want.height) = (320, 240);
        want.tile_size = Some(64);
        want.shutter = [-0.25, 0.25];
        want.sample_passes = 4;
        want.preview_every = Some(8);
        want.webhook = Some("https://hooks.example.com/t".into());
        want.priority = -3;
        want.max_attempts = 7;
        want.camera = CameraSpec::Name("Main".into());
        want.max_depth = 5;
        want.seed = 9;
        want.motion_steps = Some(3);
        want.animation = Some("Walk".into());
        want.name = Some("shot 1".into());
        assert_eq!(spec, want);
    }

    /// With a time budget, a preset gives the spp cap and the bounces; its noise threshold
    /// and minimum stand down (the budget decides the samples), unless given explicitly.
    #[test]
    fn a_time_budget_takes_a_presets_cap_but_not_its_threshold() {
        let spec = parse(&["--quality", "final", "--time-budget", "256"])
            .to_spec(&scene())
            .unwrap();
        let preset = Quality::Final.settings();
        assert_eq!(spec.time_budget, Some(256.0));
        assert_eq!((spec.spp, spec.max_depth), (preset.spp, preset.max_depth));
        assert_eq!((spec.noise_threshold, spec.min_spp), (None, None));
        assert!(!spec.denoise);
        let spec = parse(&["--time-budget", "60", "--min-spp", "8"])
            .to_spec(&scene())
            .unwrap();
        assert_eq!((spec.time_budget, spec.min_spp), (Some(60.0), Some(8)));
        // Both controls at once go to the server, which refuses them by field name.
        let spec = parse(&["--time-budget", "60", "--noise-threshold", "0.1"])
            .to_spec(&scene())
            .unwrap();
        assert_eq!(spec.noise_threshold, Some(0.1));
    }

    #[test]
    fn the_preview_and_final_presets_denoise_unless_told_not_to() {
        let denoises = |args: &[&str]| parse(args).to_spec(&scene()).unwrap().denoise;
        assert!(!denoises(&[]));
        assert!(!denoises(&["--quality", "draft"]));
        assert!(denoises(&["--quality", "preview"]));
        assert!(denoises(&["--quality", "final"]));
        assert!(!denoises(&["--quality", "final", "--no-denoise"]));
        assert!(denoises(&["--quality", "draft", "--denoise"]));
        assert!(denoises(&["--denoise"]));
        let both = Cli::try_parse_from(["submit", "--denoise", "--no-denoise"]);
        assert!(both.is_err());
    }

    #[test]
    fn camera_and_animation_indices() {
        let spec = parse(&["--camera", "2", "--animation", "0"])
            .to_spec(&scene())
            .unwrap();
        assert_eq!(spec.camera, CameraSpec::Index(2));
        assert_eq!(spec.animation.as_deref(), Some("Walk"));
        let e = parse(&["--animation", "1"]).to_spec(&scene()).unwrap_err();
        assert!(e.to_string().contains("no name"), "{e}");
        let e = parse(&["--animation", "5"]).to_spec(&scene()).unwrap_err();
        assert!(e.to_string().contains("2 animation(s)"), "{e}");
        // An unknown name goes to the server, which lists the names it has.
        let spec = parse(&["--animation", "Run"]).to_spec(&scene()).unwrap();
        assert_eq!(spec.animation.as_deref(), Some("Run"));
    }

    #[test]
    fn bad_values_are_refused_by_the_shared_parsers() {
        let cli = |args: &[&str]| Cli::try_parse_from([&["submit"], args].concat()).is_err();
        assert!(cli(&["--size", "0x10"]));
        assert!(cli(&["--frames", "5-1"]));
        assert!(cli(&["--shutter", "0.5,0"]));
    }

    #[test]
    fn job_names_become_safe_folder_names() {
        assert_eq!(folder_name("shot 1/take:2"), "shot_1_take_2");
        assert_eq!(folder_name(".."), "job");
        assert_eq!(folder_name("  "), "job");
        assert_eq!(folder_name("walk-cycle_v2.1"), "walk-cycle_v2.1");
    }
}

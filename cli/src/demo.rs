//! `tessera demo`: a whole farm on this machine, from nothing. A server runs in this
//! process on a free loopback port, N `tessera worker` child processes lease from it, the
//! animated demo scene is uploaded and rendered with motion blur, the frames are downloaded
//! and everything is shut down again, also on Ctrl-C, on an error and on a panic.
//!
//! Workers are real processes, not threads, so the demo exercises exactly what a farm of
//! machines does: HTTP leases, scene downloads, tile uploads.
//! The processes and the server live in `demo/farm.rs`.

use std::fs::File;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::Context;
use clap::Args;
use proto::JobStatus;

use crate::args::{parse_frames, parse_shutter, parse_size, FrameRange};
use crate::client::Client;
use crate::progress::{self, has_ended, Followed};
use crate::submit::{upload_and_create, JobArgs};

mod farm;

use farm::tail;
pub(crate) use farm::{terminate, tessera_command, LocalServer, Workers};

/// How long workers get to give their leases back after SIGTERM before they are killed.
const WORKER_GRACE: Duration = Duration::from_secs(5);
/// The demo's shutter: open a quarter frame either side of each frame, so the bouncing,
/// turning and sliding objects blur.
const DEMO_SHUTTER: &str = "-0.25,0.25";
/// The clamp on indirect light of a demo that is not denoised: at the demo's 16 spp it
/// halves what its caustic fireflies cost the previews (display MSE 2.5e-3 against
/// 4.3e-3 unclamped) for 5.7% of the light, the lowest error of the limits `tessera bench
/// clamp` measures. Denoised frames are better without it (5.2e-4 unclamped, 1.4e-3).
const DEMO_CLAMP: f32 = 1.0;
/// Sample passes per tile: the dashboard's previews refine once before each tile is final.
const DEMO_PASSES: u32 = 2;
/// Fewest tiles per frame the demo aims for, so that workers share frames.
const DEMO_MIN_TILES: u32 = 4;

/// Run a whole render farm on this machine: a server, worker processes, and a short
/// motion-blurred animation of the demo scene.
#[derive(Args, Debug)]
pub struct DemoArgs {
    /// Worker processes [default: one per core].
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=256))]
    pub workers: Option<u32>,
    /// Frames to render, A-B or A-B:STEP, at 24 fps (the loop is frames 0-48).
    #[arg(long, default_value = "1-24", value_parser = parse_frames)]
    pub frames: FrameRange,
    /// Image size, WIDTHxHEIGHT.
    #[arg(long, default_value = "256x192", value_parser = parse_size)]
    pub size: (u32, u32),
    /// Samples per pixel.
    #[arg(long, default_value_t = 16, value_parser = clap::value_parser!(u32).range(1..=65_536))]
    pub spp: u32,
    /// Folder for the demo's server data (data/), worker caches (cache/), logs (logs/) and
    /// the downloaded frames (frames/).
    #[arg(long, default_value = "./tessera-demo")]
    pub dir: PathBuf,
    /// Denoise the frames with Open Image Denoise [default: when it is installed;
    /// `tessera install oidn` installs it].
    #[arg(long, conflicts_with = "no_denoise")]
    pub denoise: bool,
    /// Do not denoise, even where Open Image Denoise is installed.
    #[arg(long)]
    pub no_denoise: bool,
    /// End with the frames as an H.264 MP4, `demo.mp4` in --dir [default: when FFmpeg is
    /// installed; `tessera install ffmpeg` installs it].
    #[arg(long, conflicts_with = "no_video")]
    pub video: bool,
    /// Make no video, even where FFmpeg is installed.
    #[arg(long)]
    pub no_video: bool,
    /// Clamp light that reaches the camera after two or more surfaces at this [default:
    /// 1 where the frames are not denoised, against the caustics' fireflies; off where
    /// they are].
    #[arg(long, value_parser = crate::args::parse_clamp, conflicts_with = "no_clamp")]
    pub clamp_indirect: Option<f32>,
    /// Clamp nothing, even without a denoiser.
    #[arg(long)]
    pub no_clamp: bool,
}

impl DemoArgs {
    /// Whether the demo denoises and makes a video, with a note for the user for each it
    /// does not do on its own (its program is missing); asked for without it is an error.
    fn steps(&self) -> anyhow::Result<(bool, bool, Vec<String>)> {
        let mut notes = Vec::new();
        let denoise = optional_step(
            (self.denoise, self.no_denoise),
            post::Oidn::load(None)
                .map(drop)
                .map_err(anyhow::Error::from),
            "frames are not denoised: Open Image Denoise is not installed (`tessera install \
             oidn` installs it, no root needed)",
            &mut notes,
        )?;
        let video = optional_step(
            (self.video, self.no_video),
            post::Ffmpeg::find(None)
                .map(drop)
                .map_err(anyhow::Error::from),
            "no video: FFmpeg is not installed (`tessera install ffmpeg` installs it, no root \
             needed)",
            &mut notes,
        )?;
        Ok((denoise, video, notes))
    }

    /// The clamp on indirect light for a demo that denoises or not, with a note saying so
    /// where the demo chose it.
    fn clamp(&self, denoise: bool, notes: &mut Vec<String>) -> Option<f32> {
        if self.no_clamp {
            return None;
        }
        if self.clamp_indirect.is_some() || denoise {
            return self.clamp_indirect;
        }
        notes.push(format!(
            "frames are not denoised, so indirect light is clamped at {DEMO_CLAMP} against \
             the caustics' fireflies (--clamp-indirect; --no-clamp turns it off; `tessera \
             bench clamp` measures it)"
        ));
        Some(DEMO_CLAMP)
    }
}

/// Whether an optional step runs: not when turned off (`(on, off)`), else when what it
/// needs is `there`; asked for (`on`) without it is the error, not asked for a `note`.
fn optional_step(
    (on, off): (bool, bool),
    there: anyhow::Result<()>,
    note: &str,
    notes: &mut Vec<String>,
) -> anyhow::Result<bool> {
    match (off, there) {
        (true, _) => Ok(false),
        (false, Ok(())) => Ok(true),
        (false, Err(e)) if on => Err(e),
        (false, Err(_)) => {
            notes.push(note.to_string());
            Ok(false)
        }
    }
}

/// The largest power-of-two tile side (at most 256) that still cuts a `w`×`h` frame into
/// at least [`DEMO_MIN_TILES`] tiles, so that several workers share a frame.
pub fn demo_tile_size(w: u32, h: u32) -> u32 {
    let tiles = |t: u32| w.div_ceil(t) * h.div_ceil(t);
    let mut t = 256;
    while t > 8 && tiles(t) < DEMO_MIN_TILES {
        t /= 2;
    }
    t
}

/// The demo job's settings, through the same mapping as `tessera submit`.
pub fn demo_job(args: &DemoArgs) -> JobArgs {
    let (w, h) = args.size;
    JobArgs {
        frames: Some(args.frames),
        fps: Some(24.0),
        spp: Some(args.spp),
        size: Some(args.size),
        tile: Some(demo_tile_size(w, h)),
        shutter: Some(parse_shutter(DEMO_SHUTTER).expect("the demo shutter is valid")),
        passes: Some(DEMO_PASSES.min(args.spp)),
        name: Some("tessera demo".into()),
        denoise: args.denoise,
        video: args.video,
        clamp_indirect: args.clamp_indirect,
        ..JobArgs::default()
    }
}

/// Logs of the in-process server go to a file, so the progress bar stays clean.
fn log_to_file(path: &Path) -> anyhow::Result<()> {
    let file = File::create(path).with_context(|| format!("creating {}", path.display()))?;
    let _ = tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                .unwrap_or_else(|_| "info,tower_http=warn".into()),
        )
        .with_ansi(false)
        .with_writer(std::sync::Mutex::new(file))
        .try_init();
    Ok(())
}

/// Removes the frame files a previous demo left, so the folder holds only this run's.
fn clear_old_frames(dir: &Path) -> anyhow::Result<()> {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return Ok(());
    };
    for entry in entries.flatten() {
        let name = entry.file_name();
        let name = name.to_string_lossy();
        if name.starts_with("frame_") && (name.ends_with(".exr") || name.ends_with(".png")) {
            std::fs::remove_file(entry.path())
                .with_context(|| format!("removing {}", entry.path().display()))?;
        }
    }
    Ok(())
}

/// What the demo's session came to.
enum Outcome {
    Finished {
        status: Box<JobStatus>,
        downloaded: progress::Downloaded,
        elapsed: Duration,
    },
    Interrupted,
}

pub fn run(args: DemoArgs) -> anyhow::Result<()> {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get() as u32);
    let n = args.workers.unwrap_or(cores);
    let threads = (cores / n).max(1);
    let dir = &args.dir;
    let [data, cache, logs, frames] = ["data", "cache", "logs", "frames"].map(|d| dir.join(d));
    for d in [&data, &cache, &logs, &frames] {
        std::fs::create_dir_all(d).with_context(|| format!("creating {}", d.display()))?;
    }
    clear_old_frames(&frames)?;
    let old_video = dir.join("demo.mp4");
    if old_video.exists() {
        std::fs::remove_file(&old_video)
            .with_context(|| format!("removing {}", old_video.display()))?;
    }
    let (denoise, video, mut notes) = args.steps()?;
    let clamp_indirect = args.clamp(denoise, &mut notes);
    for note in notes {
        println!("note: {note}");
    }
    let args = DemoArgs {
        denoise,
        no_denoise: !denoise,
        video,
        no_video: !video,
        clamp_indirect,
        no_clamp: clamp_indirect.is_none(),
        ..args
    };
    log_to_file(&logs.join("server.log"))?;
    let glb = tracer::export::scene_to_glb(&tracer::demo::animated_demo_scene())
        .map_err(|e| anyhow::anyhow!("exporting the demo scene to GLB: {e}"))?;

    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .context("starting the async runtime")?;
    let server = runtime.block_on(LocalServer::start(&data))?;
    println!(
        "Tessera demo: server on {} (data in {}), {n} worker(s) × {threads} thread(s)",
        server.url,
        data.display()
    );
    // Spawned from the main thread: see `configure_child`.
    let mut workers = Workers::spawn(&server.url, n, threads, &cache, &logs)?;
    let client = Client::new(&server.url, None)?;

    let outcome = runtime.block_on(session(
        &args,
        &client,
        glb,
        &frames,
        &logs,
        &mut workers,
        &server,
    ));

    // Shut down in order: workers first (they give their leases back), then the server.
    let killed = workers.stop(WORKER_GRACE);
    if !killed.is_empty() {
        eprintln!(
            "killed worker(s) {} after {}s without exiting",
            killed.join(", "),
            WORKER_GRACE.as_secs()
        );
    }
    let stopped = runtime.block_on(server.shutdown());
    runtime.shutdown_timeout(Duration::from_secs(1));
    if let Err(e) = stopped {
        eprintln!("warning: {e:#}; see {}", logs.join("server.log").display());
    }

    match outcome? {
        Outcome::Interrupted => {
            eprintln!(
                "demo interrupted; workers and server stopped. Its server data stays in {}: \
                 `tessera server --data {}` serves it again",
                data.display(),
                data.display()
            );
            std::process::exit(130);
        }
        Outcome::Finished {
            status,
            downloaded,
            elapsed,
        } => {
            let (w, h) = args.size;
            let samples = downloaded.frames.len() as f64 * w as f64 * h as f64 * args.spp as f64;
            println!(
                "{} frames of {w}x{h} at {} spp in {:.1} s on {n} worker(s): {} (farm: {})",
                downloaded.frames.len(),
                args.spp,
                elapsed.as_secs_f64(),
                progress::rate(samples / elapsed.as_secs_f64().max(1e-3)),
                progress::rate(status.samples_per_second),
            );
            progress::require_done(&status, &downloaded, &client.dashboard_url())
        }
    }
}

/// Upload, submit, follow and download, watching the workers; Ctrl-C at any point ends it.
async fn session(
    args: &DemoArgs,
    client: &Client,
    glb: Vec<u8>,
    frames_dir: &Path,
    logs: &Path,
    workers: &mut Workers,
    server: &LocalServer,
) -> anyhow::Result<Outcome> {
    let setup = async {
        clear_earlier_jobs(client).await?;
        upload_and_create(client, glb, &demo_job(args), "the demo scene").await
    };
    let job = tokio::select! {
        job = setup => job?,
        _ = crate::signal::interrupted() => return Ok(Outcome::Interrupted),
    };
    println!(
        "dashboard: {} (while the demo runs; worker logs in {})",
        client.dashboard_url(),
        logs.display()
    );
    let started = Instant::now();
    let total = workers.procs.len();
    let check = |status: &JobStatus| -> anyhow::Result<Option<String>> {
        if server.task.is_finished() {
            anyhow::bail!(
                "the demo server stopped unexpectedly; see {}",
                logs.join("server.log").display()
            );
        }
        let notes: Vec<String> = workers
            .newly_exited()
            .into_iter()
            .map(|p| {
                format!(
                    "worker {} exited early ({}); its log: {}",
                    p.name,
                    p.exited.map_or("?".into(), |s| s.to_string()),
                    p.log.display()
                )
            })
            .collect();
        if workers.running() == 0 && !has_ended(status) {
            let first = &workers.procs[0];
            anyhow::bail!(
                "all {total} worker(s) exited before the job finished ({}/{} frames done). \
                 The end of {}:\n{}",
                status.frames_done,
                status.frames_total,
                first.log.display(),
                tail(&first.log, 8)
            );
        }
        Ok((!notes.is_empty()).then(|| notes.join("\n")))
    };
    match progress::follow(client, job, frames_dir, check).await? {
        Followed::Interrupted(_) => Ok(Outcome::Interrupted),
        Followed::Ended {
            status,
            mut downloaded,
        } => {
            let elapsed = started.elapsed();
            // The demo's video sits beside its folders: tessera-demo/demo.mp4.
            if let Some(video) = downloaded.video.take() {
                let demo = args.dir.join("demo.mp4");
                std::fs::rename(&video, &demo)
                    .with_context(|| format!("moving the video to {}", demo.display()))?;
                downloaded.video = Some(demo);
            }
            println!("{}", downloaded.summary());
            Ok(Outcome::Finished {
                status: Box::new(status),
                downloaded,
                elapsed,
            })
        }
    }
}

/// Deletes the jobs earlier demos left in the same data folder (an interrupted one's
/// unfinished job too), so that the workers render this run's job and the folder does not
/// fill up run after run. Their frames were downloaded to frames/, which this run replaces.
async fn clear_earlier_jobs(client: &Client) -> anyhow::Result<()> {
    for job in client.jobs().await?.jobs {
        client.delete_job(job.id).await?;
        if !has_ended(&job) {
            eprintln!("deleted job {} left unfinished by an earlier demo", job.id);
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        demo: DemoArgs,
    }

    #[test]
    fn tiles_split_every_frame_several_ways() {
        assert_eq!(demo_tile_size(256, 192), 128);
        assert_eq!(demo_tile_size(1920, 1080), 256);
        assert_eq!(demo_tile_size(32, 32), 16);
        assert_eq!(demo_tile_size(8, 8), 8);
    }

    #[test]
    fn the_demo_job_blurs_and_refines_at_the_given_size() {
        let args = Cli::try_parse_from(["demo"]).unwrap().demo;
        let job = demo_job(&args);
        assert_eq!(
            job.frames,
            Some(FrameRange {
                start: 1,
                end: 24,
                step: 1
            })
        );
        assert_eq!(
            (job.size, job.spp, job.fps),
            (Some((256, 192)), Some(16), Some(24.0))
        );
        assert_eq!(job.tile, Some(128));
        assert_eq!(job.passes, Some(2));
        let s = job.shutter.unwrap();
        assert_eq!((s.open, s.close), (-0.25, 0.25));
        assert!(Cli::try_parse_from(["demo", "--workers", "0"]).is_err());
        assert!(Cli::try_parse_from(["demo", "--spp", "0"]).is_err());
        let one = Cli::try_parse_from(["demo", "--spp", "1"]).unwrap().demo;
        assert_eq!(demo_job(&one).passes, Some(1));
    }

    #[test]
    fn the_demo_clamps_indirect_light_only_where_it_does_not_denoise() {
        let demo = |args: &[&str]| {
            let mut all = vec!["demo"];
            all.extend(args);
            Cli::try_parse_from(all).unwrap().demo
        };
        let mut notes = Vec::new();
        assert_eq!(demo(&[]).clamp(false, &mut notes), Some(DEMO_CLAMP));
        assert!(notes[0].contains("--no-clamp"), "{notes:?}");
        notes.clear();
        assert_eq!(demo(&[]).clamp(true, &mut notes), None);
        assert_eq!(demo(&["--no-clamp"]).clamp(false, &mut notes), None);
        let explicit = demo(&["--clamp-indirect", "3"]);
        assert_eq!(explicit.clamp(true, &mut notes), Some(3.0));
        assert!(notes.is_empty(), "{notes:?}");
        assert_eq!(demo_job(&explicit).clamp_indirect, Some(3.0));
        assert!(Cli::try_parse_from(["demo", "--clamp-indirect", "0"]).is_err());
    }
}

//! `tessera bench farm`: a load test of the farm server. A real `tessera server` child
//! process on a loopback port gets one job of N empty tasks (8×8 tiles at 1 sample) and M
//! simulated workers: tokio tasks that long-poll for leases like `tessera worker` and
//! answer each lease at once with a black tile of the lease's rectangle, encoded as the
//! real worker encodes its tiles (so the server checks, stores and assembles it as usual).
//! Nothing is rendered: what is measured is the server's own cost per task.
//! `--tile-size` and `--noise` make the tiles the size and content of rendered ones (random
//! radiance does not compress, as a noisy render's does not), to measure the server's
//! upload and assembly throughput in MB/s instead.
//!
//! It reports tasks per second, lease and upload latencies, upload and assembly throughput
//! (the server's own assembly times, from its `/metrics`), the server's memory (its
//! process's peak and final resident set, from `/proc`), and checks the one thing a farm
//! must never do: lose a task or accept one twice. The figures are printed as a short
//! table and, with `--json`, written as a [`Report`].

use std::collections::hash_map::Entry;
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::process::Child;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{bail, Context};
use clap::Args;
use proto::{JobSpec, JobState, JobStatus, WorkerRegistration};
use serde::Serialize;
use tokio::sync::watch;
use tokio::task::JoinSet;
use tracer::film::{SampleValue, TileBuffer, TileRect};
use tracer::output::ExrCompression;
use worker::api::{Api, ApiError, LeaseAnswer, UploadAnswer};

use crate::bench::rays::Rng;
use crate::client::Client;
use crate::demo::{terminate, tessera_command};

/// The smallest tile the server accepts, the default: the least pixel work per task.
const TILE: u32 = server::limits::MIN_TILE_SIZE;
/// Most tiles the bench puts in one frame (frames are assembled when their last tile is
/// in, so the tiles per frame set how often the server assembles).
const MAX_TILES_PER_FRAME: u64 = 100;
/// How long a simulated worker's lease request waits for work, as a real worker's does
/// (shorter than the server's cap, so idle workers ask again often at the end of a run).
const LEASE_WAIT: Duration = Duration::from_secs(2);
/// Tries of one upload through network errors.
const UPLOAD_TRIES: u32 = 3;
/// The pause after a failed call before the next.
const ERROR_PAUSE: Duration = Duration::from_millis(100);
/// How often the bench looks at its own count of accepted tiles.
const TICK: Duration = Duration::from_millis(250);
/// How often the job's status is read before every tile is in: reading it scans the
/// job's tasks, which would load the server the bench measures.
const STATUS_EVERY: Duration = Duration::from_secs(2);
/// How often a progress line is printed.
const PROGRESS_EVERY: Duration = Duration::from_secs(5);
/// How long the server gets to print its address after starting.
const SERVER_START: Duration = Duration::from_secs(30);
/// How long the server gets to exit after SIGTERM before it is killed.
const SERVER_GRACE: Duration = Duration::from_secs(5);

/// Load-test the farm server: simulated workers long-poll for empty tasks and upload
/// black tiles at once; report tasks per second, lease latency and server memory.
#[derive(Args, Debug)]
pub struct FarmBenchArgs {
    /// Simulated workers, each with its own HTTP client, long-polling for leases.
    #[arg(long, default_value_t = 200, value_parser = clap::value_parser!(u32).range(1..=2_000))]
    pub workers: u32,
    /// Empty tasks in the job (the count is exact unless the job's limits forbid it; the
    /// report gives the actual count).
    #[arg(long, default_value_t = 20_000, value_parser = clap::value_parser!(u64).range(1..=1_000_000))]
    pub tasks: u64,
    /// Give up (and fail) after this many seconds of load.
    #[arg(long, default_value_t = 600, value_parser = clap::value_parser!(u64).range(1..=86_400))]
    pub timeout_seconds: u64,
    /// Also write the figures as JSON to this file.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Folder for the server's data: it must be new or empty, and is kept [default: a
    /// temporary folder, removed after a passing run].
    #[arg(long)]
    pub data: Option<PathBuf>,
    /// Keep one event stream (`GET /api/v1/events`) open during the load, as an open
    /// dashboard does: the server then publishes every job, frame and worker change.
    #[arg(long)]
    pub events: bool,
    /// Tile side in pixels [default: the smallest the server takes, 8].
    #[arg(long, default_value_t = TILE,
          value_parser = clap::value_parser!(u32).range(TILE as i64..=server::limits::MAX_TILE_SIZE as i64))]
    pub tile_size: u32,
    /// Fill the tiles with random radiance, albedo and normals, as a rendered tile's noise
    /// (black tiles compress to almost nothing): for upload and assembly MB/s.
    #[arg(long)]
    pub noise: bool,
}

/// How the job is cut: `frames` frames of `tiles_x` × `tiles_y` tiles of `tile` pixels a
/// side, one sample pass each.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub struct Shape {
    pub frames: u64,
    pub tiles_x: u32,
    pub tiles_y: u32,
    pub tile: u32,
}

impl Shape {
    pub fn tasks(&self) -> u64 {
        self.frames * self.tiles_x as u64 * self.tiles_y as u64
    }

    /// The frame size in pixels.
    pub fn size(&self) -> (u32, u32) {
        (self.tiles_x * self.tile, self.tiles_y * self.tile)
    }
}

/// The job shape for `tasks` tasks: the most tiles per frame (up to
/// [`MAX_TILES_PER_FRAME`]) that divide `tasks` exactly within the server's frame limit,
/// laid out as square as their divisors allow; when no exact split exists (a large prime),
/// the nearest count the limits allow. Tiles are `tile` pixels a side.
pub fn job_shape(tasks: u64, tile: u32) -> Shape {
    let max_frames = server::limits::MAX_FRAMES;
    let tasks = tasks.max(1);
    let exact = (1..=MAX_TILES_PER_FRAME.min(tasks))
        .rev()
        .find(|&d| tasks.is_multiple_of(d) && tasks / d <= max_frames);
    let (tiles, frames) = match exact {
        Some(d) => (d, tasks / d),
        None => (
            MAX_TILES_PER_FRAME,
            ((tasks as f64 / MAX_TILES_PER_FRAME as f64).round() as u64).clamp(1, max_frames),
        ),
    };
    let rows = (1..=tiles)
        .filter(|&r| tiles.is_multiple_of(r) && r * r <= tiles)
        .max();
    let rows = rows.unwrap_or(1);
    Shape {
        frames,
        tiles_x: (tiles / rows) as u32,
        tiles_y: rows as u32,
        tile,
    }
}

/// Latencies of one kind of call, in milliseconds.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct Latency {
    pub count: usize,
    pub p50: f64,
    pub p99: f64,
    pub max: f64,
    pub mean: f64,
}

impl Latency {
    fn of(mut ms: Vec<f64>) -> Latency {
        if ms.is_empty() {
            return Latency::default();
        }
        ms.sort_by(f64::total_cmp);
        // Nearest rank: the smallest value with at least p% of the values at or below it.
        let rank =
            |p: f64| ms[((p / 100.0 * ms.len() as f64).ceil() as usize).clamp(1, ms.len()) - 1];
        Latency {
            count: ms.len(),
            p50: rank(50.0),
            p99: rank(99.0),
            max: ms[ms.len() - 1],
            mean: ms.iter().sum::<f64>() / ms.len() as f64,
        }
    }
}

/// The server process's memory, MiB (absent where `/proc` is not there to read).
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct Memory {
    /// Resident set once the scene was uploaded, before the job was created.
    pub idle_rss_mib: Option<f64>,
    /// Peak resident set over the whole run (`VmHWM`).
    pub peak_rss_mib: Option<f64>,
    /// Resident set at the end of the load (`VmRSS`).
    pub final_rss_mib: Option<f64>,
}

/// Everything the bench measured; `--json` writes it as is.
#[derive(Clone, Debug, Serialize)]
pub struct Report {
    /// Tasks asked for with `--tasks`.
    pub tasks_requested: u64,
    /// Tasks in the job the server created.
    pub tasks: u64,
    pub workers: u32,
    pub frames: u64,
    pub tiles_per_frame: u64,
    pub frame_size: (u32, u32),
    /// Seconds from the job's creation to its end (every frame assembled), by the server's
    /// clock; to the timeout when it ran out.
    pub wall_seconds: f64,
    /// Seconds from the job's creation to the last accepted tile; the rest of
    /// `wall_seconds` was frame assembly catching up.
    pub last_tile_seconds: f64,
    /// Seconds the server took to create the job (a transaction inserting every task).
    pub create_job_seconds: f64,
    /// Accepted tiles per wall second.
    pub tasks_per_second: f64,
    /// Lease requests answered with a task: from the request to the 200 answer.
    pub lease_latency_ms: Latency,
    /// Tile uploads answered 200.
    pub upload_latency_ms: Latency,
    /// Lease requests answered 204 (no work within the wait).
    pub no_work_answers: u64,
    /// Uploads answered `accepted: true`.
    pub accepted: u64,
    /// Tasks accepted more than once plus acks with `accepted: false`: zero in a sound run.
    pub duplicates: u64,
    /// Tasks whose tile the server accepted twice.
    pub accepted_twice: u64,
    /// Uploads the server answered `accepted: false` (a repeat, ignored).
    pub ignored_repeats: u64,
    /// Tasks leased more than once (a lease that expired and was granted again).
    pub leased_again: u64,
    /// Tasks of the job not done at the end, per the server's job status.
    pub lost: u64,
    /// Uploads the server refused or found without a lease (409, 413, 422).
    pub refused_uploads: u64,
    /// Failed calls (network errors, 5xx), each retried.
    pub errors: u64,
    pub first_error: Option<String>,
    /// Tile bytes uploaded and accepted.
    pub upload_bytes: u64,
    /// Accepted tile bytes per wall second, MB/s (10^6 bytes).
    pub upload_mb_per_second: f64,
    /// The server's frame assembly, from its `/metrics` after the load.
    pub assembly: Option<Assembly>,
    /// Whether an event stream was open during the load (`--events`).
    pub events_listener: bool,
    /// Server-sent events received on it.
    pub events_received: u64,
    /// The job's state at the end.
    pub job_state: String,
    pub frames_done: u64,
    pub server_memory: Memory,
    /// CPU time (user + system) the server process used during the load, seconds.
    pub server_cpu_seconds: Option<f64>,
    /// CPU time the bench itself (the simulated workers) used during the load: on a small
    /// machine it competes with the server.
    pub bench_cpu_seconds: Option<f64>,
    pub timed_out: bool,
    /// Whether nothing was lost, nothing done twice, nothing refused and the job ended in time.
    pub passed: bool,
}

/// The server's frame assembly over the run: read every tile of a frame, merge, write the
/// frame's EXR and PNG, mark it in the database.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct Assembly {
    pub frames: u64,
    /// Seconds spent assembling, all frames together.
    pub seconds: f64,
    /// Tile bytes read back.
    pub tile_bytes: u64,
    /// Tile MB (10^6 bytes) assembled per second of assembly.
    pub mb_per_second: f64,
    /// Mean milliseconds per frame.
    pub mean_ms: f64,
}

impl Assembly {
    /// The figures from the server's Prometheus text; `None` if it has none (no frame
    /// assembled yet, or a server without them).
    fn from_metrics(text: &str) -> Option<Assembly> {
        let value = |name: &str| {
            text.lines()
                .find_map(|l| l.strip_prefix(name)?.strip_prefix(' ')?.parse::<f64>().ok())
        };
        let frames = value("tessera_frames_assembled_total")? as u64;
        let seconds = value("tessera_frame_assembly_seconds_sum")?;
        let tile_bytes = value("tessera_frame_assembly_tile_bytes_total")? as u64;
        Some(Assembly {
            frames,
            seconds,
            tile_bytes,
            mb_per_second: tile_bytes as f64 / 1e6 / seconds.max(1e-9),
            mean_ms: seconds * 1e3 / frames.max(1) as f64,
        })
    }
}

/// What one simulated worker saw.
#[derive(Default)]
struct Tally {
    lease_ms: Vec<f64>,
    upload_ms: Vec<f64>,
    leased: Vec<u64>,
    /// (task id, accepted) per upload answered 200.
    acks: Vec<(u64, bool)>,
    no_work: u64,
    upload_bytes: u64,
    refused: u64,
    errors: u64,
    first_error: Option<String>,
    /// When its last accepted upload was answered.
    last_accept: Option<Instant>,
}

impl Tally {
    fn error(&mut self, what: impl std::fmt::Display) {
        self.errors += 1;
        if self.first_error.is_none() {
            self.first_error = Some(what.to_string());
        }
    }
}

fn millis(d: Duration) -> f64 {
    d.as_secs_f64() * 1e3
}

/// One simulated worker: lease, upload a black tile at once, until `stop`.
async fn simulated_worker(
    api: Api,
    id: u64,
    noise: bool,
    mut stop: watch::Receiver<bool>,
    accepted: Arc<AtomicU64>,
) -> Tally {
    let mut tally = Tally::default();
    // A tile's EXR depends only on its place (its pixels are seeded by it), so each place
    // is encoded once: the bench's own encoding would otherwise take the server's cores.
    let mut encoded: HashMap<TileRect, worker::render::RenderedTile> = HashMap::new();
    loop {
        if *stop.borrow() {
            break;
        }
        let asked = Instant::now();
        let answer = tokio::select! {
            a = api.lease(id, LEASE_WAIT, None) => a,
            _ = stop.wait_for(|s| *s) => break,
        };
        let lease = match answer {
            Ok(LeaseAnswer::Assigned(lease)) => lease,
            Ok(LeaseAnswer::NoWork) => {
                tally.no_work += 1;
                continue;
            }
            Err(e) => {
                let transient = e.is_transient();
                tally.error(format!("lease: {e}"));
                if !transient {
                    break;
                }
                tokio::time::sleep(ERROR_PAUSE).await;
                continue;
            }
        };
        tally.lease_ms.push(millis(asked.elapsed()));
        let task = lease.token.task_id;
        tally.leased.push(task);
        // The upload is not cut short by `stop`: a tile half sent would look like a loss.
        let rect = worker::render::tile_rect(&lease);
        let tile = match encoded.entry(rect) {
            Entry::Occupied(known) => known.into_mut(),
            Entry::Vacant(new) => {
                // ZIP, as workers on other machines send them.
                let pixels = tile_pixels(rect, noise);
                match worker::render::encode_tile(&lease, &pixels, 0, ExrCompression::Zip) {
                    Ok(tile) => new.insert(tile),
                    Err(e) => {
                        tally.error(format!("encoding the tile of task {task}: {e}"));
                        continue;
                    }
                }
            }
        };
        let meta = proto::ResultMetadata {
            attempt: lease.token.attempt,
            ..tile.meta.clone()
        };
        for attempt in 1..=UPLOAD_TRIES {
            let sent = Instant::now();
            match api.upload(id, task, &meta, tile.exr.clone()).await {
                Ok(UploadAnswer::Stored(ack)) => {
                    tally.upload_ms.push(millis(sent.elapsed()));
                    tally.acks.push((task, ack.accepted));
                    if ack.accepted {
                        tally.upload_bytes += tile.exr.len() as u64;
                        tally.last_accept = Some(Instant::now());
                        accepted.fetch_add(1, Ordering::Relaxed);
                    }
                    break;
                }
                Ok(UploadAnswer::LeaseGone(m) | UploadAnswer::Refused(m)) => {
                    tally.refused += 1;
                    tally.error(format!("upload of task {task} refused: {m}"));
                    break;
                }
                Err(e) => {
                    let again = e.is_transient() && attempt < UPLOAD_TRIES;
                    tally.error(format!("upload of task {task}: {e}"));
                    if !again {
                        break;
                    }
                    tokio::time::sleep(ERROR_PAUSE).await;
                }
            }
        }
    }
    tally
}

/// A simulated worker's tile at `rect`: black, or one sample per pixel of random values
/// seeded by the place.
fn tile_pixels(rect: TileRect, noise: bool) -> TileBuffer {
    let mut tile = TileBuffer::new(rect);
    if !noise {
        return tile;
    }
    let mut rng = Rng(u64::from(rect.x) << 32 | u64::from(rect.y));
    let mut v3 = || glam::Vec3::new(rng.next(), rng.next(), rng.next());
    for i in 0..rect.area() {
        let sample = SampleValue {
            radiance: v3() * 4.0,
            alpha: 1.0,
            albedo: v3(),
            normal: (v3() - 0.5).normalize_or_zero(),
            depth: Some(1.0 + v3().x * 10.0),
            motion: (v3().truncate() - 0.5) * 8.0,
            rays: 1,
        };
        tile.add(i, 0, &sample);
    }
    tile
}

/// The `tessera server` child process. Dropping it stops it.
struct ServerProcess {
    child: Child,
    url: String,
    log: PathBuf,
}

impl ServerProcess {
    /// Starts `tessera server` on a free loopback port (the server picks it: no race with
    /// other programs) and waits for it to log its address.
    fn start(data: &Path, log: &Path, max_tasks: u64) -> anyhow::Result<ServerProcess> {
        let mut cmd = tessera_command(log)?;
        cmd.arg("server")
            .arg("--listen")
            .arg("127.0.0.1:0")
            .arg("--data")
            .arg(data)
            .arg("--max-tasks-per-job")
            .arg(max_tasks.to_string())
            // The address line must be logged, and nothing per request.
            .env("RUST_LOG", "info,tower_http=warn");
        let child = cmd.spawn().with_context(|| {
            format!(
                "starting the server ({})",
                cmd.get_program().to_string_lossy()
            )
        })?;
        let mut server = ServerProcess {
            child,
            url: String::new(),
            log: log.to_path_buf(),
        };
        let until = Instant::now() + SERVER_START;
        loop {
            let text = std::fs::read_to_string(log).unwrap_or_default();
            if let Some(url) = listening_url(&text) {
                server.url = url;
                return Ok(server);
            }
            if let Some(status) = server.child.try_wait()? {
                bail!("the server exited at start ({status}):\n{text}");
            }
            if Instant::now() > until {
                bail!(
                    "the server did not start listening within {} s:\n{text}",
                    SERVER_START.as_secs()
                );
            }
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    fn pid(&self) -> u32 {
        self.child.id()
    }

    fn exited(&mut self) -> bool {
        !matches!(self.child.try_wait(), Ok(None))
    }

    /// SIGTERM, then SIGKILL after [`SERVER_GRACE`].
    fn stop(&mut self) {
        if self.exited() {
            return;
        }
        terminate(&mut self.child);
        let until = Instant::now() + SERVER_GRACE;
        while !self.exited() && Instant::now() < until {
            std::thread::sleep(Duration::from_millis(20));
        }
        if !self.exited() {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}

impl Drop for ServerProcess {
    fn drop(&mut self) {
        self.stop();
    }
}

/// The `http://127.0.0.1:PORT` in the server's "Tessera farm on ..." log line.
fn listening_url(log: &str) -> Option<String> {
    let line = log
        .lines()
        .find(|l| l.contains("Tessera farm on http://"))?;
    let at = line.find("http://")?;
    let url = line[at..].split_whitespace().next()?;
    Some(url.to_string())
}

/// A process's `VmHWM` and `VmRSS` from `/proc/<pid>/status`, MiB.
fn memory_of(pid: u32) -> (Option<f64>, Option<f64>) {
    let Ok(status) = std::fs::read_to_string(format!("/proc/{pid}/status")) else {
        return (None, None);
    };
    let field = |name: &str| {
        status
            .lines()
            .find_map(|l| l.strip_prefix(name))
            .and_then(|rest| {
                rest.trim()
                    .trim_end_matches("kB")
                    .trim()
                    .parse::<f64>()
                    .ok()
            })
            .map(|kb| kb / 1024.0)
    };
    (field("VmHWM:"), field("VmRSS:"))
}

/// User plus system CPU seconds of a process (`self` or a pid) from `/proc/<pid>/stat`.
#[cfg(unix)]
pub(crate) fn cpu_seconds(pid: &str) -> Option<f64> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    // Fields after the command name (which may hold spaces) in parentheses: state is the
    // 3rd field, utime and stime the 14th and 15th.
    let rest: Vec<&str> = stat.rsplit_once(')')?.1.split_whitespace().collect();
    let ticks = rest.get(11)?.parse::<f64>().ok()? + rest.get(12)?.parse::<f64>().ok()?;
    // SAFETY: sysconf only reads a system constant.
    let per_second = unsafe { libc::sysconf(libc::_SC_CLK_TCK) };
    (per_second > 0).then(|| ticks / per_second as f64)
}

#[cfg(not(unix))]
pub(crate) fn cpu_seconds(_pid: &str) -> Option<f64> {
    None
}

/// CPU seconds (user and system) of every child process that has ended and been waited
/// for: the difference across one child's run is that child's.
#[cfg(unix)]
pub(crate) fn children_cpu_seconds() -> Option<f64> {
    let mut usage = std::mem::MaybeUninit::<libc::rusage>::zeroed();
    // SAFETY: getrusage writes the struct it is given and nothing else.
    let usage = unsafe {
        if libc::getrusage(libc::RUSAGE_CHILDREN, usage.as_mut_ptr()) != 0 {
            return None;
        }
        usage.assume_init()
    };
    let seconds = |t: libc::timeval| t.tv_sec as f64 + t.tv_usec as f64 * 1e-6;
    Some(seconds(usage.ru_utime) + seconds(usage.ru_stime))
}

#[cfg(not(unix))]
pub(crate) fn children_cpu_seconds() -> Option<f64> {
    None
}

/// The job the bench submits: the still demo scene, 1 sample, 8×8 tiles.
fn bench_spec(digest: &str, shape: Shape) -> JobSpec {
    let (width, height) = shape.size();
    let mut spec = JobSpec::new(digest);
    spec.name = Some("tessera bench farm".into());
    spec.frames = Some(proto::FrameRange {
        start: 0,
        end: (shape.frames - 1) as i32,
        step: 1,
    });
    (spec.width, spec.height) = (width, height);
    spec.spp = 1;
    spec.max_depth = 1;
    spec.tile_size = Some(shape.tile);
    spec.sample_passes = 1;
    spec
}

/// The data folder: the one given (new or empty), or a fresh temporary one.
pub(crate) fn data_folder(given: Option<&PathBuf>) -> anyhow::Result<(PathBuf, bool)> {
    match given {
        Some(dir) => {
            let empty = match std::fs::read_dir(dir) {
                Ok(mut entries) => entries.next().is_none(),
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => true,
                Err(e) => return Err(e).with_context(|| format!("reading {}", dir.display())),
            };
            if !empty {
                bail!(
                    "--data {}: the folder is not empty; give a new or empty one, so that \
                     only the bench's job runs",
                    dir.display()
                );
            }
            std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
            Ok((dir.clone(), false))
        }
        None => {
            let nanos = std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(0, |d| d.subsec_nanos());
            let dir = std::env::temp_dir()
                .join(format!("tessera-bench-farm-{}-{nanos}", std::process::id()));
            std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
            Ok((dir, true))
        }
    }
}

pub fn run(args: FarmBenchArgs) -> anyhow::Result<()> {
    let shape = job_shape(args.tasks, args.tile_size);
    let (dir, temporary) = data_folder(args.data.as_ref())?;
    let data = dir.join("data");
    let log = dir.join("server.log");
    let mut server = ServerProcess::start(&data, &log, shape.tasks())?;
    let ((w, h), t) = (shape.size(), shape.tile);
    println!(
        "tessera bench farm: {} empty tasks ({} frames × {} {} tiles of {t}x{t}, frames \
         {w}x{h}), {} simulated workers; server pid {} on {}",
        shape.tasks(),
        shape.frames,
        shape.tiles_x * shape.tiles_y,
        if args.noise { "noise" } else { "black" },
        args.workers,
        server.pid(),
        server.url
    );

    let runtime = tokio::runtime::Runtime::new().context("starting the async runtime")?;
    let result = runtime.block_on(load(&args, shape, &mut server));
    runtime.shutdown_timeout(Duration::from_secs(1));
    let final_memory = memory_of(server.pid());
    server.stop();
    let mut report = match result {
        Ok(report) => report,
        Err(e) => {
            return Err(e.context(format!(
                "the farm bench failed; the server's log: {}",
                log.display()
            )))
        }
    };
    (
        report.server_memory.peak_rss_mib,
        report.server_memory.final_rss_mib,
    ) = final_memory;

    print_table(&report);
    if let Some(path) = &args.json {
        let json = serde_json::to_string_pretty(&report)?;
        std::fs::write(path, json + "\n").with_context(|| format!("writing {}", path.display()))?;
    }
    if !report.passed {
        bail!(
            "the farm bench failed: {} tasks not done (lost), {} duplicates, {} refused \
             uploads{}; the server's data and log stay in {}",
            report.lost,
            report.duplicates,
            report.refused_uploads,
            if report.timed_out {
                format!(", timed out after {} s", args.timeout_seconds)
            } else {
                String::new()
            },
            dir.display()
        );
    }
    if temporary {
        let _ = std::fs::remove_dir_all(&dir);
    }
    Ok(())
}

/// Upload the scene, register the workers, create the job, run the load until the job
/// ends or the timeout, and count.
async fn load(
    args: &FarmBenchArgs,
    shape: Shape,
    server: &mut ServerProcess,
) -> anyhow::Result<Report> {
    let client = Client::new(&server.url, None)?;
    let glb = tracer::export::scene_to_glb(&tracer::demo::demo_scene())
        .map_err(|e| anyhow::anyhow!("exporting the demo scene to GLB: {e}"))?;
    let scene = client
        .upload_scene(glb)
        .await
        .context("uploading the demo scene")?;

    // Every worker registers first, so that the clock measures only leasing and uploads.
    let api_base = format!("{}{}", server.url, proto::API_PREFIX);
    let mut registering = JoinSet::new();
    for k in 1..=args.workers {
        let api = Api::new(&server.url, &api_base, None, None)?;
        registering.spawn(async move {
            let reg = WorkerRegistration {
                name: format!("bench-{k}"),
                threads: 1,
                version: env!("CARGO_PKG_VERSION").into(),
                ..Default::default()
            };
            let id = api.register(&reg).await?.worker_id;
            Ok::<_, ApiError>((api, id))
        });
    }
    let mut workers = Vec::new();
    while let Some(done) = registering.join_next().await {
        workers.push(done?.context("registering a simulated worker")?);
    }
    let idle_rss_mib = memory_of(server.pid()).1;

    let created = Instant::now();
    let job = client
        .create_job(&bench_spec(&scene.digest, shape))
        .await
        .context("creating the bench job")?;
    let create_job_seconds = created.elapsed().as_secs_f64();
    let tasks = job.tasks.total();
    let started = Instant::now();
    let cpu_at_start = (cpu_seconds("self"), cpu_seconds(&server.pid().to_string()));

    let (set_stop, stop) = watch::channel(false);
    let accepted = Arc::new(AtomicU64::new(0));
    let listener = args
        .events
        .then(|| tokio::spawn(listen_to_events(format!("{api_base}/events"), stop.clone())));
    let mut running = JoinSet::new();
    for (api, id) in workers {
        running.spawn(simulated_worker(
            api,
            id,
            args.noise,
            stop.clone(),
            accepted.clone(),
        ));
    }

    // Follow the job until it ends, the timeout, Ctrl-C or the server's death.
    let deadline = started + Duration::from_secs(args.timeout_seconds);
    let mut last_progress = Instant::now();
    let mut last_status = Instant::now();
    let mut timed_out = false;
    let mut interrupted = std::pin::pin!(crate::signal::interrupted());
    let status = loop {
        tokio::select! {
            _ = tokio::time::sleep(TICK) => {}
            _ = &mut interrupted => {
                let _ = set_stop.send(true);
                bail!("interrupted");
            }
        }
        if server.exited() {
            let _ = set_stop.send(true);
            bail!(
                "the server exited during the load; the end of its log:\n{}",
                tail(&server.log, 10)
            );
        }
        let all_in = accepted.load(Ordering::Relaxed) >= tasks;
        let late = Instant::now() >= deadline;
        if all_in || late || last_status.elapsed() >= STATUS_EVERY {
            last_status = Instant::now();
            let status = client
                .job(job.id)
                .await
                .context("reading the job's status")?;
            if crate::progress::has_ended(&status) {
                break status;
            }
            if late {
                timed_out = true;
                break status;
            }
        }
        if last_progress.elapsed() >= PROGRESS_EVERY {
            last_progress = Instant::now();
            let n = accepted.load(Ordering::Relaxed);
            eprintln!(
                "  {n}/{tasks} tasks done after {:.0} s ({:.0}/s)",
                started.elapsed().as_secs_f64(),
                n as f64 / started.elapsed().as_secs_f64()
            );
        }
    };
    let mut wall_seconds = started.elapsed().as_secs_f64();
    let cpu_at_end = (cpu_seconds("self"), cpu_seconds(&server.pid().to_string()));
    let _ = set_stop.send(true);
    let mut tallies = Vec::new();
    while let Some(t) = running.join_next().await {
        tallies.push(t.context("a simulated worker panicked")?);
    }
    let events_received = match listener {
        Some(l) => l.await.context("the event listener panicked")??,
        None => 0,
    };
    // The status after every upload in flight has been answered.
    let status = client.job(job.id).await.unwrap_or(status);
    // The server's own times: the polls above only see the end some time after it.
    if let (Some(finished), false) = (status.finished_ms, timed_out) {
        wall_seconds = (finished - status.created_ms).max(0) as f64 / 1e3;
    }
    let last_tile_seconds = tallies
        .iter()
        .filter_map(|t| t.last_accept)
        .max()
        .map_or(0.0, |last| last.duration_since(created).as_secs_f64());
    let mut report = report(
        args,
        shape,
        tasks,
        &status,
        tallies,
        wall_seconds,
        create_job_seconds,
        Memory {
            idle_rss_mib,
            ..Memory::default()
        },
        timed_out,
    );
    report.events_received = events_received;
    let metrics = reqwest::get(format!("{}/metrics", server.url))
        .await
        .and_then(|a| a.error_for_status());
    report.assembly = match metrics {
        Ok(answer) => Assembly::from_metrics(&answer.text().await.unwrap_or_default()),
        Err(_) => None,
    };
    report.last_tile_seconds = last_tile_seconds;
    let spent = |a: Option<f64>, b: Option<f64>| Some(b? - a?);
    report.server_cpu_seconds = spent(cpu_at_start.1, cpu_at_end.1);
    report.bench_cpu_seconds = spent(cpu_at_start.0, cpu_at_end.0);
    Ok(report)
}

/// Reads the server's event stream until `stop`, as a dashboard would; returns how many
/// events came.
async fn listen_to_events(url: String, mut stop: watch::Receiver<bool>) -> anyhow::Result<u64> {
    let mut answer = reqwest::Client::new()
        .get(&url)
        .send()
        .await
        .and_then(|a| a.error_for_status())
        .with_context(|| format!("opening the event stream {url}"))?;
    let mut events = 0;
    loop {
        let chunk = tokio::select! {
            c = answer.chunk() => c.context("reading the event stream")?,
            _ = stop.wait_for(|s| *s) => break,
        };
        let Some(chunk) = chunk else { break };
        // Each event has one `event:` line (keep-alives are comments).
        events += chunk
            .split(|&b| b == b'\n')
            .filter(|l| l.starts_with(b"event:"))
            .count() as u64;
    }
    Ok(events)
}

/// The figures from what the workers saw and the job's final status.
#[allow(clippy::too_many_arguments)]
fn report(
    args: &FarmBenchArgs,
    shape: Shape,
    tasks: u64,
    status: &JobStatus,
    tallies: Vec<Tally>,
    wall_seconds: f64,
    create_job_seconds: f64,
    server_memory: Memory,
    timed_out: bool,
) -> Report {
    let mut lease_ms = Vec::new();
    let mut upload_ms = Vec::new();
    let mut accepts: HashMap<u64, u64> = HashMap::new();
    let mut leases: HashMap<u64, u64> = HashMap::new();
    let (mut ignored_repeats, mut no_work, mut bytes, mut refused, mut errors) = (0, 0, 0, 0, 0);
    let mut first_error = None;
    for t in tallies {
        lease_ms.extend(t.lease_ms);
        upload_ms.extend(t.upload_ms);
        for task in t.leased {
            *leases.entry(task).or_default() += 1;
        }
        for (task, accepted) in t.acks {
            if accepted {
                *accepts.entry(task).or_default() += 1;
            } else {
                ignored_repeats += 1;
            }
        }
        no_work += t.no_work;
        bytes += t.upload_bytes;
        refused += t.refused;
        errors += t.errors;
        first_error = first_error.or(t.first_error);
    }
    let accepted: u64 = accepts.values().sum();
    let accepted_twice = accepts.values().filter(|&&n| n > 1).count() as u64;
    let leased_again = leases.values().filter(|&&n| n > 1).count() as u64;
    let duplicates = accepted_twice + ignored_repeats;
    let lost = status.tasks.total().saturating_sub(status.tasks.done);
    let seconds = wall_seconds.max(1e-9);
    Report {
        tasks_requested: args.tasks,
        tasks,
        workers: args.workers,
        frames: shape.frames,
        tiles_per_frame: (shape.tiles_x * shape.tiles_y) as u64,
        frame_size: shape.size(),
        wall_seconds,
        last_tile_seconds: 0.0,
        create_job_seconds,
        tasks_per_second: accepted as f64 / seconds,
        lease_latency_ms: Latency::of(lease_ms),
        upload_latency_ms: Latency::of(upload_ms),
        no_work_answers: no_work,
        accepted,
        duplicates,
        accepted_twice,
        ignored_repeats,
        leased_again,
        lost,
        refused_uploads: refused,
        errors,
        first_error,
        events_listener: args.events,
        events_received: 0,
        upload_bytes: bytes,
        upload_mb_per_second: bytes as f64 / 1e6 / seconds,
        assembly: None,
        job_state: format!("{:?}", status.state).to_lowercase(),
        frames_done: status.frames_done,
        server_memory,
        server_cpu_seconds: None,
        bench_cpu_seconds: None,
        timed_out,
        passed: lost == 0
            && duplicates == 0
            && refused == 0
            && !timed_out
            && accepted == tasks
            && status.state == JobState::Done,
    }
}

fn print_table(r: &Report) {
    let mib = |v: Option<f64>| v.map_or("n/a".into(), |v| format!("{v:.1} MiB"));
    let m = &r.server_memory;
    let (l, u) = (&r.lease_latency_ms, &r.upload_latency_ms);
    println!("| figure | value |");
    println!("|---|---:|");
    println!(
        "| tasks done | {} of {} in {:.2} s ({} frames assembled; last tile acknowledged at {:.2} s) |",
        r.accepted, r.tasks, r.wall_seconds, r.frames_done, r.last_tile_seconds
    );
    println!("| tasks per second | {:.1} |", r.tasks_per_second);
    println!(
        "| lease latency p50 / p99 / max | {:.1} / {:.1} / {:.1} ms |",
        l.p50, l.p99, l.max
    );
    println!(
        "| upload latency p50 / p99 / max | {:.1} / {:.1} / {:.1} ms |",
        u.p50, u.p99, u.max
    );
    println!(
        "| tile uploads | {:.2} MB, {:.2} MB/s |",
        r.upload_bytes as f64 / 1e6,
        r.upload_mb_per_second
    );
    if let Some(a) = &r.assembly {
        println!(
            "| frame assembly | {} frames from {:.2} MB of tiles in {:.2} s: {:.1} MB/s, {:.1} ms per frame |",
            a.frames,
            a.tile_bytes as f64 / 1e6,
            a.seconds,
            a.mb_per_second,
            a.mean_ms
        );
    }
    println!(
        "| server memory idle / peak / end | {} / {} / {} |",
        mib(m.idle_rss_mib),
        mib(m.peak_rss_mib),
        mib(m.final_rss_mib)
    );
    println!(
        "| lost / done twice / repeats ignored | {} / {} / {} |",
        r.lost, r.accepted_twice, r.ignored_repeats
    );
    println!(
        "| leased again / refused uploads / errors | {} / {} / {} |",
        r.leased_again, r.refused_uploads, r.errors
    );
    let secs = |v: Option<f64>| v.map_or("n/a".into(), |v| format!("{v:.1} s"));
    println!(
        "| CPU during the load: server / bench | {} / {} |",
        secs(r.server_cpu_seconds),
        secs(r.bench_cpu_seconds)
    );
    println!("| job creation | {:.2} s |", r.create_job_seconds);
    if r.events_listener {
        println!("| events received (--events) | {} |", r.events_received);
    }
    if let Some(e) = &r.first_error {
        println!("first error: {e}");
    }
}

/// The last `n` lines of a log file.
fn tail(path: &Path, n: usize) -> String {
    let text = std::fs::read_to_string(path).unwrap_or_default();
    let lines: Vec<&str> = text.lines().collect();
    lines[lines.len().saturating_sub(n)..].join("\n")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn assembly_figures_come_from_the_servers_metrics() {
        let text = "tessera_frames_assembled_total 4\n\
                    tessera_frame_assembly_seconds{quantile=\"0.5\"} 0.2\n\
                    tessera_frame_assembly_seconds_sum 0.8\n\
                    tessera_frame_assembly_seconds_count 4\n\
                    tessera_frame_assembly_tile_bytes_total 16000000\n";
        let a = Assembly::from_metrics(text).unwrap();
        assert_eq!((a.frames, a.tile_bytes), (4, 16_000_000));
        assert!((a.mb_per_second - 20.0).abs() < 1e-9 && (a.mean_ms - 200.0).abs() < 1e-9);
        assert_eq!(Assembly::from_metrics("tessera_leases_total 3\n"), None);
    }

    /// Noise tiles carry every layer, differ from place to place and are the same for the
    /// same place (so one encoding serves every frame).
    #[test]
    fn noise_tiles_are_seeded_by_their_place() {
        let (a, b) = (TileRect::new(0, 0, 8, 8), TileRect::new(8, 0, 8, 8));
        let tile = tile_pixels(a, true).resolve();
        assert!(
            tile.beauty.iter().all(|p| p.w == 1.0),
            "every pixel covered"
        );
        assert!(tile.albedo.iter().all(|a| a.max_element() > 0.0));
        assert!(tile.normal.iter().all(|n| (n.length() - 1.0).abs() < 1e-3));
        assert_eq!(tile_pixels(a, true), tile_pixels(a, true));
        assert_ne!(tile_pixels(a, true).beauty, tile_pixels(b, true).beauty);
        assert_eq!(tile_pixels(a, false), TileBuffer::new(a));
    }

    #[test]
    fn the_job_shape_gives_the_task_count_exactly_when_it_can() {
        let s = job_shape(20_000, TILE);
        assert_eq!((s.frames, s.tiles_x, s.tiles_y), (200, 10, 10));
        assert_eq!(s.size(), (80, 80));
        assert_eq!(job_shape(400, 64).size(), (640, 640));
        assert_eq!(job_shape(400, TILE).tasks(), 400);
        assert_eq!(job_shape(1, TILE).tasks(), 1);
        // A prime below the frame limit: one tile per frame.
        assert_eq!(job_shape(997, TILE).tasks(), 997);
        for n in [2, 12, 128, 1000, 65_536, 99_991, 1_000_000] {
            let s = job_shape(n, TILE);
            assert_eq!(s.tasks(), n, "{s:?}");
            assert!(s.frames <= server::limits::MAX_FRAMES);
        }
        // A prime above it: the nearest count the limits allow.
        let s = job_shape(999_983, TILE);
        assert!(s.tasks().abs_diff(999_983) <= MAX_TILES_PER_FRAME, "{s:?}");
    }

    #[test]
    fn latencies_are_nearest_rank_percentiles() {
        let l = Latency::of((1..=100).rev().map(f64::from).collect());
        assert_eq!((l.count, l.p50, l.p99, l.max), (100, 50.0, 99.0, 100.0));
        assert_eq!(l.mean, 50.5);
        let one = Latency::of(vec![3.0]);
        assert_eq!((one.p50, one.p99), (3.0, 3.0));
        assert_eq!(Latency::of(vec![]), Latency::default());
    }

    #[test]
    fn farm_is_a_subcommand_of_bench_and_the_tracer_bench_still_parses() {
        use crate::bench::{BenchArgs, BenchCommand};
        use clap::Parser;
        #[derive(Parser)]
        struct Cli {
            #[command(flatten)]
            bench: BenchArgs,
        }
        let parse = |args: &[&str]| Cli::try_parse_from(args).map(|c| c.bench);
        let b = parse(&["bench"]).unwrap();
        assert!(b.command.is_none());
        let b = parse(&["bench", "scene.glb", "--quick"]).unwrap();
        assert!(b.command.is_none());
        let b = parse(&["bench", "farm", "--workers", "20", "--tasks", "400"]).unwrap();
        let Some(BenchCommand::Farm(f)) = b.command else {
            panic!("farm parsed as a scene")
        };
        assert_eq!((f.workers, f.tasks, f.timeout_seconds), (20, 400, 600));
        let Some(BenchCommand::Farm(f)) = parse(&["bench", "farm"]).unwrap().command else {
            panic!("no farm subcommand")
        };
        assert_eq!((f.workers, f.tasks, f.events), (200, 20_000, false));
        assert!(parse(&["bench", "farm", "--workers", "0"]).is_err());
        assert!(parse(&["bench", "farm", "--quick"]).is_err());
        let b = parse(&["bench", "overhead", "--quick", "--runs", "2"]).unwrap();
        assert!(matches!(b.command, Some(BenchCommand::Overhead(_))));
        assert!(parse(&["bench", "overhead", "--runs", "0"]).is_err());
        let b = parse(&["bench", "cornell", "--quick", "--runs", "5"]).unwrap();
        let Some(BenchCommand::Cornell(c)) = b.command else {
            panic!("no cornell subcommand")
        };
        assert_eq!((c.quick, c.runs), (true, 5));
        assert!(parse(&["bench", "cornell", "--runs", "21"]).is_err());
        let b = parse(&["bench", "features", "--size", "32x16", "--runs", "4"]).unwrap();
        let Some(BenchCommand::Features(f)) = b.command else {
            panic!("no features subcommand")
        };
        assert_eq!((f.size, f.spp, f.runs), ((32, 16), 32, 4));
        assert!(parse(&["bench", "features", "--runs", "0"]).is_err());
    }

    #[test]
    fn the_servers_address_is_read_from_its_log() {
        let log =
            "2025 INFO tessera::server: Tessera farm on http://127.0.0.1:41234 (data in /x)\n";
        assert_eq!(
            listening_url(log).as_deref(),
            Some("http://127.0.0.1:41234")
        );
        assert_eq!(listening_url("starting\n"), None);
    }
}

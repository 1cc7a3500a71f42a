//! Following a job on the farm until it ends: a progress bar fed by polling
//! `GET /jobs/{id}`, then every finished frame downloaded as `frame_0001.exr` and
//! `frame_0001.png`. `tessera submit --wait` and `tessera demo` both use [`follow`].

use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::Context;
use indicatif::{ProgressBar, ProgressStyle};
use proto::{FrameState, FrameStatus, JobState, JobStatus};

use crate::client::{Client, ClientError, FrameFile};

/// How often the job's status is read while waiting.
pub const POLL_INTERVAL: Duration = Duration::from_millis(500);
/// Polls in a row that may fail (a server restarting, a network blip) before giving up.
const MAX_FAILED_POLLS: u32 = 40;

/// How waiting for a job ended.
#[derive(Debug)]
pub enum Watched {
    /// The job finished: done, failed or cancelled, nothing left running.
    Ended(JobStatus),
    /// Ctrl-C (or SIGTERM) stopped the waiting; the job itself goes on. The last status read.
    Interrupted(JobStatus),
}

/// What [`follow`] did.
#[derive(Debug)]
pub enum Followed {
    /// The job ended and its finished frames are in the folder.
    Ended {
        /// The job's last status.
        status: JobStatus,
        /// What was downloaded.
        downloaded: Downloaded,
    },
    /// Waiting was interrupted; nothing was downloaded.
    Interrupted(JobStatus),
}

/// Frames written to a folder.
#[derive(Debug, Default)]
pub struct Downloaded {
    /// The folder.
    pub dir: PathBuf,
    /// Frame numbers whose EXR was written, in order.
    pub frames: Vec<i32>,
    /// Bytes written.
    pub bytes: u64,
    /// Files already there and kept (when resuming).
    pub kept: u64,
    /// The job's MP4, when it has one.
    pub video: Option<PathBuf>,
}

/// Whether nothing more will happen to the job without a person acting (retry, resume,
/// or a worker that may take a stuck job's tasks).
pub fn has_ended(s: &JobStatus) -> bool {
    s.finished_ms.is_some()
        || s.stuck.is_some()
        || s.state == JobState::Done
        || (s.state == JobState::Cancelled && s.tasks.leased == 0)
}

/// The job's state as a word for tables and messages.
pub fn state_name(state: JobState) -> &'static str {
    match state {
        JobState::Queued => "queued",
        JobState::Running => "running",
        JobState::Paused => "paused",
        JobState::Cancelled => "cancelled",
        JobState::Failed => "failed",
        JobState::Done => "done",
    }
}

/// Seconds as `42s`, `3m 05s` or `2h 07m`.
pub fn duration(seconds: f64) -> String {
    if !seconds.is_finite() || seconds < 0.0 {
        return "?".into();
    }
    let s = seconds.round() as u64;
    match s {
        0..60 => format!("{s}s"),
        60..3600 => format!("{}m {:02}s", s / 60, s % 60),
        _ => format!("{}h {:02}m", s / 3600, (s % 3600) / 60),
    }
}

/// Samples per second with an SI prefix: `950 samples/s`, `1.23 M samples/s`.
pub fn rate(samples_per_second: f64) -> String {
    let r = samples_per_second.max(0.0);
    if r >= 1e9 {
        format!("{:.2} G samples/s", r / 1e9)
    } else if r >= 1e6 {
        format!("{:.2} M samples/s", r / 1e6)
    } else if r >= 1e3 {
        format!("{:.1} k samples/s", r / 1e3)
    } else {
        format!("{r:.0} samples/s")
    }
}

/// The line beside the bar: frames, ETA, the state when it is not simply running, rate.
pub fn progress_message(s: &JobStatus) -> String {
    // Most important first: a narrow terminal cuts the end off.
    let mut parts = vec![format!("frames {}/{}", s.frames_done, s.frames_total)];
    if let Some(eta) = s.eta_seconds {
        parts.push(format!("ETA {}", duration(eta)));
    }
    if let Some(b) = &s.budget {
        parts.push(format!("{} passes added", b.passes_added));
    }
    match s.state {
        JobState::Running => {}
        JobState::Queued => parts.push("waiting for a worker".into()),
        JobState::Failed => parts.push(format!(
            "{} task(s) failed; the other frames go on",
            s.tasks.failed
        )),
        other => parts.push(state_name(other).into()),
    }
    if s.samples_per_second > 0.0 {
        parts.push(rate(s.samples_per_second));
    }
    if let Some(why) = &s.waiting {
        parts.push(format!("waiting: {why}"));
    }
    parts.join(" · ")
}

/// How often a progress line is printed when there is no terminal for the bar.
const PROGRESS_LINE_EVERY: Duration = Duration::from_secs(10);

/// One line of progress for a log: `job 3: 6/12 tasks · frames 1/4 · ETA 1m 05s · ...`.
fn progress_line(s: &JobStatus) -> String {
    format!(
        "job {}: {}/{} tasks · {}",
        s.id,
        s.tasks.done,
        s.tasks.total(),
        progress_message(s)
    )
}

fn bar(total: u64) -> ProgressBar {
    let bar = ProgressBar::new(total);
    let style = ProgressStyle::with_template(
        "{spinner:.green} {elapsed:>4} [{bar:24.cyan/blue}] {pos}/{len} tasks · {wide_msg}",
    )
    .expect("the template is valid")
    .progress_chars("=> ");
    bar.set_style(style);
    bar.enable_steady_tick(Duration::from_millis(120));
    bar
}

/// Prints a line above a progress bar (or plainly when the bar is hidden, as it is when
/// stderr is not a terminal).
fn note(bar: &ProgressBar, line: &str) {
    bar.suspend(|| eprintln!("{line}"));
}

/// Polls the job (`job` is its status as last read, e.g. the answer to its creation) about
/// twice a second, drawing a progress bar, until it ends or Ctrl-C. `check` runs after every poll (the demo watches its worker processes with it):
/// `Ok(Some(line))` prints the line above the bar, an error stops waiting with that error.
pub async fn watch(
    client: &Client,
    job: JobStatus,
    mut check: impl FnMut(&JobStatus) -> anyhow::Result<Option<String>>,
) -> anyhow::Result<Watched> {
    // One listener for the whole wait (it starts listening when first polled, below,
    // with no await before): a signal between two polls must not be lost.
    let interrupted = crate::signal::interrupted();
    tokio::pin!(interrupted);
    let (id, mut status) = (job.id, job);
    let bar = bar(status.tasks.total());
    // Without a terminal the bar is hidden: a line now and then tells a log how it goes.
    let mut lines = (!std::io::stderr().is_terminal()).then_some(None::<Instant>);
    let mut failed_polls = 0;
    loop {
        bar.set_length(status.tasks.total());
        bar.set_position(status.tasks.done);
        bar.set_message(progress_message(&status));
        if let Some(last) = &mut lines {
            if last.is_none_or(|t| t.elapsed() >= PROGRESS_LINE_EVERY) || has_ended(&status) {
                *last = Some(Instant::now());
                eprintln!("{}", progress_line(&status));
            }
        }
        if let Some(line) = check(&status).inspect_err(|_| bar.abandon())? {
            note(&bar, &line);
        }
        if has_ended(&status) {
            bar.finish_and_clear();
            return Ok(Watched::Ended(status));
        }
        tokio::select! {
            _ = &mut interrupted => {
                bar.abandon();
                return Ok(Watched::Interrupted(status));
            }
            _ = tokio::time::sleep(POLL_INTERVAL) => {}
        }
        match client.job(id).await {
            Ok(s) => {
                status = s;
                failed_polls = 0;
            }
            // A job deleted under us will not come back.
            Err(e @ ClientError::Api { .. })
                if e.status() == Some(reqwest::StatusCode::NOT_FOUND) =>
            {
                bar.abandon();
                return Err(e).with_context(|| format!("job {id} is gone"));
            }
            Err(e) => {
                failed_polls += 1;
                if failed_polls == 1 {
                    note(&bar, &format!("reading job {id}: {e}; trying again"));
                }
                if failed_polls >= MAX_FAILED_POLLS {
                    bar.abandon();
                    return Err(e).with_context(|| {
                        format!("lost the server while waiting for job {id} (it may still run)")
                    });
                }
            }
        }
    }
}

/// Downloads every done frame of job `id` into `dir` (created when missing) as
/// `frame_0001.exr` and `frame_0001.png`. Each file is written whole or not at all (a
/// temp file renamed), so with `resume` a file already there is kept and not fetched
/// again: an interrupted download goes on where it stopped.
pub async fn download_frames(
    client: &Client,
    id: u64,
    dir: &Path,
    resume: bool,
) -> anyhow::Result<Downloaded> {
    let frames = client.frames(id).await?;
    let done: Vec<&FrameStatus> = frames
        .frames
        .iter()
        .filter(|f| f.state == FrameState::Done)
        .collect();
    let mut downloaded = Downloaded {
        dir: dir.to_path_buf(),
        ..Downloaded::default()
    };
    if done.is_empty() {
        return Ok(downloaded);
    }
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let bar = ProgressBar::new(done.len() as u64);
    bar.set_style(
        ProgressStyle::with_template("downloading [{bar:30.cyan/blue}] {pos}/{len} frames")
            .expect("the template is valid")
            .progress_chars("=> "),
    );
    for status in done {
        let frame = status.frame;
        for file in [FrameFile::Exr, FrameFile::Png] {
            // The server's name: as wide as the job's last frame, so the files sort.
            let path = dir.join(Path::new(&status.file).with_extension(file.extension()));
            if resume && path.is_file() {
                downloaded.kept += 1;
                continue;
            }
            let bytes = match client.frame_file(id, frame, file).await {
                Ok(bytes) => bytes,
                // The preview is a convenience: a frame without one is still a frame.
                Err(e) if file == FrameFile::Png => {
                    note(&bar, &format!("frame {frame}: no PNG preview ({e})"));
                    continue;
                }
                Err(e) => {
                    bar.abandon();
                    return Err(e).with_context(|| format!("downloading frame {frame}"));
                }
            };
            let part = path.with_extension(format!("{}.part", file.extension()));
            std::fs::write(&part, &bytes)
                .and_then(|()| std::fs::rename(&part, &path))
                .with_context(|| format!("writing {}", path.display()))?;
            downloaded.bytes += bytes.len() as u64;
        }
        downloaded.frames.push(frame);
        bar.inc(1);
    }
    bar.finish_and_clear();
    if client.job(id).await?.video {
        let path = dir.join(VIDEO_FILE);
        if !(resume && path.is_file()) {
            let bytes = client.video(id).await.context("downloading the video")?;
            let part = path.with_extension("mp4.part");
            std::fs::write(&part, &bytes)
                .and_then(|()| std::fs::rename(&part, &path))
                .with_context(|| format!("writing {}", path.display()))?;
            downloaded.bytes += bytes.len() as u64;
        }
        downloaded.video = Some(path);
    }
    Ok(downloaded)
}

impl Downloaded {
    /// What was downloaded where, for the user: `24 frame(s) in shot` and the video.
    pub fn summary(&self) -> String {
        let frames = format!("{} frame(s) in {}", self.frames.len(), self.dir.display());
        match &self.video {
            Some(video) => format!("{frames}; the video is {}", video.display()),
            None => frames,
        }
    }
}

/// The name of a job's MP4 among its downloaded frames.
pub const VIDEO_FILE: &str = "video.mp4";

/// Waits for `job` with a progress bar ([`watch`]), then downloads its finished frames
/// into `dir` ([`download_frames`]), even when the job failed or was cancelled.
pub async fn follow(
    client: &Client,
    job: JobStatus,
    dir: &Path,
    check: impl FnMut(&JobStatus) -> anyhow::Result<Option<String>>,
) -> anyhow::Result<Followed> {
    let id = job.id;
    match watch(client, job, check).await? {
        Watched::Interrupted(status) => Ok(Followed::Interrupted(status)),
        Watched::Ended(status) => {
            let downloaded = download_frames(client, id, dir, false).await?;
            Ok(Followed::Ended { status, downloaded })
        }
    }
}

/// Ok for a job that is done; for a failed or cancelled one an error that says how many
/// frames finished and what to do next.
pub fn require_done(
    status: &JobStatus,
    downloaded: &Downloaded,
    server: &str,
) -> anyhow::Result<()> {
    let id = status.id;
    let kept = format!(
        "{} of {} frames finished and were downloaded to {}",
        downloaded.frames.len(),
        status.frames_total,
        downloaded.dir.display()
    );
    if let Some(why) = &status.stuck {
        anyhow::bail!(
            "job {id} cannot go on: {why}; {kept}. See `tessera status {id} --server {server}`"
        );
    }
    match status.state {
        JobState::Done => Ok(()),
        JobState::Failed => anyhow::bail!(
            "job {id} failed: {} task(s) in {} frame(s) ran out of attempts; {kept}. See \
             `tessera status {id} --server {server}` and the worker logs; `tessera retry {id}` \
             runs the failed tasks again",
            status.tasks.failed,
            status.frames_failed
        ),
        JobState::Cancelled => anyhow::bail!(
            "job {id} was cancelled; {kept}. `tessera clone {id} --server {server}` submits it \
             again"
        ),
        other => anyhow::bail!("job {id} stopped while {}; {kept}", state_name(other)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proto::{JobSpec, TaskCounts};

    fn status(state: JobState) -> JobStatus {
        JobStatus {
            id: 3,
            name: "job 3".into(),
            state,
            spec: JobSpec::new("abc"),
            created_ms: 0,
            finished_ms: None,
            tasks: TaskCounts {
                queued: 4,
                leased: 2,
                done: 6,
                failed: 0,
                cancelled: 0,
            },
            frames_total: 4,
            frames_done: 1,
            frames_failed: 0,
            progress: 0.5,
            samples_per_second: 1_234_567.0,
            eta_seconds: Some(65.2),
            budget: None,
            attempts_failed: 0,
            stuck: None,
            waiting: None,
            video: false,
        }
    }

    #[test]
    fn durations_and_rates_read_at_a_glance() {
        assert_eq!(duration(0.4), "0s");
        assert_eq!(duration(42.0), "42s");
        assert_eq!(duration(65.2), "1m 05s");
        assert_eq!(duration(7260.0), "2h 01m");
        assert_eq!(duration(f64::NAN), "?");
        assert_eq!(rate(950.0), "950 samples/s");
        assert_eq!(rate(12_345.0), "12.3 k samples/s");
        assert_eq!(rate(1_234_567.0), "1.23 M samples/s");
    }

    #[test]
    fn a_progress_line_names_the_job_and_its_tasks() {
        assert_eq!(
            progress_line(&status(JobState::Running)),
            "job 3: 6/12 tasks · frames 1/4 · ETA 1m 05s · 1.23 M samples/s"
        );
    }

    #[test]
    fn the_bar_message_shows_frames_rate_eta_and_unusual_states() {
        let s = status(JobState::Running);
        assert_eq!(
            progress_message(&s),
            "frames 1/4 · ETA 1m 05s · 1.23 M samples/s"
        );
        let mut s = status(JobState::Paused);
        s.eta_seconds = None;
        assert_eq!(
            progress_message(&s),
            "frames 1/4 · paused · 1.23 M samples/s"
        );
    }

    #[test]
    fn a_job_ends_when_nothing_is_left_to_run() {
        let mut s = status(JobState::Running);
        assert!(!has_ended(&s));
        s.state = JobState::Cancelled;
        assert!(!has_ended(&s), "a leased task may still be assembling");
        s.tasks.leased = 0;
        assert!(has_ended(&s));
        let mut s = status(JobState::Failed);
        assert!(!has_ended(&s), "the other frames still finish");
        s.finished_ms = Some(1);
        assert!(has_ended(&s));
        let mut s = status(JobState::Running);
        s.stuck = Some("no live worker may take its tasks".into());
        assert!(has_ended(&s), "nothing happens until a person acts");
    }

    #[test]
    fn a_stuck_job_is_an_error_that_says_why() {
        let mut s = status(JobState::Running);
        s.stuck = Some("no live worker may take its tasks: of 1 live worker(s), 1 blocked".into());
        let d = Downloaded {
            dir: PathBuf::from("out"),
            frames: vec![1],
            bytes: 10,
            kept: 0,
            video: None,
        };
        let e = require_done(&s, &d, "http://s").unwrap_err().to_string();
        assert!(
            e.starts_with("job 3 cannot go on: no live worker may take its tasks: of 1 live")
                && e.contains("1 of 4 frames finished"),
            "{e}"
        );
    }

    #[test]
    fn a_failed_job_is_an_error_that_counts_what_was_kept() {
        let d = Downloaded {
            dir: PathBuf::from("out"),
            frames: vec![1, 2, 3],
            bytes: 10,
            kept: 0,
            video: None,
        };
        assert!(require_done(&status(JobState::Done), &d, "http://x").is_ok());
        let mut s = status(JobState::Failed);
        s.tasks.failed = 2;
        s.frames_failed = 1;
        let e = require_done(&s, &d, "http://x").unwrap_err().to_string();
        assert!(
            e.contains("job 3 failed") && e.contains("3 of 4 frames"),
            "{e}"
        );
        let e = require_done(&status(JobState::Cancelled), &d, "http://x")
            .unwrap_err()
            .to_string();
        assert!(e.contains("cancelled"), "{e}");
    }
}

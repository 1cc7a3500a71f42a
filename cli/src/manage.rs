//! A job's life after submission: `tessera download`, `clone`, `rerender`, `priority`
//! and `delete`; and `tessera gc`, which removes what the farm keeps no longer.
//! Each takes the job by id or by name.

use std::path::PathBuf;

use anyhow::Context;
use clap::Args;
use proto::{GcReport, GcRequest};

use crate::args::{parse_frame_list, FrameList};
use crate::client::{JobRef, ServerOpts};
use crate::control::{print_json, with_client};
use crate::progress::{self, state_name};
use crate::submit::{folder_name, server_flag, JobArgs};

/// Download a job's finished frames (EXR and PNG preview); run again, it fetches only what
/// is missing.
#[derive(Args, Debug)]
pub struct DownloadArgs {
    /// The job, by id or name.
    pub job: JobRef,
    #[command(flatten)]
    pub server: ServerOpts,
    /// The folder [default: ./<job name>].
    #[arg(long)]
    pub out: Option<PathBuf>,
}

/// Submit a job again with the same scene and settings, the given ones changed.
#[derive(Args, Debug)]
pub struct CloneArgs {
    /// The job to clone, by id or name.
    pub job: JobRef,
    #[command(flatten)]
    pub server: ServerOpts,
    /// The settings to change (any of `tessera submit`'s; the rest stay the job's).
    #[command(flatten)]
    pub settings: JobArgs,
    /// Print the new job's status as JSON.
    #[arg(long)]
    pub json: bool,
}

/// Render some frames of a finished job again from scratch, in the same job (after the
/// workers were fixed, or a frame file was lost): their old files go, their tasks run
/// again with the job's settings.
#[derive(Args, Debug)]
pub struct RerenderArgs {
    /// The job, by id or name.
    pub job: JobRef,
    /// The frames: single frames and ranges, e.g. 12,40-42.
    #[arg(long, value_parser = parse_frame_list, allow_hyphen_values = true)]
    pub frames: FrameList,
    #[command(flatten)]
    pub server: ServerOpts,
    /// Print the job's new status as JSON.
    #[arg(long)]
    pub json: bool,
}

/// Change a job's priority: higher runs first, from its next task on.
#[derive(Args, Debug)]
pub struct PriorityArgs {
    /// The job, by id or name.
    pub job: JobRef,
    /// The new priority, -1000 to 1000.
    #[arg(allow_hyphen_values = true)]
    pub priority: i32,
    #[command(flatten)]
    pub server: ServerOpts,
    /// Print the job's new status as JSON.
    #[arg(long)]
    pub json: bool,
}

/// Delete a job with every file it made (a running job stops: its workers drop their
/// tiles).
#[derive(Args, Debug)]
pub struct DeleteArgs {
    /// The job, by id or name.
    pub job: JobRef,
    #[command(flatten)]
    pub server: ServerOpts,
}

/// Remove finished jobs past the server's `--keep-jobs` (or the rule given) with their
/// frames, scenes no job uses a day after their last upload, and old events; with
/// `--dry-run`, only say what would go.
#[derive(Args, Debug)]
pub struct GcArgs {
    #[command(flatten)]
    pub server: ServerOpts,
    /// Say what would go; remove nothing.
    #[arg(long)]
    pub dry_run: bool,
    /// Keep finished jobs by this rule instead of the server's: the newest N (`50`) or
    /// those finished within an age (`30d`, `12h`).
    #[arg(long, value_name = "RULE")]
    pub keep_jobs: Option<String>,
    /// Print the report as JSON.
    #[arg(long)]
    pub json: bool,
}

pub fn gc(args: GcArgs) -> anyhow::Result<()> {
    with_client(&args.server, |client| async move {
        let request = GcRequest {
            dry_run: args.dry_run,
            keep_jobs: args.keep_jobs,
        };
        let report = client.gc(&request).await.context("collecting")?;
        if args.json {
            return print_json(&report);
        }
        print!("{}", gc_text(&report));
        Ok(())
    })
}

fn gc_text(r: &GcReport) -> String {
    let verb = if r.dry_run { "would remove" } else { "removed" };
    let mut out = format!(
        "{verb} {} finished job(s) (kept: {}), {} unused scene(s) and {} event(s): {} freed\n",
        r.jobs.len(),
        r.keep_jobs,
        r.scenes.len(),
        r.events,
        mib(r.bytes)
    );
    for j in &r.jobs {
        out.push_str(&format!("  job {} `{}`\n", j.id, j.name));
    }
    for s in &r.scenes {
        out.push_str(&format!("  scene {}\n", &s[..12.min(s.len())]));
    }
    out
}

/// Bytes as MiB with one decimal.
fn mib(bytes: u64) -> String {
    format!("{:.1} MiB", bytes as f64 / (1 << 20) as f64)
}

pub fn download(args: DownloadArgs) -> anyhow::Result<()> {
    with_client(&args.server, |client| async move {
        let id = client.resolve(&args.job).await?;
        let job = client.job(id).await?;
        let out = args
            .out
            .unwrap_or_else(|| PathBuf::from(folder_name(&job.name)));
        let got = progress::download_frames(&client, id, &out, true)
            .await
            .with_context(|| format!("downloading job {id}"))?;
        println!(
            "{} of {} frame(s) of job {id} in {} ({} file(s) already there, {} bytes fetched); \
             the job is {}",
            got.frames.len(),
            job.frames_total,
            out.display(),
            got.kept,
            got.bytes,
            state_name(job.state)
        );
        if let Some(video) = &got.video {
            println!("the video is {}", video.display());
        }
        Ok(())
    })
}

pub fn clone(args: CloneArgs) -> anyhow::Result<()> {
    let follow = server_flag(&args.server);
    with_client(&args.server, |client| async move {
        let id = client.resolve(&args.job).await?;
        let original = client.job(id).await?;
        let scene = client
            .scene_info(&original.spec.scene)
            .await
            .with_context(|| format!("reading the scene of job {id}"))?;
        let mut spec = original.spec.clone();
        // A name of its own unless one is given: the server names it after its id.
        spec.name = None;
        args.settings.overlay(&mut spec, &scene)?;
        let job = client
            .create_job(&spec)
            .await
            .with_context(|| format!("submitting a clone of job {id}"))?;
        if args.json {
            return print_json(&job);
        }
        println!(
            "job {} submitted: a clone of job {id}; follow it with `tessera status {}{follow}`",
            job.id, job.id
        );
        Ok(())
    })
}

pub fn rerender(args: RerenderArgs) -> anyhow::Result<()> {
    let follow = server_flag(&args.server);
    with_client(&args.server, |client| async move {
        let id = client.resolve(&args.job).await?;
        let list: Vec<String> = args.frames.0.iter().map(i32::to_string).collect();
        let job = client
            .rerender(id, args.frames.0)
            .await
            .with_context(|| format!("rendering frames {} of job {id} again", list.join(",")))?;
        if args.json {
            return print_json(&job);
        }
        println!(
            "job {id}: {} frame(s) queued to render again; follow it with `tessera status \
             {id}{follow}`",
            list.len()
        );
        Ok(())
    })
}

pub fn priority(args: PriorityArgs) -> anyhow::Result<()> {
    with_client(&args.server, |client| async move {
        let id = client.resolve(&args.job).await?;
        let job = client
            .set_priority(id, args.priority)
            .await
            .with_context(|| format!("setting the priority of job {id}"))?;
        if args.json {
            return print_json(&job);
        }
        println!("job {id} now has priority {}", job.spec.priority);
        Ok(())
    })
}

pub fn delete(args: DeleteArgs) -> anyhow::Result<()> {
    with_client(&args.server, |client| async move {
        let id = client.resolve(&args.job).await?;
        client
            .delete_job(id)
            .await
            .with_context(|| format!("deleting job {id}"))?;
        println!("job {id} deleted with its files");
        Ok(())
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_gc_report_says_what_went() {
        let report = GcReport {
            dry_run: true,
            keep_jobs: "30d".into(),
            jobs: vec![proto::GcJob {
                id: 4,
                name: "walk".into(),
                finished_ms: 0,
            }],
            scenes: vec!["ab".repeat(32)],
            events: 12,
            bytes: 3 << 20,
        };
        assert_eq!(
            gc_text(&report),
            "would remove 1 finished job(s) (kept: 30d), 1 unused scene(s) and 12 event(s): \
             3.0 MiB freed\n  job 4 `walk`\n  scene abababababab\n"
        );
    }
}

//! A job's life after submission: `tessera download`, `clone`, `rerender`, `priority`
//! and `delete`.
//! Each takes the job by id or by name.

use std::path::PathBuf;

use anyhow::Context;
use clap::Args;

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

//! Job controls, each one database transaction: submit, pause, resume, cancel, retry,
//! priority and delete. A command asks the job's control state machine
//! ([`state::control_transition`](crate::state::control_transition)) first; a refusal is a
//! 409 naming the job and why.

use rusqlite::{Connection, Transaction};

use crate::budget;
use crate::db::events::log;
use crate::db::tasks::{self, NewTask};
use crate::db::{failures, frames, jobs};
use crate::error::{Error, Result};
use crate::limits::MAX_FRAMES;
use crate::spec::{self, Plan};
use crate::state::{control_transition, ControlChange, JobCommand, TaskEvent, TaskState};

/// Stores a new job and its tasks; returns its id.
pub fn submit(conn: &mut Connection, plan: &Plan, now: i64) -> Result<u64> {
    let tx = conn.transaction()?;
    let spec = &plan.spec;
    let id = jobs::insert(&tx, spec, plan.pixel_samples(), now)?;
    for &f in &plan.frames {
        frames::insert(&tx, id, f, plan.tasks_per_frame())?;
    }
    for t in plan.tasks() {
        tasks::insert(
            &tx,
            &NewTask {
                kind: proto::TaskKind::Render,
                job: id,
                frame: t.frame,
                tile: t.tile,
                pass: t.pass,
                rect: t.rect,
                samples: t.samples,
                check_of: None,
                round: t.round,
            },
        )?;
    }
    // No worker has a speed on a new job: the plan says the first pass is queued.
    budget::replan(&tx, id, spec, now, now, u64::MAX)?;
    log(
        &tx,
        now,
        Some(id),
        "job_created",
        &format!("{} tasks", plan.task_count()),
    )?;
    tx.commit()?;
    Ok(id)
}

/// Asks the transition table about `command` on `job` and stores the new control; a
/// refusal is a conflict that names the job.
fn command(tx: &Transaction, job: u64, command: JobCommand) -> Result<ControlChange> {
    let from = jobs::control(tx, job)?;
    let change = control_transition(from, command, jobs::is_finished(tx, job)?)
        .map_err(|refused| Error::Conflict(format!("job {job} {refused}")))?;
    if let ControlChange::To(to) = change {
        jobs::set_control(tx, job, to)?;
    }
    Ok(change)
}

/// Pauses a job: nothing more is leased, and its live leases are taken back (their
/// workers hear 409 on their next heartbeat).
pub fn pause(conn: &mut Connection, job: u64, now: i64) -> Result<()> {
    let tx = conn.transaction()?;
    if command(&tx, job, JobCommand::Pause)? == ControlChange::Stays {
        return Ok(());
    }
    for task in tasks::of_job(&tx, job, &[TaskState::Leased])? {
        tasks::revoke(&tx, &task)?;
    }
    log(&tx, now, Some(job), "job_paused", "")?;
    tx.commit()?;
    Ok(())
}

/// Resumes a paused job.
pub fn resume(conn: &mut Connection, job: u64, now: i64) -> Result<()> {
    let tx = conn.transaction()?;
    if command(&tx, job, JobCommand::Resume)? == ControlChange::Stays {
        return Ok(());
    }
    log(&tx, now, Some(job), "job_resumed", "")?;
    tx.commit()?;
    Ok(())
}

/// Cancels a job: its queued and leased tasks are cancelled (workers hear 409).
pub fn cancel(conn: &mut Connection, job: u64, now: i64) -> Result<()> {
    let tx = conn.transaction()?;
    if command(&tx, job, JobCommand::Cancel)? == ControlChange::Stays {
        return Ok(());
    }
    let open = tasks::of_job(&tx, job, &[TaskState::Queued, TaskState::Leased])?;
    for task in &open {
        tasks::advance(&tx, task, TaskEvent::Cancel)?;
        tasks::clear_lease(&tx, task.id)?;
    }
    log(
        &tx,
        now,
        Some(job),
        "job_cancelled",
        &format!("{} tasks cancelled", open.len()),
    )?;
    jobs::update_finished(&tx, job, now)?;
    tx.commit()?;
    Ok(())
}

/// A fresh start once the cause is mended: re-queues a job's failed tasks, gives every
/// task its full attempts again and forgets the failed ones (the event log keeps them),
/// lifts its worker blocks (a job every live worker is blocked from is stuck), and lets
/// frames whose assembly failed be assembled again. Returns how many tasks, frames and
/// blocks.
pub fn retry(conn: &mut Connection, job: u64, now: i64) -> Result<usize> {
    let tx = conn.transaction()?;
    command(&tx, job, JobCommand::Retry)?;
    let failed = tasks::of_job(&tx, job, &[TaskState::Failed])?;
    let frames = frames::clear_failures(&tx, job)?;
    let blocks = jobs::unblock_all(&tx, job)?;
    if failed.is_empty() && frames == 0 && blocks == 0 {
        return Err(Error::Conflict(format!(
            "job {job} has no failed tasks or frames and no blocked workers"
        )));
    }
    for task in &failed {
        tasks::advance(&tx, task, TaskEvent::Retry)?;
    }
    // Blocks count failures: kept, they would block a worker again at its next one.
    tasks::reset_failures(&tx, job)?;
    failures::forget(&tx, job)?;
    log(
        &tx,
        now,
        Some(job),
        "job_retried",
        &format!(
            "{} tasks, {frames} frames, {blocks} worker blocks",
            failed.len()
        ),
    )?;
    jobs::update_finished(&tx, job, now)?;
    tx.commit()?;
    Ok(failed.len() + frames + blocks)
}

/// Renders `frames` of `job` again from scratch, as a worker would have the first time:
/// their check tasks go, their render tasks are queued again (same tiles, same samples,
/// so an unchanged tracer gives the same bits), and the frames count as not rendered. A
/// frame still rendering is refused, as is a time-budget job (its passes follow its
/// budget: clone it instead). Returns the tasks whose tiles and frame files the caller
/// removes after this commits.
pub fn rerender(conn: &mut Connection, job: u64, frames: &[i32], now: i64) -> Result<Vec<u64>> {
    let mut unique = frames.to_vec();
    unique.sort_unstable();
    unique.dedup();
    if frames.is_empty() || unique.len() != frames.len() || frames.len() as u64 > MAX_FRAMES {
        return Err(Error::Invalid {
            field: "frames".into(),
            message: format!(
                "must list 1 to {MAX_FRAMES} frames, each once; got {} ({} distinct)",
                frames.len(),
                unique.len()
            ),
        });
    }
    let tx = conn.transaction()?;
    command(&tx, job, JobCommand::Rerender)?;
    if jobs::load(&tx, job)?.budget.is_some() {
        return Err(Error::Conflict(format!(
            "job {job} has a time budget, which plans its frames' passes: clone it to render \
             frames again"
        )));
    }
    let mut rerendered = Vec::new();
    for &frame in frames {
        if !frames::exists(&tx, job, frame)? {
            return Err(Error::Invalid {
                field: "frames".into(),
                message: format!("job {job} has no frame {frame}"),
            });
        }
        let tasks = tasks::of_frame(&tx, job, frame)?;
        if tasks
            .iter()
            .any(|t| matches!(t.state, TaskState::Queued | TaskState::Leased))
            || frames::needs_assembly(&tx, job, frame)?
        {
            return Err(Error::Conflict(format!(
                "frame {frame} of job {job} is still rendering or denoising: rerender it once it \
                 is done"
            )));
        }
        let mut renders = 0;
        for task in &tasks {
            rerendered.push(task.id);
            // Checks and the denoise step come again with the frame's new tiles.
            if task.check_of.is_some() || task.kind == proto::TaskKind::Denoise {
                tasks::delete(&tx, task.id)?;
                continue;
            }
            tasks::advance(&tx, task, TaskEvent::Rerender)?;
            tasks::clear_for_rerender(&tx, task.id)?;
            renders += 1;
        }
        frames::reset(&tx, job, frame, renders)?;
    }
    // The video comes again once the frames are finished again.
    if let Some(encode) = tasks::encode_of_job(&tx, job)? {
        rerendered.push(encode.id);
        tasks::delete(&tx, encode.id)?;
    }
    let list: Vec<String> = frames.iter().map(i32::to_string).collect();
    log(
        &tx,
        now,
        Some(job),
        "frames_rerender",
        &format!("frames {}", list.join(", ")),
    )?;
    jobs::update_finished(&tx, job, now)?;
    tx.commit()?;
    Ok(rerendered)
}

/// Changes a job's priority (higher runs first); its next leases follow it.
pub fn set_priority(conn: &mut Connection, job: u64, priority: i32, now: i64) -> Result<()> {
    spec::check_priority(priority)?;
    let tx = conn.transaction()?;
    jobs::control(&tx, job)?;
    jobs::set_priority(&tx, job, priority)?;
    log(&tx, now, Some(job), "job_priority", &priority.to_string())?;
    tx.commit()?;
    Ok(())
}

/// Deletes a job's rows (its files are removed by the caller after this commits); `why`
/// goes to the event log.
pub fn delete(conn: &mut Connection, job: u64, now: i64, why: &str) -> Result<()> {
    let tx = conn.transaction()?;
    jobs::control(&tx, job)?;
    jobs::delete(&tx, job)?;
    log(&tx, now, Some(job), "job_deleted", why)?;
    tx.commit()?;
    Ok(())
}

//! Time budgets: "render frames 1-600 within 256 seconds on the workers I have". A budget
//! job starts as one pass of `min_spp` samples for every frame, so that every frame exists
//! early. Whenever one of its frames is assembled, [`replan`] measures the farm and adds a
//! sample pass to the frame with the highest estimated error, for as long as the work
//! queued and leased is predicted to end before the deadline. A worker that joins or leaves
//! changes the measured speed, so it changes the plan, never the deadline.
//!
//! A pass goes to a whole frame (every tile), so a frame's noise is even across it. It at
//! most doubles the frame's samples, so each pass buys about the same relative error, and
//! it takes at most the frame's share of the time left, so late passes stay small enough to
//! go round the frames.
//!
//! The steps after rendering come last: once no pass fits and every frame is assembled
//! with all of its passes, the job finishes (denoises every frame, then encodes its video,
//! where it asks for them) and takes no more passes. The plan keeps their time free before
//! the deadline, from what the steps take on the live workers that can take them
//! ([`workers::step_ms_per_mp`]).

use proto::{BudgetPlan, JobSpec};
use rusqlite::{Connection, Transaction};
use tracer::film::SampleRange;

use crate::config::Timing;
use crate::db::plans::{self, Open};
use crate::db::workers::{self, Step};
use crate::db::{frames, jobs, tasks};
use crate::error::Result;
use crate::state::{JobControl, TaskState};

/// A worker's speed is measured over its last this many tiles of the job.
const SPEED_WINDOW: u32 = 8;
/// Queued tasks kept per live worker, so that none waits for the next pass.
const QUEUE_PER_WORKER: u64 = 2;
/// The measured speeds are discounted by this much: a later frame may be slower, and the
/// last frame's assembly comes after its last tile.
const SPEED_MARGIN: f64 = 0.9;

/// The share of the budget kept for assembling the last frames (at least 0.25 s, at most
/// 30 s).
const RESERVE_FRACTION: f64 = 0.02;

/// The farm's speed on one job, in pixel samples per second.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct Speed {
    /// Summed over the measured workers.
    total: f64,
    /// The slowest measured worker's: the last task of a pass may fall to it.
    slowest: f64,
    /// Workers measured.
    measured: u32,
    /// Live workers that may work on the job (measured or not yet).
    live: u32,
}

/// Each live worker's speed (a worker is live if seen since `live_since`): the pixel
/// samples of its last [`SPEED_WINDOW`] tiles of the job over the time from lease to
/// upload (so preparing frames and uploads count).
fn measure(conn: &Connection, job: u64, live_since: i64) -> Result<Speed> {
    let live = workers::live_for_job(conn, job, live_since)?;
    let mut speed = Speed {
        slowest: f64::INFINITY,
        live: live.len() as u32,
        ..Speed::default()
    };
    for worker in live {
        if let Some((samples, ms)) = plans::recent_speed(conn, job, worker, SPEED_WINDOW)? {
            let rate = samples as f64 / (ms as f64 / 1000.0) * SPEED_MARGIN;
            speed.total += rate;
            speed.slowest = speed.slowest.min(rate);
            speed.measured += 1;
        }
    }
    if speed.measured == 0 {
        speed.slowest = 0.0;
    }
    Ok(speed)
}

/// Seconds until `open` is done at `speed`: the work shared among the workers, then the
/// largest task on the slowest of them.
fn seconds_to_finish(open: &Open, speed: &Speed) -> f64 {
    open.samples / speed.total + open.largest / speed.slowest
}

/// Seconds the steps after rendering have left at the end of `spec`'s job: every frame
/// not yet denoised, shared among the live workers that denoise (the last frame on the
/// slowest), then the video, unless made, on the slowest encoder. A step no live worker
/// can take counts nothing (the job waits for one, and says so in its status).
fn finishing_seconds(tx: &Transaction, job: u64, spec: &JobSpec, live_since: i64) -> Result<f64> {
    let frame_mp = f64::from(spec.width) * f64::from(spec.height) / 1e6;
    let frames = frames::counts(tx, job)?.0 as f64;
    let undenoised = frames::undenoised_count(tx, job)? as f64;
    let mut ms = 0.0;
    if spec.denoise && undenoised > 0.0 {
        let each = workers::step_ms_per_mp(tx, job, Step::Denoise, live_since)?;
        if !each.is_empty() {
            let shared = each.iter().map(|m| 1.0 / m).sum::<f64>();
            let slowest = each.iter().copied().fold(0.0, f64::max);
            ms += (undenoised - 1.0) * frame_mp / shared + frame_mp * slowest;
        }
    }
    let video_made = tasks::encode_of_job(tx, job)?.is_some_and(|t| t.state == TaskState::Done);
    if spec.video && !video_made {
        let each = workers::step_ms_per_mp(tx, job, Step::Encode, live_since)?;
        ms += frames * frame_mp * each.iter().copied().fold(0.0, f64::max);
    }
    Ok(ms / 1000.0 / SPEED_MARGIN)
}

/// Whether a time-budget job has started its steps after rendering (see the module
/// documentation): it has a denoise or an encode task.
fn finishing(tx: &Transaction, job: u64) -> Result<bool> {
    Ok(tasks::steps_count(tx, job)? > 0)
}

/// Plans a time-budget job again at `now` (see the module documentation): adds the passes
/// that fit and stores the plan for the job's status. Workers seen since `live_since` count
/// as live; the job holds at most `max_tasks` tasks. Does nothing for other jobs.
pub fn replan(
    tx: &Transaction,
    job: u64,
    spec: &JobSpec,
    now: i64,
    live_since: i64,
    max_tasks: u64,
) -> Result<()> {
    let Some(budget) = spec.time_budget else {
        return Ok(());
    };
    let control = jobs::control(tx, job)?;
    let created_ms = jobs::created_ms(tx, job)?;
    let deadline_ms = created_ms + (budget * 1000.0).round() as i64;
    // The last frames are assembled after their last tiles come in: plan to end a little
    // before the deadline.
    let finish_s = finishing_seconds(tx, job, spec, live_since)?;
    let plan_end_ms = deadline_ms
        - (budget * RESERVE_FRACTION * 1000.0).clamp(250.0, 30_000.0) as i64
        - (finish_s * 1000.0).round() as i64;
    let speed = measure(tx, job, live_since)?;
    let mut open = plans::open_work(tx, job)?;
    let first_spp = spec.min_spp.unwrap_or(1).max(1);
    let frame_pixels = spec.width as f64 * spec.height as f64;

    let stage = if control != JobControl::Active {
        format!("{}: no passes added", control.as_str())
    } else if finishing(tx, job)? {
        finish(tx, job, spec)?
    } else if open.first_pass_queued > 0 {
        format!("first pass: every frame at {first_spp} spp")
    } else if speed.measured == 0 {
        "waiting for a worker's speed".to_string()
    } else {
        let mut stage = String::from("refining: the noisiest frames get more samples");
        let mut tasks = plans::task_count(tx, job)?;
        while open.queued < QUEUE_PER_WORKER * u64::from(speed.live.max(1)) {
            let Some((frame, reached, pass)) = plans::noisiest_frame(tx, job, spec.spp)? else {
                stage = if open.samples > 0.0 {
                    "refining: every frame that can take more has a pass running".into()
                } else {
                    format!("done: every frame reached {} spp", spec.spp)
                };
                break;
            };
            let tiles = plans::tiles(tx, job, frame)?;
            if tasks + tiles.len() as u64 > max_tasks {
                stage = format!("stopped: the job holds {tasks} tasks, this server's limit");
                break;
            }
            let largest_tile = tiles.iter().map(|(_, r)| r.area()).max().unwrap_or(0) as f64;
            // The pass fits when the open work, the pass shared out, and the larger of the
            // last tasks on the slowest worker all end by the deadline.
            let left = (plan_end_ms - now) as f64 / 1000.0 - open.samples / speed.total;
            let fit_shared = (left - open.largest / speed.slowest) / (frame_pixels / speed.total);
            let fit_tail = left / (frame_pixels / speed.total + largest_tile / speed.slowest);
            let fit = fit_shared.min(fit_tail).floor().max(0.0) as u32;
            // A frame's fair share of the samples left, so that one frame's big pass late
            // in the budget does not leave the others behind.
            let share = (left * speed.total
                / frame_pixels
                / f64::from(plans::hungry_frames(tx, job, spec.spp)?))
            .floor()
            .max(f64::from(first_spp)) as u32;
            let k = reached.min(spec.spp - reached).min(fit).min(share);
            if k < first_spp.min(spec.spp - reached) {
                stage = format!(
                    "stopped: another pass on frame {frame} (at {reached} spp) would end \
                     after the deadline"
                );
                break;
            }
            let samples = SampleRange::new(reached, reached + k);
            plans::add_pass(tx, job, frame, pass, &tiles, samples, frame_pixels)?;
            open.samples += frame_pixels * f64::from(k);
            open.largest = open.largest.max(largest_tile * f64::from(k));
            open.queued += tiles.len() as u64;
            tasks += tiles.len() as u64;
        }
        // The farm slowed (a worker left): passes nobody started that would end after
        // the deadline go, newest first.
        let mut withdrawn = 0;
        while now as f64 + (seconds_to_finish(&open, &speed) + finish_s) * 1000.0
            > deadline_ms as f64
        {
            if !plans::withdraw_unstarted_pass(tx, job, frame_pixels)? {
                break;
            }
            withdrawn += 1;
            open = plans::open_work(tx, job)?;
        }
        if withdrawn > 0 {
            stage = format!("slowed down: {withdrawn} pass(es) nobody started were withdrawn");
        }
        // Nothing more fits, nothing is open and every frame has all of its passes: the
        // steps after rendering begin.
        let ended = stage.starts_with("stopped") || stage.starts_with("done");
        let idle = open.queued == 0 && open.samples == 0.0;
        if (spec.denoise || spec.video) && ended && idle && !frames::any_needs_assembly(tx, job)? {
            stage = finish(tx, job, spec)?;
        }
        stage
    };
    let passes_added = plans::passes_added(tx, job)?;
    let predicted_end_ms = (speed.measured > 0)
        .then(|| now + ((seconds_to_finish(&open, &speed) + finish_s) * 1000.0).round() as i64);
    let plan = BudgetPlan {
        budget_seconds: budget,
        deadline_ms,
        planned_ms: now,
        samples_per_second: speed.total,
        workers: speed.measured,
        predicted_end_ms,
        passes_added,
        stage,
    };
    jobs::set_budget_plan(tx, job, &plan)
}

/// The steps after rendering of a job whose passes are over: a denoise task for every
/// assembled frame that has none (a frame assembled later gets its own at the next
/// plan), then the encode task once every frame is finished; what it does, for the plan.
fn finish(tx: &Transaction, job: u64, spec: &JobSpec) -> Result<String> {
    for frame in frames::assembled(tx, job)? {
        crate::denoising::queue(tx, job, frame, spec)?;
    }
    crate::encoding::queue_if_complete(tx, job, spec)?;
    let steps: Vec<&str> = [
        (spec.denoise, "denoising every frame"),
        (spec.video, "the video"),
    ]
    .into_iter()
    .filter_map(|(on, what)| on.then_some(what))
    .collect();
    Ok(format!("finishing: {}", steps.join(", then ")))
}

/// [`replan`] with the scheduler's settings.
pub fn replan_with(tx: &Transaction, job: u64, now: i64, timing: Timing) -> Result<()> {
    replan(
        tx,
        job,
        &jobs::spec(tx, job)?,
        now,
        timing.live_since(now),
        timing.max_tasks_per_job,
    )
}

/// Plans every unfinished active time-budget job again (the sweeper does, every tick, so
/// that a worker joining or leaving between two frames changes the plan at once);
/// returns those jobs.
pub fn replan_running(conn: &mut Connection, now: i64, timing: Timing) -> Result<Vec<u64>> {
    let tx = conn.transaction()?;
    let running = jobs::running_budget_jobs(&tx)?;
    for &job in &running {
        replan_with(&tx, job, now, timing)?;
        jobs::update_finished(&tx, job, now)?;
    }
    tx.commit()?;
    Ok(running)
}

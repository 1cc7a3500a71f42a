//! Time budgets: passes planned inside the deadline, and the demand they add.

use super::*;

/// A time-budget job of `frames` frames of 16×16 in `tile`-pixel tiles, at most 64 spp.
fn budget_job(c: &mut Connection, frames: i32, tile: u32, seconds: f64, now: i64) -> u64 {
    let mut spec = JobSpec::new(scene().digest);
    (spec.width, spec.height, spec.tile_size, spec.spp) = (16, 16, Some(tile), 64);
    spec.frames = Some(FrameRange {
        start: 1,
        end: frames,
        step: 1,
    });
    spec.time_budget = Some(seconds);
    let plan = crate::spec::plan(spec, &scene(), 1_000).unwrap();
    submit(c, &plan, now).unwrap()
}

/// The samples every pixel of a frame has, from its tasks.
fn reached(c: &Connection, job: u64, frame: i32) -> u32 {
    c.query_row(
        "SELECT max(sample_end) FROM tasks WHERE job_id = ?1 AND frame = ?2",
        params![job, frame],
        |r| r.get(0),
    )
    .unwrap()
}

/// Leases one task to `w` at `*t` and finishes it `ms` per 256 pixel samples later; when
/// it completes its frame, the frame is assembled with the estimated error
/// `error(frame, spp)`. `None` when `w` gets nothing.
fn render_one(
    c: &mut Connection,
    w: u64,
    t: &mut i64,
    ms: i64,
    error: &impl Fn(i32, u32) -> f64,
) -> Option<Lease> {
    let l = lease(c, w, *t, TIMING).unwrap()?;
    let pixel_samples = i64::from(l.tile.width * l.tile.height * (l.samples.end - l.samples.start));
    *t += ms * pixel_samples / 256;
    if let Accepted::New {
        job,
        frame,
        frame_complete: true,
        ..
    } = accept(c, w, l.token, 1, 1, None, *t, TIMING).unwrap()
    {
        let spp = reached(c, job, frame);
        let summary = SamplingSummary {
            mean_samples: f64::from(spp),
            min_samples: spp,
            max_samples: spp,
            mean_noise: Some(error(frame, spp)),
        };
        mark_assembled(c, job, frame, *t, &summary, TIMING).unwrap();
    }
    Some(l)
}

/// Renders whatever is queued on `workers` in turn (see [`render_one`]), each frame's
/// error falling as `base(frame) / sqrt(spp)`, as a real frame's does, until no worker
/// gets a task.
fn render_budget(
    c: &mut Connection,
    workers: &[u64],
    t: &mut i64,
    ms: i64,
    base: impl Fn(i32) -> f64,
) {
    let error = |frame, spp: u32| base(frame) / f64::from(spp).sqrt();
    let mut idle = 0;
    for &w in workers.iter().cycle() {
        if render_one(c, w, t, ms, &error).is_some() {
            idle = 0;
        } else {
            idle += 1;
            if idle == workers.len() {
                return;
            }
        }
    }
}

/// A time budget: every frame at the first pass's 4 spp first, then passes to the
/// noisiest frames, each at most doubling it, until the next would end after the
/// deadline; the job finishes inside the budget with every frame assembled.
#[test]
fn a_time_budget_renders_every_frame_then_refines_the_noisiest_inside_the_deadline() {
    let mut c = db();
    let j = budget_job(&mut c, 3, 8, 10.0, 0);
    let plan = job_status(&c, j, 0, TIMING.live_since(0))
        .unwrap()
        .budget
        .unwrap();
    assert_eq!((plan.deadline_ms, plan.passes_added), (10_000, 0));
    assert_eq!(plan.predicted_end_ms, None);
    assert!(plan.stage.starts_with("first pass"), "{}", plan.stage);
    let w = worker(&mut c, "w", 0);
    // The first pass: 12 tiles of 8×8 at 4 spp, frame by frame; nothing else is planned
    // while any of it is queued. Frame 2 is the noisiest.
    let mut t = 0;
    let error = |frame, _| if frame == 2 { 0.3 } else { 0.1 };
    for _ in 0..12 {
        let l = render_one(&mut c, w, &mut t, 100, &error).unwrap();
        assert_eq!(l.samples, SampleSpan { start: 0, end: 4 });
    }
    let status = job_status(&c, j, t, TIMING.live_since(t)).unwrap();
    assert_eq!((status.frames_done, status.finished_ms), (3, None));
    assert_eq!(status.state, JobState::Running);
    // Then a pass that doubles frame 2: 256 pixel samples per 0.1 s, less 10 %.
    let plan = status.budget.unwrap();
    assert_eq!((plan.passes_added, plan.workers), (1, 1));
    assert!((plan.samples_per_second - 2_304.0).abs() < 1e-6);
    assert!(plan.stage.starts_with("refining"), "{}", plan.stage);
    let l = lease(&mut c, w, t, TIMING).unwrap().unwrap();
    assert_eq!((l.frame, l.samples), (2, SampleSpan { start: 4, end: 8 }));
    assert!(!is_assembled(&c, j, 2).unwrap());
    // Open work (4 tiles at 4 spp) on the one worker, then its last tile again.
    let expect = t + ((1024.0 + 256.0) / 2_304.0 * 1000.0_f64).round() as i64;
    assert_eq!(plan.predicted_end_ms, Some(expect));
    revoke_all_leases(&mut c, t).unwrap();

    // Frame 2 stays the noisiest until it is twice the others' samples... and so on,
    // until the deadline.
    render_budget(
        &mut c,
        &[w],
        &mut t,
        100,
        |f| if f == 2 { 0.6 } else { 0.2 },
    );
    let status = job_status(&c, j, t, TIMING.live_since(t)).unwrap();
    let finished = status.finished_ms.expect("the job finished");
    assert!(finished <= 10_000, "finished at {finished} ms");
    assert_eq!((status.state, status.frames_done), (JobState::Done, 3));
    let spp: Vec<u32> = (1..=3).map(|f| reached(&c, j, f)).collect();
    assert!(spp[1] > spp[0] && spp[0] > 4, "{spp:?}");
    assert!(spp.iter().all(|&s| s <= 64), "{spp:?}");
    // 9.3 s of work at 2304 samples/s is 83 spp over 3 frames of 256 pixels.
    let total: u32 = spp.iter().sum();
    assert!(total >= 60, "{spp:?}");
    let plan = status.budget.unwrap();
    assert!(plan.stage.starts_with("stopped"), "{}", plan.stage);
    assert!(plan.passes_added >= 4, "{plan:?}");
    assert_eq!(status.progress, 1.0);
}

/// A budget job's passes are leased in the order they were planned: the noisiest
/// frame's pass first, whatever its frame number, and a late frame's pass is never
/// starved by passes planned after it for earlier frames.
#[test]
fn a_time_budgets_passes_are_leased_in_plan_order() {
    let mut c = db();
    budget_job(&mut c, 3, 16, 60.0, 0);
    let w = worker(&mut c, "w", 0);
    let mut t = 0;
    let error = |frame, _| [0.2, 0.1, 0.3][frame as usize - 1];
    for _ in 0..3 {
        render_one(&mut c, w, &mut t, 100, &error).unwrap();
    }
    // One tile a frame, two queued tasks for the one worker: frames 3 and 1, in that order.
    let frames: Vec<i32> = (0..2)
        .map(|_| lease(&mut c, w, t, TIMING).unwrap().unwrap().frame)
        .collect();
    assert_eq!(frames, [3, 1]);
}

/// A time budget that denoises and makes a video: no step before the passes are over,
/// then every frame denoised and the video, on a worker that timed both when it started;
/// the passes end early enough to leave the steps' time free before the deadline.
#[test]
fn a_time_budget_keeps_time_for_denoising_and_the_video_after_its_last_pass() {
    // Rendering, the same farm and budget with the steps and without them.
    let run = |steps: bool| {
        let mut c = db();
        let mut spec = JobSpec::new(scene().digest);
        (spec.width, spec.height, spec.tile_size, spec.spp) = (16, 16, Some(8), 64);
        spec.frames = Some(FrameRange {
            start: 1,
            end: 3,
            step: 1,
        });
        (spec.time_budget, spec.denoise, spec.video) = (Some(10.0), steps, steps);
        let plan = crate::spec::plan(spec, &scene(), 1_000).unwrap();
        let j = submit(&mut c, &plan, 0).unwrap();
        // Its denoiser took 4e6 ms per megapixel, 1.024 s a 16x16 frame; its encoder 1e6.
        let mut joining = joining("both", None);
        joining.profile.denoiser = Some("Open Image Denoise 2.5.1");
        joining.profile.encoder = Some("FFmpeg with libx264");
        joining.profile.step_ms_per_mp = [Some(4_000_000), Some(1_000_000)];
        let w = join(&mut c, &joining, 0, TIMING.live_since(0)).unwrap().id;
        let mut t = 0;
        let (mut first_step, mut steps_before) = (None, 0);
        let error = |frame: i32, spp: u32| 0.1 * f64::from(frame) / f64::from(spp).sqrt();
        while let Some(l) = render_one(&mut c, w, &mut t, 100, &error) {
            if l.kind == proto::TaskKind::Render {
                steps_before += usize::from(first_step.is_some());
            } else {
                first_step.get_or_insert(t);
            }
        }
        let status = job_status(&c, j, t, TIMING.live_since(t)).unwrap();
        let spp: u32 = (1..=3).map(|f| reached(&c, j, f)).sum();
        (c, j, status, spp, first_step, steps_before)
    };
    let (_, _, plain, plain_spp, none, _) = run(false);
    assert_eq!((plain.state, none), (JobState::Done, None));
    let (c, j, status, spp, first_step, renders_after) = run(true);
    assert_eq!((status.state, status.frames_done), (JobState::Done, 3));
    assert!(status.video, "{status:?}");
    let steps: Vec<(String, String)> = c
        .prepare("SELECT kind, state FROM tasks WHERE job_id = ?1 AND kind != 'render'")
        .unwrap()
        .query_map([j], |r| Ok((r.get(0)?, r.get(1)?)))
        .unwrap()
        .collect::<rusqlite::Result<_>>()
        .unwrap();
    let done = |kind: &str| {
        steps
            .iter()
            .filter(|s| s.0 == kind && s.1 == "done")
            .count()
    };
    assert_eq!(
        (done("denoise"), done("encode"), steps.len()),
        (3, 1, 4),
        "{steps:?}"
    );
    // The steps came after every pass; the passes left them (3 denoised frames, one
    // after another on the one worker, and 3 frames encoded: 4.3 s with the plan's 10 %
    // margin) and the assembly reserve (0.25 s) before the 10 s deadline.
    let first_step = first_step.expect("the steps ran");
    assert_eq!(renders_after, 0, "a pass after the steps began");
    let reserve = ((3.0 * 1.024 + 3.0 * 0.256) / 0.9 * 1000.0) as i64;
    assert!(
        first_step <= 10_000 - 250 - reserve,
        "steps began at {first_step} ms"
    );
    assert!(
        spp < plain_spp,
        "{spp} spp with the steps, {plain_spp} without"
    );
    let plan = status.budget.unwrap();
    assert!(
        plan.stage
            .starts_with("finishing: denoising every frame, then the video"),
        "{}",
        plan.stage
    );
    println!("{spp} spp with the steps, {plain_spp} without; steps began at {first_step} ms");
}

/// Every frame that reached the job's spp leaves nothing to refine: the job ends early.
#[test]
fn a_time_budget_ends_early_when_every_frame_reaches_spp() {
    let mut c = db();
    let j = budget_job(&mut c, 2, 8, 3_600.0, 0);
    let w = worker(&mut c, "w", 0);
    let mut t = 0;
    render_budget(&mut c, &[w], &mut t, 10, |_| 1.0);
    let status = job_status(&c, j, t, TIMING.live_since(t)).unwrap();
    assert_eq!(status.state, JobState::Done);
    assert_eq!((reached(&c, j, 1), reached(&c, j, 2)), (64, 64));
    // 4, 4, 8, 16, 32: each pass doubles a frame.
    let passes: i64 = c
        .query_row(
            "SELECT count(DISTINCT pass) FROM tasks WHERE job_id = ?1 AND frame = 1",
            [j],
            |r| r.get(0),
        )
        .unwrap();
    assert_eq!(passes, 5);
    let plan = status.budget.unwrap();
    assert!(plan.stage.starts_with("done"), "{}", plan.stage);
}

/// Workers that join or leave change the measured speed, so the plan; the deadline stays.
#[test]
fn a_worker_joining_or_leaving_changes_the_plan_not_the_deadline() {
    let mut c = db();
    let j = budget_job(&mut c, 4, 8, 60.0, 0);
    let a = worker(&mut c, "a", 0);
    let mut t = 0;
    // Worker a renders the first pass alone.
    let error = |frame, _| 0.1 * f64::from(frame);
    while job_status(&c, j, t, TIMING.live_since(t))
        .unwrap()
        .budget
        .unwrap()
        .passes_added
        == 0
    {
        render_one(&mut c, a, &mut t, 100, &error).unwrap();
    }
    let alone = job_status(&c, j, t, TIMING.live_since(t))
        .unwrap()
        .budget
        .unwrap();
    assert_eq!(alone.workers, 1);
    // Worker b joins and renders a tile as fast: the farm is measured twice as fast.
    let b = worker(&mut c, "b", t);
    let l = lease(&mut c, b, t, TIMING).unwrap().unwrap();
    accept(&mut c, b, l.token, 1, 1, None, t + 100, TIMING).unwrap();
    t += 100;
    assert_eq!(replan_running(&mut c, t, TIMING).unwrap(), vec![j]);
    let both = job_status(&c, j, t, TIMING.live_since(t))
        .unwrap()
        .budget
        .unwrap();
    assert_eq!(both.workers, 2);
    let ratio = both.samples_per_second / alone.samples_per_second;
    assert!((ratio - 2.0).abs() < 1e-9, "{both:?} {alone:?}");
    // It leaves: the plan is back to one worker's speed.
    leave(&mut c, b, t).unwrap();
    replan_running(&mut c, t, TIMING).unwrap();
    let after = job_status(&c, j, t, TIMING.live_since(t))
        .unwrap()
        .budget
        .unwrap();
    assert_eq!(after.workers, 1);
    assert_eq!(after.samples_per_second, alone.samples_per_second);
    assert!(
        after.predicted_end_ms > both.predicted_end_ms,
        "{after:?} {both:?}"
    );
    assert_eq!(
        (after.deadline_ms, both.deadline_ms),
        (alone.deadline_ms, alone.deadline_ms)
    );
    // Close to the deadline, the passes nobody started no longer fit: they are withdrawn.
    // The pass b started stays (its frame is refined whole or not at all).
    let queued = |c: &Connection, started: bool| -> i64 {
        c.query_row(
            "SELECT count(*) FROM tasks t WHERE job_id = ?1 AND state = 'queued'
               AND ?2 = EXISTS (SELECT 1 FROM tasks s WHERE s.job_id = t.job_id
                                  AND s.frame = t.frame AND s.pass = t.pass
                                  AND (s.state != 'queued' OR s.attempt > 0))",
            params![j, started],
            |r| r.get(0),
        )
        .unwrap()
    };
    let started = queued(&c, true);
    assert!(queued(&c, false) > 0);
    t = after.deadline_ms - 100;
    heartbeat(&mut c, a, None, &[], t, TIMING).unwrap();
    replan_running(&mut c, t, TIMING).unwrap();
    assert_eq!((queued(&c, false), queued(&c, true)), (0, started));
    let status = job_status(&c, j, t, TIMING.live_since(t)).unwrap();
    let plan = status.budget.unwrap();
    assert!(plan.stage.starts_with("slowed down"), "{plan:?}");
    let open = status.tasks.queued + status.tasks.leased;
    assert_eq!(status.tasks.done + open, status.tasks.total());
}

/// The demand an autoscaler reads: a paused job's queued tasks want no worker; a time
/// budget job wants a worker for every tile of each frame it could refine now, not only
/// for the two tasks per worker it keeps queued.
#[test]
fn the_demand_counts_active_jobs_and_what_a_time_budget_could_run() {
    let mut c = db();
    let demand = |c: &Connection, now| {
        crate::metrics::snapshot(c, now, TIMING.live_since(now))
            .unwrap()
            .demand
    };
    let plain = job(&mut c, 1, 0, 3, 0);
    assert_eq!(demand(&c, 0), 4);
    pause(&mut c, plain, 0).unwrap();
    assert_eq!(demand(&c, 0), 0);

    let j = budget_job(&mut c, 3, 8, 60.0, 0);
    assert_eq!(demand(&c, 0), 12, "the first pass: 3 frames of 4 tiles");
    let w = worker(&mut c, "w", 0);
    let mut t = 0;
    let error = |frame, _| if frame == 2 { 0.3 } else { 0.1 };
    for _ in 0..12 {
        render_one(&mut c, w, &mut t, 100, &error).unwrap();
    }
    // One worker: one pass of frame 2 is queued (4 tasks); frames 1 and 3 could each run
    // a pass of 4 tiles too, had they workers.
    let queued: u64 = c
        .query_row(
            "SELECT count(*) FROM tasks WHERE job_id = ?1 AND state = 'queued'",
            [j],
            |r| r.get(0),
        )
        .unwrap();
    assert_eq!(queued, 4);
    assert_eq!(demand(&c, t), 12);
    // Past its deadline a budget job plans nothing more: only its queue counts.
    assert_eq!(demand(&c, 60_000), 4);
    resume(&mut c, plain, t).unwrap();
    assert_eq!(demand(&c, 60_000), 8);
}

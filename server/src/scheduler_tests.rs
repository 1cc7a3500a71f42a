//! Scheduler tests against an in-memory database, with explicit times.

use proto::{FrameRange, JobSpec, JobState, SceneInfo, TaskToken};
use rusqlite::Connection;

use super::*;
use crate::identity::{join, worker_of_credential, Joining};
use crate::status::job_status;

const LEASE_MS: i64 = 10_000;
const TIMING: Timing = Timing {
    lease_ms: LEASE_MS,
    block_after_failures: 2,
    verify_fraction: 0.0,
    max_tasks_per_job: 1_000_000,
};

fn scene() -> SceneInfo {
    SceneInfo {
        digest: "a".repeat(64),
        size: 1,
        triangles: 1,
        meshes: 1,
        instances: 1,
        materials: 1,
        ..Default::default()
    }
}

fn db() -> Connection {
    let mut c = Connection::open_in_memory().unwrap();
    crate::migrations::migrate(&mut c).unwrap();
    c.execute(
        "INSERT INTO scenes (digest, size, info, created_ms) VALUES (?1, 1, '{}', 0)",
        [scene().digest],
    )
    .unwrap();
    c
}

/// A job of `frames` frames of 16×16 in 8×8 tiles (4 tasks a frame).
fn job(c: &mut Connection, frames: i32, priority: i32, max_attempts: u32, now: i64) -> u64 {
    let mut spec = JobSpec::new(scene().digest);
    spec.width = 16;
    spec.height = 16;
    spec.tile_size = Some(8);
    spec.spp = 4;
    spec.frames = Some(FrameRange {
        start: 1,
        end: frames,
        step: 1,
    });
    spec.priority = priority;
    spec.max_attempts = max_attempts;
    spec.shutter = [-0.25, 0.25];
    let plan = crate::spec::plan(spec, &scene(), 1_000).unwrap();
    create_job(c, &plan, now).unwrap()
}

fn worker(c: &mut Connection, name: &str, now: i64) -> u64 {
    let joining = Joining {
        name,
        threads: 4,
        version: "test",
        credential: None,
        platform: None,
    };
    join(c, &joining, now, now - 2 * LEASE_MS).unwrap().id
}

/// The task a leased check repeats (`None` for a render task).
fn check_of(c: &Connection, lease: &Lease) -> Option<u64> {
    load_task(c, lease.token.task_id).unwrap().unwrap().check_of
}

fn state_of(c: &Connection, task: u64) -> TaskState {
    load_task(c, task).unwrap().unwrap().state
}

#[test]
fn lease_takes_priority_then_age_then_frame_order() {
    let mut c = db();
    let old_low = job(&mut c, 1, 0, 3, 100);
    let new_high = job(&mut c, 1, 5, 3, 200);
    let new_low = job(&mut c, 1, 0, 3, 300);
    let w = worker(&mut c, "w", 0);
    let jobs: Vec<u64> = (0..12)
        .map(|_| lease(&mut c, w, 1_000, TIMING).unwrap().unwrap().job_id)
        .collect();
    assert_eq!(&jobs[..4], &[new_high; 4]);
    assert_eq!(&jobs[4..8], &[old_low; 4]);
    assert_eq!(&jobs[8..], &[new_low; 4]);
    assert_eq!(lease(&mut c, w, 1_000, TIMING).unwrap(), None);
}

#[test]
fn lease_carries_what_the_tracer_needs() {
    let mut c = db();
    let j = job(&mut c, 2, 0, 3, 0);
    let w = worker(&mut c, "w", 0);
    let l = lease(&mut c, w, 5_000, TIMING).unwrap().unwrap();
    assert_eq!(l.job_id, j);
    assert_eq!(l.token.attempt, 1);
    assert_eq!((l.frame, l.width, l.height), (1, 16, 16));
    assert_eq!(
        l.tile,
        Rect {
            x: 0,
            y: 0,
            width: 8,
            height: 8
        }
    );
    assert_eq!(l.samples, SampleSpan { start: 0, end: 4 });
    assert_eq!(l.shutter, [-0.25, 0.25]);
    assert_eq!(l.scene, scene().digest);
    assert_eq!(l.deadline_ms, 5_000 + LEASE_MS);
    assert_eq!(state_of(&c, l.token.task_id), TaskState::Leased);
}

#[test]
fn heartbeat_extends_the_lease_and_a_stale_token_is_refused() {
    let mut c = db();
    job(&mut c, 1, 0, 3, 0);
    let w = worker(&mut c, "w", 0);
    let l = lease(&mut c, w, 0, TIMING).unwrap().unwrap();
    assert_eq!(
        heartbeat(&mut c, w, Some(l.token), 4_000, TIMING).unwrap(),
        Some(4_000 + LEASE_MS)
    );
    // Not expired at the first deadline, thanks to the heartbeat.
    assert!(expire(&mut c, LEASE_MS + 1, TIMING).unwrap().is_empty());
    let stale = TaskToken {
        attempt: l.token.attempt + 1,
        ..l.token
    };
    assert!(matches!(
        heartbeat(&mut c, w, Some(stale), 5_000, TIMING),
        Err(Error::LeaseGone(_))
    ));
    // Another worker's heartbeat for this lease is refused too.
    let other = worker(&mut c, "other", 0);
    assert!(matches!(
        heartbeat(&mut c, other, Some(l.token), 5_000, TIMING),
        Err(Error::LeaseGone(_))
    ));
}

#[test]
fn expired_lease_requeues_and_the_next_lease_fences_the_old_one() {
    let mut c = db();
    let j = job(&mut c, 1, 0, 3, 0);
    let (a, b) = (worker(&mut c, "a", 0), worker(&mut c, "b", 0));
    let first = lease(&mut c, a, 0, TIMING).unwrap().unwrap();
    assert_eq!(expire(&mut c, LEASE_MS + 1, TIMING).unwrap(), vec![j]);
    let task = load_task(&c, first.token.task_id).unwrap().unwrap();
    assert_eq!(
        (task.state, task.failures, task.worker_id),
        (TaskState::Queued, 1, None)
    );
    // Worker b gets it (a failed it), at attempt 2.
    let again = lease(&mut c, b, LEASE_MS + 2, TIMING).unwrap().unwrap();
    assert_eq!(
        again.token,
        TaskToken {
            task_id: first.token.task_id,
            attempt: 2
        }
    );
    // The presumed-dead worker's heartbeat and upload are refused and change nothing.
    assert!(matches!(
        heartbeat(&mut c, a, Some(first.token), LEASE_MS + 3, TIMING),
        Err(Error::LeaseGone(_))
    ));
    assert!(matches!(
        accept(&mut c, a, first.token, 1, 1, None, LEASE_MS + 3, TIMING),
        Err(Error::LeaseGone(_))
    ));
    assert_eq!(state_of(&c, first.token.task_id), TaskState::Leased);
}

#[test]
fn failures_requeue_until_max_attempts_then_fail_the_job_while_others_finish() {
    let mut c = db();
    let j = job(&mut c, 2, 0, 2, 0);
    let ws: Vec<u64> = (0..3)
        .map(|i| worker(&mut c, &format!("w{i}"), 0))
        .collect();
    let l = lease(&mut c, ws[0], 0, TIMING).unwrap().unwrap();
    let (_, ack) = fail(&mut c, ws[0], l.token, "out of memory", 1, TIMING).unwrap();
    assert_eq!(
        ack,
        FailureAck {
            requeued: true,
            task_failed: false,
            blocked_from_job: false
        }
    );
    let l2 = lease(&mut c, ws[1], 2, TIMING).unwrap().unwrap();
    assert_eq!(l2.token.task_id, l.token.task_id);
    let (_, ack) = fail(&mut c, ws[1], l2.token, "out of memory", 3, TIMING).unwrap();
    assert!(ack.task_failed && !ack.requeued);
    assert_eq!(state_of(&c, l.token.task_id), TaskState::Failed);
    let status = job_status(&c, j, 4).unwrap();
    assert_eq!(status.state, JobState::Failed);
    assert_eq!(
        (
            status.tasks.failed,
            status.tasks.queued,
            status.frames_failed
        ),
        (1, 7, 1)
    );
    // The other tasks still lease and finish.
    let mut done = 0;
    while let Some(l) = lease(&mut c, ws[2], 10, TIMING).unwrap() {
        assert!(matches!(
            accept(&mut c, ws[2], l.token, 1, 1, None, 11, TIMING).unwrap(),
            Accepted::New { .. }
        ));
        done += 1;
    }
    assert_eq!(done, 7);
    let status = job_status(&c, j, 12).unwrap();
    assert_eq!((status.state, status.tasks.done), (JobState::Failed, 7));
    // Frame 2 is complete but not yet written: the job is not finished until it is.
    assert_eq!(status.finished_ms, None);
    let reached = SamplingSummary {
        mean_samples: 4.0,
        min_samples: 4,
        max_samples: 4,
        mean_noise: Some(0.05),
    };
    mark_assembled(&mut c, j, 2, 13, &reached, TIMING).unwrap();
    let status = job_status(&c, j, 14).unwrap();
    assert_eq!(
        (status.state, status.frames_done, status.finished_ms),
        (JobState::Failed, 1, Some(13))
    );
}

#[test]
fn a_failed_task_goes_to_another_worker_while_one_can_take_it() {
    let mut c = db();
    job(&mut c, 1, 0, 5, 0);
    let (a, b) = (worker(&mut c, "a", 0), worker(&mut c, "b", 0));
    let l = lease(&mut c, a, 0, TIMING).unwrap().unwrap();
    fail(&mut c, a, l.token, "crash", 1, TIMING).unwrap();
    // a gets the other three tasks, never the one it failed, while b is live.
    let mut got = vec![];
    while let Some(next) = lease(&mut c, a, 2, TIMING).unwrap() {
        got.push(next.token.task_id);
    }
    assert_eq!(got.len(), 3);
    assert!(!got.contains(&l.token.task_id));
    // b takes it.
    assert_eq!(
        lease(&mut c, b, 3, TIMING).unwrap().unwrap().token.task_id,
        l.token.task_id
    );
}

#[test]
fn a_failed_task_goes_back_to_the_same_worker_when_no_other_is_live() {
    let mut c = db();
    job(&mut c, 1, 0, 5, 0);
    let a = worker(&mut c, "a", 0);
    // b registered long ago and has not been seen for more than two lease periods.
    let _b = worker(&mut c, "b", -3 * LEASE_MS);
    let l = lease(&mut c, a, 0, TIMING).unwrap().unwrap();
    fail(&mut c, a, l.token, "crash", 1, TIMING).unwrap();
    let ids: Vec<u64> = std::iter::from_fn(|| lease(&mut c, a, 2, TIMING).unwrap())
        .map(|l| l.token.task_id)
        .collect();
    assert_eq!(ids.len(), 4);
    // The failed task comes last, after the ones it has not failed.
    assert_eq!(*ids.last().unwrap(), l.token.task_id);
}

#[test]
fn a_worker_that_fails_n_tasks_of_a_job_is_blocked_from_it() {
    let mut c = db();
    let j = job(&mut c, 1, 0, 5, 0);
    let other = job(&mut c, 1, -1, 5, 1);
    let (a, _b) = (worker(&mut c, "a", 0), worker(&mut c, "b", 0));
    let l = lease(&mut c, a, 0, TIMING).unwrap().unwrap();
    assert!(
        !fail(&mut c, a, l.token, "x", 1, TIMING)
            .unwrap()
            .1
            .blocked_from_job
    );
    let l = lease(&mut c, a, 2, TIMING).unwrap().unwrap();
    assert_eq!(l.job_id, j);
    assert!(
        fail(&mut c, a, l.token, "x", 3, TIMING)
            .unwrap()
            .1
            .blocked_from_job
    );
    // Blocked from j: a gets only the lower-priority job now.
    let next = lease(&mut c, a, 4, TIMING).unwrap().unwrap();
    assert_eq!(next.job_id, other);
    // Retry lifts the block.
    accept(&mut c, a, next.token, 1, 1, None, 5, TIMING).unwrap();
    for _ in 0..3 {
        let l = lease(&mut c, a, 6, TIMING).unwrap().unwrap();
        assert_eq!(l.job_id, other);
        accept(&mut c, a, l.token, 1, 1, None, 6, TIMING).unwrap();
    }
    assert_eq!(lease(&mut c, a, 7, TIMING).unwrap(), None);
}

#[test]
fn pause_takes_leases_back_and_the_heartbeat_says_so() {
    let mut c = db();
    let j = job(&mut c, 1, 0, 3, 0);
    let w = worker(&mut c, "w", 0);
    let l = lease(&mut c, w, 0, TIMING).unwrap().unwrap();
    pause(&mut c, j, 1).unwrap();
    assert_eq!(state_of(&c, l.token.task_id), TaskState::Queued);
    match heartbeat(&mut c, w, Some(l.token), 2, TIMING) {
        Err(Error::LeaseGone(why)) => assert!(why.contains("paused"), "{why}"),
        other => panic!("{other:?}"),
    }
    assert_eq!(lease(&mut c, w, 3, TIMING).unwrap(), None);
    assert_eq!(job_status(&c, j, 3).unwrap().state, JobState::Paused);
    // A revoke is not the worker's fault: no failure counted.
    assert_eq!(load_task(&c, l.token.task_id).unwrap().unwrap().failures, 0);
    resume(&mut c, j, 4).unwrap();
    let again = lease(&mut c, w, 5, TIMING).unwrap().unwrap();
    assert_eq!(
        again.token,
        TaskToken {
            task_id: l.token.task_id,
            attempt: 2
        }
    );
}

#[test]
fn cancel_stops_open_tasks_and_cannot_be_undone() {
    let mut c = db();
    let j = job(&mut c, 1, 0, 3, 0);
    let w = worker(&mut c, "w", 0);
    let l = lease(&mut c, w, 0, TIMING).unwrap().unwrap();
    accept(&mut c, w, l.token, 1, 1, None, 1, TIMING).unwrap();
    let l = lease(&mut c, w, 2, TIMING).unwrap().unwrap();
    cancel(&mut c, j, 3).unwrap();
    match heartbeat(&mut c, w, Some(l.token), 4, TIMING) {
        Err(Error::LeaseGone(why)) => assert!(why.contains("cancelled"), "{why}"),
        other => panic!("{other:?}"),
    }
    let s = job_status(&c, j, 5).unwrap();
    assert_eq!(
        (s.state, s.tasks.done, s.tasks.cancelled),
        (JobState::Cancelled, 1, 3)
    );
    assert!(matches!(resume(&mut c, j, 6), Err(Error::Conflict(_))));
    assert!(matches!(retry(&mut c, j, 6), Err(Error::Conflict(_))));
    assert_eq!(lease(&mut c, w, 7, TIMING).unwrap(), None);
}

#[test]
fn retry_requeues_failed_tasks_with_fresh_attempts() {
    let mut c = db();
    let j = job(&mut c, 1, 0, 1, 0);
    let w = worker(&mut c, "w", 0);
    let l = lease(&mut c, w, 0, TIMING).unwrap().unwrap();
    assert!(
        fail(&mut c, w, l.token, "x", 1, TIMING)
            .unwrap()
            .1
            .task_failed
    );
    assert!(matches!(retry(&mut c, j + 1, 2), Err(Error::NotFound(_))));
    assert_eq!(retry(&mut c, j, 2).unwrap(), 1);
    let t = load_task(&c, l.token.task_id).unwrap().unwrap();
    assert_eq!((t.state, t.failures), (TaskState::Queued, 0));
    assert!(matches!(retry(&mut c, j, 3), Err(Error::Conflict(_))));
}

#[test]
fn a_second_upload_is_accepted_once_and_ignored_after() {
    let mut c = db();
    job(&mut c, 1, 0, 3, 0);
    let w = worker(&mut c, "w", 0);
    let l = lease(&mut c, w, 0, TIMING).unwrap().unwrap();
    assert!(matches!(
        accept(&mut c, w, l.token, 10, 1, None, 1, TIMING).unwrap(),
        Accepted::New {
            frame_complete: false,
            ..
        }
    ));
    assert_eq!(
        accept(&mut c, w, l.token, 10, 1, None, 2, TIMING).unwrap(),
        Accepted::Duplicate
    );
    let done: i64 = c
        .query_row("SELECT tasks_done FROM frames", [], |r| r.get(0))
        .unwrap();
    assert_eq!(done, 1);
}

#[test]
fn the_last_tile_of_a_frame_and_of_a_pass_are_reported() {
    let mut c = db();
    let mut spec = JobSpec::new(scene().digest);
    (
        spec.width,
        spec.height,
        spec.tile_size,
        spec.spp,
        spec.sample_passes,
    ) = (16, 8, Some(8), 4, 2);
    spec.frames = Some(FrameRange {
        start: 0,
        end: 0,
        step: 1,
    });
    let plan = crate::spec::plan(spec, &scene(), 100).unwrap();
    create_job(&mut c, &plan, 0).unwrap();
    let w = worker(&mut c, "w", 0);
    let results: Vec<Accepted> = std::iter::from_fn(|| lease(&mut c, w, 1, TIMING).unwrap())
        .collect::<Vec<_>>()
        .into_iter()
        .map(|l| accept(&mut c, w, l.token, 1, 1, None, 2, TIMING).unwrap())
        .collect();
    let flags: Vec<(u32, bool, bool)> = results
        .iter()
        .map(|a| match a {
            Accepted::New {
                pass,
                frame_complete,
                pass_complete,
                ..
            } => (*pass, *pass_complete, *frame_complete),
            Accepted::Duplicate => panic!(),
        })
        .collect();
    // Pass 0's two tiles, then pass 1's.
    assert_eq!(
        flags,
        vec![
            (0, false, false),
            (0, true, false),
            (1, false, false),
            (1, true, true)
        ]
    );
}

#[test]
fn restart_revokes_live_leases_without_counting_a_failure() {
    let mut c = db();
    job(&mut c, 1, 0, 1, 0);
    let w = worker(&mut c, "w", 0);
    let l = lease(&mut c, w, 0, TIMING).unwrap().unwrap();
    assert_eq!(revoke_all_leases(&mut c, 1).unwrap(), 1);
    let t = load_task(&c, l.token.task_id).unwrap().unwrap();
    assert_eq!((t.state, t.failures, t.attempt), (TaskState::Queued, 0, 1));
    assert_eq!(revoke_all_leases(&mut c, 2).unwrap(), 0);
}

#[test]
fn unknown_worker_must_register() {
    let mut c = db();
    job(&mut c, 1, 0, 1, 0);
    assert!(matches!(
        lease(&mut c, 99, 0, TIMING),
        Err(Error::NotFound(_))
    ));
}

/// Verification at the scheduler: a sampled task gets a check for another worker; a
/// disagreement asks a third worker; the verdict quarantines the wrong one, whose leases
/// and unchecked tiles go back to checks; an operator clears it.
#[test]
fn checks_go_to_other_workers_and_the_verdict_quarantines_the_wrong_one() {
    let timing = Timing {
        verify_fraction: 1.0,
        ..TIMING
    };
    let mut c = db();
    let j = job(&mut c, 1, 0, 3, 0);
    let (a, b, d) = (
        worker(&mut c, "a", 0),
        worker(&mut c, "b", 0),
        worker(&mut c, "d", 0),
    );
    let total = |c: &Connection| -> (u32, u32) {
        c.query_row(
            "SELECT tasks_total, tasks_done FROM frames WHERE job_id = ?1",
            [j],
            |r| Ok((r.get(0)?, r.get(1)?)),
        )
        .unwrap()
    };

    // a renders tile 0; every task is sampled, so its check is queued and the frame waits.
    let first = lease(&mut c, a, 1, timing).unwrap().unwrap();
    accept(&mut c, a, first.token, 1, 1, None, 2, timing).unwrap();
    assert_eq!(total(&c), (5, 1));
    // a is never given the check of its own tile: it gets the next render task.
    let second = lease(&mut c, a, 3, timing).unwrap().unwrap();
    let check = load_task(&c, second.token.task_id).unwrap().unwrap();
    assert_eq!(check.check_of, None);
    // b gets the check (checks share their task's frame, pass and tile: first in line).
    let l = lease(&mut c, b, 3, timing).unwrap().unwrap();
    let check = load_task(&c, l.token.task_id).unwrap().unwrap();
    assert_eq!(check.check_of, Some(first.token.task_id));
    assert_eq!((check.rect, check.samples), {
        let t = load_task(&c, first.token.task_id).unwrap().unwrap();
        (t.rect, t.samples)
    });
    // b's tile differs from a's: both suspects, a third render is asked for.
    accept(
        &mut c,
        b,
        l.token,
        1,
        1,
        Some(&Verdict::Disagrees),
        4,
        timing,
    )
    .unwrap();
    assert_eq!(total(&c), (6, 2));
    let suspects: i64 = c
        .query_row(
            "SELECT count(*) FROM workers WHERE suspect_ms IS NOT NULL",
            [],
            |r| r.get(0),
        )
        .unwrap();
    assert_eq!(suspects, 2);
    // d decides: it agrees with b, so a's tile was wrong.
    let third = lease(&mut c, d, 5, timing).unwrap().unwrap();
    let deciding = load_task(&c, third.token.task_id).unwrap().unwrap();
    assert_eq!(deciding.check_of, Some(first.token.task_id));
    accept(
        &mut c,
        d,
        third.token,
        1,
        1,
        Some(&Verdict::Agrees(vec![check.id])),
        6,
        timing,
    )
    .unwrap();
    assert!(crate::verify::is_quarantined(&c, a).unwrap());
    assert!(!crate::verify::is_quarantined(&c, b).unwrap());
    // a's lease on its second task went back to the queue, and a gets no more work.
    assert_eq!(state_of(&c, second.token.task_id), TaskState::Queued);
    assert_eq!(lease(&mut c, a, 7, timing).unwrap(), None);
    let workers = crate::status::workers(&c, 7, LEASE_MS).unwrap().workers;
    assert!(workers[0]
        .quarantined
        .as_deref()
        .unwrap()
        .contains("differs"));
    assert!(!workers[1].suspect && workers[1].quarantined.is_none());
    // Cleared by an operator, it works again.
    crate::verify::clear(&mut c, a, 8).unwrap();
    assert!(lease(&mut c, a, 9, timing).unwrap().is_some());
}

/// A quarantined worker's tiles in frames not yet assembled are all checked, whatever
/// the fraction.
#[test]
fn quarantine_sends_the_workers_other_tiles_to_checks() {
    let mut c = db();
    let j = job(&mut c, 1, 0, 3, 0);
    let (a, b, e) = (
        worker(&mut c, "a", 0),
        worker(&mut c, "b", 0),
        worker(&mut c, "e", 0),
    );
    // a renders three of the four tiles, unchecked (fraction 0).
    let mut done = Vec::new();
    for _ in 0..3 {
        let l = lease(&mut c, a, 1, TIMING).unwrap().unwrap();
        accept(&mut c, a, l.token, 1, 1, None, 1, TIMING).unwrap();
        done.push(l.token.task_id);
    }
    // The first is sampled after all; b checks it and disagrees; e agrees with b.
    let tx = c.transaction().unwrap();
    let first = load_task(&tx, done[0]).unwrap().unwrap();
    crate::verify::sample(&tx, &first, a, 1.0, 0, 2).unwrap();
    tx.commit().unwrap();
    let l = lease(&mut c, b, 3, TIMING).unwrap().unwrap();
    assert_eq!(check_of(&c, &l), Some(done[0]));
    accept(
        &mut c,
        b,
        l.token,
        1,
        1,
        Some(&Verdict::Disagrees),
        4,
        TIMING,
    )
    .unwrap();
    let b_check = l.token.task_id;
    let l = lease(&mut c, e, 5, TIMING).unwrap().unwrap();
    assert_eq!(check_of(&c, &l), Some(done[0]));
    accept(
        &mut c,
        e,
        l.token,
        1,
        1,
        Some(&Verdict::Agrees(vec![b_check])),
        6,
        TIMING,
    )
    .unwrap();
    assert!(crate::verify::is_quarantined(&c, a).unwrap());
    // a's two other tiles now have checks queued, and the frame waits for them and for
    // its last render task.
    for &t in &done[1..] {
        let n: i64 = c
            .query_row(
                "SELECT count(*) FROM tasks WHERE check_of = ?1 AND state = 'queued'",
                [t],
                |r| r.get(0),
            )
            .unwrap();
        assert_eq!(n, 1, "task {t}");
    }
    let open: i64 = c
        .query_row(
            "SELECT tasks_total - tasks_done FROM frames WHERE job_id = ?1",
            [j],
            |r| r.get(0),
        )
        .unwrap();
    assert_eq!(open, 3);
}

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
    create_job(c, &plan, now).unwrap()
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
    let plan = job_status(&c, j, 0).unwrap().budget.unwrap();
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
    let status = job_status(&c, j, t).unwrap();
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
    let status = job_status(&c, j, t).unwrap();
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

/// Every frame that reached the job's spp leaves nothing to refine: the job ends early.
#[test]
fn a_time_budget_ends_early_when_every_frame_reaches_spp() {
    let mut c = db();
    let j = budget_job(&mut c, 2, 8, 3_600.0, 0);
    let w = worker(&mut c, "w", 0);
    let mut t = 0;
    render_budget(&mut c, &[w], &mut t, 10, |_| 1.0);
    let status = job_status(&c, j, t).unwrap();
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
    while job_status(&c, j, t).unwrap().budget.unwrap().passes_added == 0 {
        render_one(&mut c, a, &mut t, 100, &error).unwrap();
    }
    let alone = job_status(&c, j, t).unwrap().budget.unwrap();
    assert_eq!(alone.workers, 1);
    // Worker b joins and renders a tile as fast: the farm is measured twice as fast.
    let b = worker(&mut c, "b", t);
    let l = lease(&mut c, b, t, TIMING).unwrap().unwrap();
    accept(&mut c, b, l.token, 1, 1, None, t + 100, TIMING).unwrap();
    t += 100;
    assert_eq!(replan_budgets(&mut c, t, TIMING).unwrap(), vec![j]);
    let both = job_status(&c, j, t).unwrap().budget.unwrap();
    assert_eq!(both.workers, 2);
    let ratio = both.samples_per_second / alone.samples_per_second;
    assert!((ratio - 2.0).abs() < 1e-9, "{both:?} {alone:?}");
    // It leaves: the plan is back to one worker's speed.
    leave(&mut c, b, t).unwrap();
    replan_budgets(&mut c, t, TIMING).unwrap();
    let after = job_status(&c, j, t).unwrap().budget.unwrap();
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
    heartbeat(&mut c, a, None, t, TIMING).unwrap();
    replan_budgets(&mut c, t, TIMING).unwrap();
    assert_eq!((queued(&c, false), queued(&c, true)), (0, started));
    let status = job_status(&c, j, t).unwrap();
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
    let demand = |c: &Connection, now| crate::metrics::snapshot(c, now, LEASE_MS).unwrap().demand;
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

/// A worker that comes back, with its credential or under the name of a worker that is
/// gone, is that worker again: its job blocks and quarantine stay, its leases go back to
/// the queue. A name a live worker holds is refused; a taken-over identity's old
/// credential is nobody's.
#[test]
fn a_worker_that_comes_back_keeps_its_identity_and_a_live_name_is_refused() {
    let mut c = db();
    let j = job(&mut c, 1, 0, 5, 0);
    let joining = |name, credential| Joining {
        name,
        threads: 4,
        version: "test",
        credential,
        platform: None,
    };
    let live = |now| live_since(now, TIMING);
    let first = join(&mut c, &joining("a", None), 0, live(0)).unwrap();
    assert!(!first.returned);
    assert_eq!(first.credential.len(), 64);
    assert_eq!(
        worker_of_credential(&c, &first.credential).unwrap(),
        Some(first.id)
    );
    // Blocked from j (block_after_failures is 2), then quarantined, holding a lease.
    for t in [1, 2] {
        let l = lease(&mut c, first.id, t, TIMING).unwrap().unwrap();
        fail(&mut c, first.id, l.token, "x", t, TIMING).unwrap();
    }
    let other = job(&mut c, 1, -1, 5, 3);
    let held = lease(&mut c, first.id, 3, TIMING).unwrap().unwrap();
    assert_eq!(held.job_id, other);
    c.execute(
        "UPDATE workers SET quarantined_ms = 3, quarantine_reason = 'wrong' WHERE id = ?1",
        [first.id],
    )
    .unwrap();

    // Another process under the same name, without the credential, while it is live.
    let taken = join(&mut c, &joining("a", None), 4, live(4));
    assert!(
        matches!(taken, Err(Error::Conflict(ref m)) if m.contains("worker 1")),
        "{taken:?}"
    );
    // With the credential it is back at once: same id, same credential, lease requeued.
    let back = join(&mut c, &joining("a", Some(&first.credential)), 5, live(5)).unwrap();
    assert_eq!((back.id, back.returned), (first.id, true));
    assert_eq!(back.credential, first.credential);
    assert_eq!(state_of(&c, held.token.task_id), TaskState::Queued);
    let row: (Option<i64>, Option<i64>) = c
        .query_row(
            "SELECT quarantined_ms, left_ms FROM workers WHERE id = ?1",
            [first.id],
            |r| Ok((r.get(0)?, r.get(1)?)),
        )
        .unwrap();
    assert_eq!(row, (Some(3), None), "still quarantined");
    let blocked: bool = c
        .query_row(
            "SELECT count(*) > 0 FROM job_blocks WHERE job_id = ?1 AND worker_id = ?2",
            params![j, first.id],
            |r| r.get(0),
        )
        .unwrap();
    assert!(blocked, "still blocked from job {j}");

    // Once it left, its name alone takes it over, with a new credential.
    leave(&mut c, first.id, 6).unwrap();
    let again = join(&mut c, &joining("a", None), 7, live(7)).unwrap();
    assert_eq!((again.id, again.returned), (first.id, true));
    assert_ne!(again.credential, first.credential);
    assert_eq!(worker_of_credential(&c, &first.credential).unwrap(), None);
    // Silent for two lease periods counts as gone too.
    let late = 8 + 2 * LEASE_MS + 1;
    let third = join(&mut c, &joining("a", None), late, live(late)).unwrap();
    assert_eq!(third.id, first.id);
    // A different name is a different worker.
    let b = join(&mut c, &joining("b", None), late, live(late)).unwrap();
    assert!(!b.returned && b.id != first.id);
}

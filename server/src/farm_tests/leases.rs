//! Leases: order, heartbeats, expiry, failures and blocks, uploads, restarts.

use super::*;

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
fn preview_first_leases_every_nth_frame_before_the_rest_fill_in() {
    let mut c = db();
    let mut spec = JobSpec::new(scene().digest);
    (spec.width, spec.height, spec.tile_size, spec.spp) = (16, 16, Some(16), 4);
    spec.sample_passes = 2;
    // Frames 10, 12, ..., 24: every third of them (10, 16, 22) first.
    spec.frames = Some(FrameRange {
        start: 10,
        end: 24,
        step: 2,
    });
    spec.preview_every = Some(3);
    let plan = crate::spec::plan(spec, &scene(), 1_000).unwrap();
    submit(&mut c, &plan, 0).unwrap();
    let w = worker(&mut c, "w", 0);
    let order: Vec<(i32, u32)> = std::iter::from_fn(|| lease(&mut c, w, 1_000, TIMING).unwrap())
        .map(|l| (l.frame, l.samples.start))
        .collect();
    let frames = [10, 16, 22, 12, 14, 18, 20, 24];
    let expected: Vec<(i32, u32)> = frames.iter().flat_map(|&f| [(f, 0), (f, 2)]).collect();
    assert_eq!(order, expected);
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
        heartbeat(&mut c, w, Some(l.token), &[], 4_000, TIMING).unwrap(),
        Some(4_000 + LEASE_MS)
    );
    // Not expired at the first deadline, thanks to the heartbeat.
    assert!(expire(&mut c, LEASE_MS + 1, TIMING).unwrap().is_empty());
    let stale = TaskToken {
        attempt: l.token.attempt + 1,
        ..l.token
    };
    assert!(matches!(
        heartbeat(&mut c, w, Some(stale), &[], 5_000, TIMING),
        Err(Error::LeaseGone(_))
    ));
    // Another worker's heartbeat for this lease is refused too.
    let other = worker(&mut c, "other", 0);
    assert!(matches!(
        heartbeat(&mut c, other, Some(l.token), &[], 5_000, TIMING),
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
    let task = tasks::load(&c, first.token.task_id).unwrap().unwrap();
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
        heartbeat(&mut c, a, Some(first.token), &[], LEASE_MS + 3, TIMING),
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
    let (_, ack) = fail(&mut c, ws[0], l.token, "out of memory", &[], 1, TIMING).unwrap();
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
    let (_, ack) = fail(&mut c, ws[1], l2.token, "out of memory", &[], 3, TIMING).unwrap();
    assert!(ack.task_failed && !ack.requeued);
    assert_eq!(state_of(&c, l.token.task_id), TaskState::Failed);
    let status = job_status(&c, j, 4, TIMING.live_since(4)).unwrap();
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
    let status = job_status(&c, j, 12, TIMING.live_since(12)).unwrap();
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
    let status = job_status(&c, j, 14, TIMING.live_since(14)).unwrap();
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
    fail(&mut c, a, l.token, "crash", &[], 1, TIMING).unwrap();
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
    fail(&mut c, a, l.token, "crash", &[], 1, TIMING).unwrap();
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
        !fail(&mut c, a, l.token, "x", &[], 1, TIMING)
            .unwrap()
            .1
            .blocked_from_job
    );
    let l = lease(&mut c, a, 2, TIMING).unwrap().unwrap();
    assert_eq!(l.job_id, j);
    assert!(
        fail(&mut c, a, l.token, "x", &[], 3, TIMING)
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
    submit(&mut c, &plan, 0).unwrap();
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
    let t = tasks::load(&c, l.token.task_id).unwrap().unwrap();
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

//! Job controls: pause, resume, cancel, retry, priority.

use super::*;

#[test]
fn pause_takes_leases_back_and_the_heartbeat_says_so() {
    let mut c = db();
    let j = job(&mut c, 1, 0, 3, 0);
    let w = worker(&mut c, "w", 0);
    let l = lease(&mut c, w, 0, TIMING).unwrap().unwrap();
    pause(&mut c, j, 1).unwrap();
    assert_eq!(state_of(&c, l.token.task_id), TaskState::Queued);
    match heartbeat(&mut c, w, Some(l.token), &[], 2, TIMING) {
        Err(Error::LeaseGone(why)) => assert!(why.contains("paused"), "{why}"),
        other => panic!("{other:?}"),
    }
    assert_eq!(lease(&mut c, w, 3, TIMING).unwrap(), None);
    assert_eq!(
        job_status(&c, j, 3, TIMING.live_since(3)).unwrap().state,
        JobState::Paused
    );
    // A revoke is not the worker's fault: no failure counted.
    assert_eq!(
        tasks::load(&c, l.token.task_id).unwrap().unwrap().failures,
        0
    );
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
    match heartbeat(&mut c, w, Some(l.token), &[], 4, TIMING) {
        Err(Error::LeaseGone(why)) => assert!(why.contains("cancelled"), "{why}"),
        other => panic!("{other:?}"),
    }
    let s = job_status(&c, j, 5, TIMING.live_since(5)).unwrap();
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
        fail(&mut c, w, l.token, "x", &[], 1, TIMING)
            .unwrap()
            .1
            .task_failed
    );
    assert!(matches!(retry(&mut c, j + 1, 2), Err(Error::NotFound(_))));
    assert_eq!(retry(&mut c, j, 2).unwrap(), 1);
    let t = tasks::load(&c, l.token.task_id).unwrap().unwrap();
    assert_eq!((t.state, t.failures), (TaskState::Queued, 0));
    assert!(matches!(retry(&mut c, j, 3), Err(Error::Conflict(_))));
}

#[test]
fn a_new_priority_decides_the_next_lease_and_is_checked() {
    let mut c = db();
    let first = job(&mut c, 1, 0, 3, 0);
    let second = job(&mut c, 1, 0, 3, 1);
    let w = worker(&mut c, "w", 0);
    assert_eq!(lease(&mut c, w, 2, TIMING).unwrap().unwrap().job_id, first);
    crate::controls::set_priority(&mut c, second, 5, 3).unwrap();
    assert_eq!(lease(&mut c, w, 4, TIMING).unwrap().unwrap().job_id, second);
    let status = job_status(&c, second, 4, TIMING.live_since(4)).unwrap();
    assert_eq!(status.spec.priority, 5);
    assert!(matches!(
        crate::controls::set_priority(&mut c, second, 1_001, 5),
        Err(Error::Invalid { field, .. }) if field == "priority"
    ));
    assert!(matches!(
        crate::controls::set_priority(&mut c, second + 1, 1, 5),
        Err(Error::NotFound(_))
    ));
}

/// Leases and accepts every queued task of `w`, assembling each frame it completes.
fn render_all(c: &mut Connection, w: u64, t: i64) -> Vec<Lease> {
    let mut done = Vec::new();
    while let Some(l) = lease(c, w, t, TIMING).unwrap() {
        accept_assembling(c, w, &l, t);
        done.push(l);
    }
    done
}

#[test]
fn rerender_queues_a_finished_frames_tasks_again_and_refuses_what_it_cannot() {
    let mut c = db();
    let j = job(&mut c, 2, 0, 3, 0);
    let w = worker(&mut c, "w", 0);
    let first = render_all(&mut c, w, 1);
    assert_eq!(first.len(), 8);
    let st = job_status(&c, j, 2, TIMING.live_since(2)).unwrap();
    assert_eq!((st.state, st.frames_done), (JobState::Done, 2));

    let tasks = crate::controls::rerender(&mut c, j, &[2], 3).unwrap();
    let frame2: Vec<u64> = first
        .iter()
        .filter(|l| l.frame == 2)
        .map(|l| l.token.task_id)
        .collect();
    assert_eq!(tasks, frame2);
    let st = job_status(&c, j, 3, TIMING.live_since(3)).unwrap();
    assert_eq!(
        (st.state, st.frames_done, st.tasks.queued),
        (JobState::Running, 1, 4)
    );
    assert!(!is_assembled(&c, j, 2).unwrap());
    // Queued again: not yet. A frame the job lacks, none, or one twice: refused.
    for (frames, word) in [
        (&[2][..], "still rendering"),
        (&[9][..], "has no frame 9"),
        (&[][..], "must list 1 to"),
        (&[1, 1][..], "each once"),
    ] {
        let e = crate::controls::rerender(&mut c, j, frames, 4).unwrap_err();
        assert!(e.to_string().contains(word), "{frames:?}: {e}");
    }
    // The same tiles and samples again, with fresh attempts.
    let again = render_all(&mut c, w, 5);
    let pairs = |ls: &[Lease]| -> Vec<_> {
        ls.iter()
            .map(|l| (l.token.task_id, l.tile, l.samples))
            .collect()
    };
    assert_eq!(pairs(&again), pairs(&first[4..]));
    assert!(again.iter().all(|l| l.token.attempt == 2));
    let st = job_status(&c, j, 6, TIMING.live_since(6)).unwrap();
    assert_eq!((st.state, st.frames_done), (JobState::Done, 2));

    let k = job(&mut c, 1, 0, 3, 8);
    cancel(&mut c, k, 9).unwrap();
    let e = crate::controls::rerender(&mut c, k, &[1], 10).unwrap_err();
    assert!(e.to_string().contains("is cancelled"), "{e}");
}

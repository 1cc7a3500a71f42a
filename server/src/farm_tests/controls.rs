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

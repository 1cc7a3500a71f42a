//! Why attempts failed: every reason kept word for word, per task and grouped, and a job
//! that no live worker may take says so until it is retried.

use super::*;
use crate::status::{failures, tasks as task_page};

const REASON: &str = "preparing frame 1: the scene's texture 3 cannot be decoded: bad PNG";

#[test]
fn reasons_are_kept_per_task_and_grouped_and_a_blocked_out_job_is_stuck_until_retried() {
    let mut c = db();
    // Five attempts a task: the worker is blocked (after two failures) before any task
    // runs out.
    let j = job(&mut c, 1, 0, 5, 0);
    let w = worker(&mut c, "w", 0);
    let status = |c: &Connection, now| job_status(c, j, now, TIMING.live_since(now)).unwrap();
    assert_eq!(status(&c, 0).stuck, None);
    let mut failed = Vec::new();
    for now in [1, 2] {
        let l = lease(&mut c, w, now, TIMING).unwrap().unwrap();
        fail(&mut c, w, l.token, REASON, &[], now, TIMING).unwrap();
        failed.push(l.token.task_id);
    }
    // Another attempt's lease expires: a reason of its own.
    let other = worker(&mut c, "other", 3);
    let l = lease(&mut c, other, 3, TIMING).unwrap().unwrap();
    expire(&mut c, 3 + LEASE_MS + 1, TIMING).unwrap();

    let now = 3 + LEASE_MS + 2;
    let groups = failures(&c, j).unwrap().groups;
    assert_eq!(groups.len(), 2, "{groups:?}");
    assert_eq!(
        (
            groups[0].kind,
            groups[0].reason.as_str(),
            groups[0].attempts
        ),
        (proto::FailureKind::Reported, REASON, 2)
    );
    assert_eq!(
        (groups[0].tasks, groups[0].workers.clone()),
        (2, vec!["w".to_string()])
    );
    assert_eq!(groups[1].kind, proto::FailureKind::Expired);
    assert_eq!(groups[1].workers, vec!["other".to_string()]);

    let page = task_page(&c, j, Some(TaskState::Queued), 0, 1000).unwrap();
    assert_eq!(page.tasks.len(), 4, "nothing ran out of attempts");
    // `other` took the first task again (it had not failed it): two failures, oldest
    // first; the second task one.
    assert_eq!(l.token.task_id, failed[0]);
    let first = page.tasks.iter().find(|t| t.id == failed[0]).unwrap();
    let kinds: Vec<_> = first.failures.iter().map(|f| (f.kind, f.attempt)).collect();
    use proto::FailureKind::{Expired, Reported};
    assert_eq!(kinds, vec![(Reported, 1), (Expired, 2)]);
    let second = page.tasks.iter().find(|t| t.id == failed[1]).unwrap();
    assert_eq!(second.failures.len(), 1);
    assert_eq!(second.failures[0].reason, REASON);
    assert_eq!(
        (
            second.failures[0].worker.as_str(),
            second.failures[0].attempt
        ),
        ("w", 1)
    );
    assert!(task_page(&c, j, Some(TaskState::Failed), 0, 1000)
        .unwrap()
        .tasks
        .is_empty());

    // `other` is live but not blocked: the job can go on. Once it is gone (two lease
    // periods silent), every live worker is blocked: stuck, saying why.
    assert_eq!(status(&c, now).stuck, None);
    heartbeat(&mut c, w, None, &[], 3 * LEASE_MS, TIMING).unwrap();
    let st = status(&c, 3 * LEASE_MS);
    assert_eq!(st.attempts_failed, 3);
    let stuck = st.stuck.expect("every live worker is blocked");
    assert!(
        stuck.contains("of 1 live worker(s), 1 blocked from this job")
            && stuck.contains(REASON)
            && stuck.contains(&format!("tessera retry {j}")),
        "{stuck}"
    );
    // Retry lifts the blocks (no task failed for good, yet it is not refused)
    // and forgets the failures: the worker is blocked again only after failing anew.
    assert_eq!(retry(&mut c, j, 3 * LEASE_MS).unwrap(), 1);
    let st = status(&c, 3 * LEASE_MS);
    assert_eq!((st.stuck, st.attempts_failed), (None, 0));
    assert!(failures(&c, j).unwrap().groups.is_empty());
    assert!(lease(&mut c, w, 3 * LEASE_MS, TIMING).unwrap().is_some());
}

#[test]
fn task_pages_follow_ids_and_end() {
    let mut c = db();
    let j = job(&mut c, 3, 0, 3, 0);
    let first = task_page(&c, j, None, 0, 5).unwrap();
    assert_eq!(first.tasks.len(), 5);
    let after = first.next_after.expect("more pages");
    let rest = task_page(&c, j, None, after, 5).unwrap();
    assert_eq!(rest.tasks.len(), 5);
    let last = task_page(&c, j, None, rest.next_after.unwrap(), 5).unwrap();
    assert_eq!((last.tasks.len(), last.next_after), (2, None));
    let ids: Vec<u64> = [first, rest, last]
        .iter()
        .flat_map(|p| p.tasks.iter().map(|t| t.id))
        .collect();
    assert!(ids.windows(2).all(|w| w[0] < w[1]) && ids.len() == 12);
    // A page is at most the limit, whatever is asked.
    let all = task_page(&c, j, None, 0, u32::MAX).unwrap();
    assert_eq!(all.tasks.len(), 12);
    assert!(matches!(
        task_page(&c, j + 1, None, 0, 5),
        Err(Error::NotFound(_))
    ));
}

#[test]
fn a_worker_shows_its_speed_and_its_failures_of_the_last_hour() {
    let mut c = db();
    job(&mut c, 1, 0, 5, 0);
    let w = worker(&mut c, "w", 0);
    let info = |c: &Connection, now| workers::info(c, w, now, TIMING.live_since(now)).unwrap();
    assert_eq!(info(&c, 0).samples_per_second, None);
    // Two 8×8 tiles of 4 samples in 2 ms each: 256 samples per 2 ms.
    for now in [1, 2] {
        let l = lease(&mut c, w, now, TIMING).unwrap().unwrap();
        accept(&mut c, w, l.token, 1, 2, None, now, TIMING).unwrap();
    }
    let l = lease(&mut c, w, 3, TIMING).unwrap().unwrap();
    fail(&mut c, w, l.token, REASON, &[], 3, TIMING).unwrap();
    let now_ = info(&c, 4);
    assert_eq!(now_.samples_per_second, Some(128_000.0));
    assert_eq!(
        (now_.recent_failures, now_.last_failure.as_deref()),
        (1, Some(REASON))
    );
    // An hour later the failure is no longer recent; what it was stays.
    let later = info(&c, 3 + 3_600_001);
    assert_eq!(later.recent_failures, 0);
}

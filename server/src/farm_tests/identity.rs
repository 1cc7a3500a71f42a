//! Worker identity: a worker that comes back is itself again.

use super::*;

/// A worker that comes back, with its credential or under the name of a worker that is
/// gone, is that worker again: its job blocks and quarantine stay, its leases go back to
/// the queue. A name a live worker holds is refused; a taken-over identity's old
/// credential is nobody's.
#[test]
fn a_worker_that_comes_back_keeps_its_identity_and_a_live_name_is_refused() {
    let mut c = db();
    let j = job(&mut c, 1, 0, 5, 0);
    let live = |now| TIMING.live_since(now);
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
        fail(&mut c, first.id, l.token, "x", &[], t, TIMING).unwrap();
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

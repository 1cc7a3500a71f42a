//! Checks: a second render of a tile, verdicts, quarantine.

use super::*;

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
    let check = tasks::load(&c, second.token.task_id).unwrap().unwrap();
    assert_eq!(check.check_of, None);
    // b gets the check (checks share their task's frame, pass and tile: first in line).
    let l = lease(&mut c, b, 3, timing).unwrap().unwrap();
    let check = tasks::load(&c, l.token.task_id).unwrap().unwrap();
    assert_eq!(check.check_of, Some(first.token.task_id));
    assert_eq!((check.rect, check.samples), {
        let t = tasks::load(&c, first.token.task_id).unwrap().unwrap();
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
    let deciding = tasks::load(&c, third.token.task_id).unwrap().unwrap();
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
    assert!(workers::is_quarantined(&c, a).unwrap());
    assert!(!workers::is_quarantined(&c, b).unwrap());
    // Webhooks are to be told, once.
    let told: Vec<_> = crate::db::outbox::pending(&c, 100)
        .unwrap()
        .into_iter()
        .filter_map(|p| match p.subject {
            crate::db::outbox::Subject::WorkerQuarantined(w) => Some(w),
            _ => None,
        })
        .collect();
    assert_eq!(told, [a]);
    // a's lease on its second task went back to the queue, and a gets no more work.
    assert_eq!(state_of(&c, second.token.task_id), TaskState::Queued);
    assert_eq!(lease(&mut c, a, 7, timing).unwrap(), None);
    let workers = workers::list(&c, 7, TIMING.live_since(7), 0)
        .unwrap()
        .workers;
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
    let first = tasks::load(&tx, done[0]).unwrap().unwrap();
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
    assert!(workers::is_quarantined(&c, a).unwrap());
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

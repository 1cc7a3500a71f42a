//! A worker that silently computes wrong pixels. With every tile rendered again on a
//! second worker (`--verify-fraction 1`), the farm catches it, quarantines it, assembles
//! every frame from the tiles the healthy workers agree on, and gives it work again only
//! once an operator clears it.

use std::time::Duration;

use proto::{JobState, WorkerInfo};
use tests::{render_directly, settings, Farm};

fn worker_named<'a>(workers: &'a [WorkerInfo], name: &str) -> &'a WorkerInfo {
    workers
        .iter()
        .find(|w| w.name == name)
        .unwrap_or_else(|| panic!("no worker {name} in {workers:?}"))
}

#[test]
fn a_worker_that_perturbs_its_pixels_is_caught_quarantined_and_cleared() {
    let mut farm = Farm::new();
    farm.start_server_with(60, &["--verify-fraction", "1"]);
    // Every worker registers before the job exists, so each tile has someone to check it.
    farm.start_worker_with("bad", 1, &["--inject-fault", "perturb"]);
    farm.start_worker("good-1", 1);
    farm.start_worker("good-2", 1);
    tests::wait_until(
        "three workers to register",
        Duration::from_secs(60),
        || farm.worker_list().workers.len() == 3,
        || farm.logs(),
    );
    let scene = farm.demo_scene();
    let mut args = vec![scene.to_str().unwrap(), "--frames", "1-4", "--tile", "16"];
    args.extend(settings("2"));
    let job = farm.submit(&args);

    let st = farm.wait_for_job(job, Duration::from_secs(300));
    assert_eq!(st.state, JobState::Done, "{st:?}");
    for frame in 1..=4 {
        let direct = render_directly(&scene, frame, "2", farm.path());
        assert!(
            farm.server_frame(job, frame) == direct,
            "frame {frame} differs from tessera render\n{}",
            farm.logs()
        );
    }
    let workers = farm.worker_list().workers;
    let bad = worker_named(&workers, "bad");
    let reason = bad
        .quarantined
        .as_deref()
        .expect("the bad worker is quarantined");
    assert!(reason.contains("differs"), "{reason}");
    // The reason names every render's worker and platform (CPU, build), so a mismatch
    // between two kinds of machine can be told from a broken one.
    let platform = bad
        .platform
        .as_deref()
        .expect("workers report their platform");
    assert!(
        platform.starts_with(std::env::consts::ARCH) && platform.contains("tessera "),
        "{platform}"
    );
    assert!(
        reason.contains(&format!("by worker {} (bad) on {platform}", bad.id)),
        "{reason}"
    );
    for name in ["good-1", "good-2"] {
        let good = worker_named(&workers, name);
        assert!(good.quarantined.is_none() && !good.suspect, "{good:?}");
    }
    let table = farm.client(&["workers"]);
    assert!(table.contains("quarantined"), "{table}");

    // From the database: checks ran, one quarantine, and nothing finished by the bad
    // worker after it.
    let db = rusqlite::Connection::open(farm.path().join("data").join("tessera.db")).unwrap();
    let (checks, quarantines, after): (u64, u64, u64) = db
        .query_row(
            "SELECT (SELECT count(*) FROM tasks WHERE check_of IS NOT NULL AND state = 'done'),
                    (SELECT count(*) FROM events WHERE kind = 'worker_quarantined'),
                    (SELECT count(*) FROM tasks t JOIN workers w ON w.id = t.worker_id
                     WHERE w.id = ?1 AND t.state = 'done' AND t.done_ms > w.quarantined_ms)",
            [bad.id],
            |r| Ok((r.get(0)?, r.get(1)?, r.get(2)?)),
        )
        .unwrap();
    assert!(
        checks >= 16,
        "every one of the 16 tiles was checked: {checks}"
    );
    assert_eq!((quarantines, after), (1, 0));

    // A restart does not shed the quarantine: killed (no goodbye) and started again with
    // its name and cache folder (its identity file), without the fault, the machine is the
    // same worker, still quarantined, and gets no work.
    farm.workers[0].kill9();
    let restarted = farm.start_worker("bad", 1);
    let back = format!("as worker {} ", bad.id);
    tests::wait_until(
        "the restarted worker to register",
        Duration::from_secs(60),
        || farm.workers[restarted].log().contains(&back),
        || farm.logs(),
    );
    let workers = farm.worker_list().workers;
    assert_eq!(workers.len(), 3, "no new worker: {workers:?}");
    let again = worker_named(&workers, "bad");
    assert_eq!(again.id, bad.id);
    assert!(again.quarantined.is_some() && again.online, "{again:?}");
    let mut args = vec![scene.to_str().unwrap(), "--frames", "2-2", "--tile", "16"];
    args.extend(settings("2"));
    let during = farm.submit(&args);
    let st = farm.wait_for_job(during, Duration::from_secs(120));
    assert_eq!(st.state, JobState::Done, "{st:?}");
    let again = worker_named(&farm.worker_list().workers, "bad").clone();
    assert_eq!(
        again.tasks_done, bad.tasks_done,
        "a quarantined worker rendered"
    );

    // The operator clears it: alone on the farm now, it renders the next job.
    let done_before = bad.tasks_done;
    let cleared = farm.client(&["workers", "--clear", &bad.id.to_string()]);
    assert!(cleared.contains("cleared"), "{cleared}");
    for good in [1, 2] {
        let status = farm.workers[good].terminate(Duration::from_secs(20));
        assert!(status.success(), "{status}");
    }
    let mut args = vec![scene.to_str().unwrap(), "--frames", "1-1", "--tile", "16"];
    args.extend(settings("2"));
    let next = farm.submit(&args);
    let st = farm.wait_for_job(next, Duration::from_secs(120));
    assert_eq!(st.state, JobState::Done, "{st:?}");
    let bad = worker_named(&farm.worker_list().workers, "bad").clone();
    assert!(bad.quarantined.is_none(), "{bad:?}");
    assert_eq!(bad.tasks_done, done_before + 4);
}

//! Retention: which finished jobs, unused scenes and events go, with their files; what a
//! dry run says; a job with work left is never touched.

use super::*;
use crate::retention::{collect, KeepJobs};
use crate::Config;

const DAY: i64 = 86_400_000;

fn write(path: &std::path::Path, bytes: usize) {
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    std::fs::write(path, vec![7u8; bytes]).unwrap();
}

#[test]
fn retention_removes_old_finished_jobs_unused_scenes_and_their_events_only() {
    let dir = tempfile::tempdir().unwrap();
    let app = crate::open(Config::new(dir.path())).unwrap();
    let store = app.store.clone();
    let used = scene().digest;
    let (unused, fresh) = ("b".repeat(64), "c".repeat(64));
    let (old, newer, running) = app.db.with(|c| {
        for (digest, uploaded) in [(&used, 0), (&unused, 0), (&fresh, 10 * DAY - 3_600_000)] {
            crate::db::scenes::insert(c, digest, 1, &scene(), uploaded).unwrap();
        }
        let ids = [job(c, 1, 0, 3, 0), job(c, 1, 0, 3, 0), job(c, 1, 0, 3, 0)];
        // Two finished (one on day 1, one on day 5); the third has work left.
        for (id, at) in [(ids[0], DAY), (ids[1], 5 * DAY)] {
            c.execute(
                "UPDATE jobs SET finished_ms = ?2 WHERE id = ?1",
                params![id, at],
            )
            .unwrap();
        }
        (ids[0], ids[1], ids[2])
    });
    for id in [old, newer, running] {
        write(&store.frame(id, 1, 1, "exr"), 1_000);
        write(&store.tile(id, 1, 1), 100);
    }
    for digest in [&used, &unused, &fresh] {
        write(&store.scene(digest), 10);
    }
    let now = 10 * DAY;

    // Keep the one finished last: the older goes, with the scene nobody uses (the one
    // uploaded an hour ago stays: its job may be on its way).
    let dry = collect(&app, KeepJobs::Newest(1), true, now).unwrap();
    let ids: Vec<u64> = dry.jobs.iter().map(|j| j.id).collect();
    assert_eq!(ids, [old]);
    assert_eq!(dry.scenes, std::slice::from_ref(&unused));
    assert_eq!(dry.bytes, 1_000 + 100 + 10);
    assert_eq!(dry.events, 1, "the old job's job_created");
    assert!(dry.dry_run && store.frame(old, 1, 1, "exr").is_file());
    assert!(store.scene(&unused).is_file());

    let done = collect(&app, KeepJobs::Newest(1), false, now).unwrap();
    assert_eq!(
        (done.jobs, done.scenes, done.bytes),
        (dry.jobs, dry.scenes, dry.bytes)
    );
    assert_eq!(done.events, 1);
    assert!(!store.job_dir(old).exists() && !store.tile_dir(old).exists());
    assert!(!store.scene(&unused).exists());
    app.db.with(|c| {
        assert!(matches!(
            crate::db::jobs::load(c, old),
            Err(Error::NotFound(_))
        ));
        let scenes: i64 = c
            .query_row("SELECT count(*) FROM scenes", [], |r| r.get(0))
            .unwrap();
        assert_eq!(scenes, 2);
        let left: Vec<String> = c
            .prepare("SELECT kind FROM events WHERE job_id = ?1")
            .unwrap()
            .query_map([old], |r| r.get(0))
            .unwrap()
            .collect::<rusqlite::Result<_>>()
            .unwrap();
        assert_eq!(left, ["job_deleted"], "the record of the deletion stays");
    });

    // By age: everything finished more than a day ago goes; the job with work left stays
    // however old it is, and so do its scene and files.
    let by_age = collect(
        &app,
        KeepJobs::For(std::time::Duration::from_secs(86_400)),
        false,
        now,
    )
    .unwrap();
    let ids: Vec<u64> = by_age.jobs.iter().map(|j| j.id).collect();
    assert_eq!(ids, [newer]);
    assert!(by_age.scenes.is_empty(), "the running job still uses it");
    assert!(store.frame(running, 1, 1, "exr").is_file());
    assert!(store.scene(&used).is_file());
    let all = collect(&app, KeepJobs::All, false, now).unwrap();
    assert!(all.jobs.is_empty() && all.scenes.is_empty() && all.bytes == 0);
}

#[test]
fn the_event_log_keeps_its_newest_entries_up_to_the_bound() {
    let mut c = db();
    let tx = c.transaction().unwrap();
    for i in 0..5 {
        crate::db::events::log(&tx, i, None, "worker_registered", &i.to_string()).unwrap();
    }
    assert_eq!(crate::db::events::to_trim(&tx, &[], 3).unwrap(), 2);
    assert_eq!(crate::db::events::trim(&tx, 3).unwrap(), 2);
    let left: Vec<String> = tx
        .prepare("SELECT detail FROM events ORDER BY id")
        .unwrap()
        .query_map([], |r| r.get(0))
        .unwrap()
        .collect::<rusqlite::Result<_>>()
        .unwrap();
    assert_eq!(left, ["2", "3", "4"]);
    assert_eq!(crate::db::events::trim(&tx, 3).unwrap(), 0);
}

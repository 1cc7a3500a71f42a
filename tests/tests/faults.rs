//! Workers that die or hang mid-tile: the farm re-queues their work, ignores what comes
//! late, and every frame still equals a direct `tessera render`.

use std::time::Duration;

use proto::JobState;
use tests::{render_directly, settings, Farm};

#[path = "faults/disk.rs"]
mod disk;
#[path = "faults/memory.rs"]
mod memory;
#[path = "faults/verify.rs"]
mod verify;

/// The shortest lease `tessera server` allows, so an expiry comes within seconds.
const LEASE_SECONDS: u64 = 5;

/// Submits two frames of the demo as one tile each, with enough samples (512) that a
/// worker is caught mid-render; returns the job id.
fn slow_job(farm: &Farm) -> u64 {
    let scene = farm.demo_scene();
    let mut args = vec![scene.to_str().unwrap(), "--frames", "1-2", "--tile", "32"];
    args.extend(settings("512"));
    farm.submit(&args)
}

fn wait_for_a_lease(farm: &Farm, job: u64) {
    tests::wait_until(
        "a worker to hold a lease",
        Duration::from_secs(60),
        || farm.job(job).tasks.leased == 1,
        || farm.logs(),
    );
}

fn assert_frames_match_direct_renders(farm: &Farm, job: u64) {
    let st = farm.wait_for_job(job, Duration::from_secs(300));
    assert_eq!(st.state, JobState::Done, "{st:?}");
    let scene = farm.path().join("demo.glb");
    for frame in 1..=2 {
        let direct = render_directly(&scene, frame, "512", farm.path());
        assert!(
            farm.server_frame(job, frame) == direct,
            "frame {frame} differs from tessera render"
        );
    }
}

#[test]
fn a_worker_killed_mid_tile_loses_its_lease_and_another_finishes_the_task() {
    let mut farm = Farm::new();
    farm.start_server(LEASE_SECONDS);
    let job = slow_job(&farm);
    let doomed = farm.start_worker("doomed", 1);
    wait_for_a_lease(&farm, job);
    farm.workers[doomed].kill9();
    // No goodbye: the lease stays until it expires.
    assert_eq!(farm.job(job).tasks.leased, 1);

    farm.start_worker("rescuer", 2);
    assert_frames_match_direct_renders(&farm, job);
    let st = farm.job(job);
    assert_eq!((st.tasks.done, st.tasks.failed), (2, 0), "{st:?}");
}

#[test]
fn a_hung_worker_loses_its_task_and_its_late_upload_is_ignored() {
    let mut farm = Farm::new();
    farm.start_server(LEASE_SECONDS);
    let job = slow_job(&farm);
    let hung = farm.start_worker("hung", 1);
    wait_for_a_lease(&farm, job);
    // SIGSTOP: the process keeps its connections but neither renders nor heartbeats.
    farm.workers[hung].signal(libc::SIGSTOP);

    farm.start_worker("rescuer", 2);
    let st = farm.wait_for_job(job, Duration::from_secs(300));
    assert_eq!(st.state, JobState::Done, "{st:?}");
    // Woken up, the hung worker finds its lease gone: the tile is dropped, not stored.
    farm.workers[hung].signal(libc::SIGCONT);
    tests::wait_until(
        "the woken worker to notice its lease is gone",
        Duration::from_secs(60),
        || {
            let log = farm.workers[hung].log();
            log.contains("gone") || log.contains("expired")
        },
        || farm.logs(),
    );
    assert_frames_match_direct_renders(&farm, job);
    let status = farm.workers[hung].terminate(Duration::from_secs(20));
    assert!(status.success(), "{status}");
}

#[test]
fn a_worker_that_always_fails_one_job_is_blocked_from_it_and_renders_the_others() {
    let mut farm = Farm::new();
    farm.start_server(60);
    let scene = farm.demo_scene();
    let mut args = vec![scene.to_str().unwrap(), "--frames", "1-2", "--tile", "16"];
    args.extend(settings("2"));
    let failing = farm.submit(&args);
    let other = farm.submit(&args);
    let fault = format!("fail-job={failing}");
    farm.start_worker_with("flaky", 1, &["--inject-fault", &fault]);

    // The older job comes first: three failures (on three different tasks) block the
    // worker from it, and it renders the other job whole.
    let st = farm.wait_for_job(other, Duration::from_secs(120));
    assert_eq!(st.state, JobState::Done, "{st:?}");
    let st = farm.job(failing);
    assert_eq!((st.tasks.done, st.tasks.failed), (0, 0), "{st:?}");
    let db = rusqlite::Connection::open(farm.path().join("data").join("tessera.db")).unwrap();
    let (blocks, failures): (u64, u64) = db
        .query_row(
            "SELECT (SELECT count(*) FROM job_blocks WHERE job_id = ?1),
                    (SELECT count(*) FROM task_failures WHERE job_id = ?1)",
            [failing],
            |r| Ok((r.get(0)?, r.get(1)?)),
        )
        .unwrap();
    assert_eq!((blocks, failures), (1, 3));

    // A healthy worker finishes the blocked job; its frames are as tessera render makes them.
    farm.start_worker("healthy", 1);
    let st = farm.wait_for_job(failing, Duration::from_secs(120));
    assert_eq!(st.state, JobState::Done, "{st:?}");
    for frame in 1..=2 {
        let direct = render_directly(&scene, frame, "2", farm.path());
        assert!(farm.server_frame(failing, frame) == direct, "frame {frame}");
    }
}

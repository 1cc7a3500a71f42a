//! A job's life after submission, as its user drives it from the command line, naming the
//! job by its name: download its frames (again after a server restart, fetching only what
//! is missing), clone it
//! with one setting changed (the clone's frames equal a direct render at that setting,
//! bit for bit), render a frame again (the same bits), change its priority, delete it.

use std::time::Duration;

use proto::JobState;
use tests::{http, render_directly, settings, Farm};
use tracer::output::read_exr;

#[test]
fn download_clone_priority_and_delete_by_name() {
    let mut farm = Farm::new();
    farm.start_server(60);
    farm.start_worker("w", 2);
    let scene = farm.demo_scene();
    let mut args = vec![scene.to_str().unwrap(), "--frames", "1-2", "--name", "walk"];
    args.extend(settings("2"));
    let first = farm.submit(&args);
    assert_eq!(
        farm.wait_for_job(first, Duration::from_secs(120)).state,
        JobState::Done
    );

    // Download by name; again after losing a file: only that one is fetched.
    let out = farm.client(&["download", "walk", "--out", "walk-frames"]);
    assert!(
        out.starts_with(&format!(
            "2 of 2 frame(s) of job {first} in walk-frames (0 file(s) already there"
        )),
        "{out}"
    );
    let dir = farm.path().join("walk-frames");
    let frame1 = dir.join("frame_0001.exr");
    assert_eq!(
        read_exr(&frame1).unwrap().layers,
        farm.server_frame(first, 1)
    );
    assert!(dir.join("frame_0002.png").is_file());
    std::fs::remove_file(&frame1).unwrap();
    // The server restarts in between: the finished job's frames are still there.
    farm.server.as_mut().unwrap().kill9();
    farm.start_server(60);
    let out = farm.client(&["download", "walk", "--out", "walk-frames"]);
    assert!(out.contains("(3 file(s) already there"), "{out}");
    assert_eq!(
        read_exr(&frame1).unwrap().layers,
        farm.server_frame(first, 1)
    );

    // Clone with more samples and a name of its own: everything else is the job's.
    let out = farm.client(&["clone", "walk", "--spp", "4", "--name", "walk-4spp"]);
    let clone: u64 = out
        .split_whitespace()
        .nth(1)
        .and_then(|id| id.parse().ok())
        .unwrap_or_else(|| panic!("no job id in {out}"));
    assert!(out.contains(&format!("a clone of job {first}")), "{out}");
    let st = farm.wait_for_job(clone, Duration::from_secs(120));
    assert_eq!(st.state, JobState::Done, "{st:?}");
    assert_eq!((st.name.as_str(), st.spec.spp), ("walk-4spp", 4));
    let original = farm.job(first).spec;
    assert_eq!(
        (st.spec.frames, st.spec.shutter, st.spec.seed, st.spec.width),
        (
            original.frames,
            original.shutter,
            original.seed,
            original.width
        )
    );
    for frame in 1..=2 {
        assert!(
            farm.server_frame(clone, frame) == render_directly(&scene, frame, "4", farm.path()),
            "the clone's frame {frame} differs from tessera render at 4 spp"
        );
    }

    // Frame 2 of the clone rendered again, in the same job: the same bits, its old files
    // replaced, the job's log says so.
    let before = std::fs::metadata(farm.data_dir().join(format!("jobs/{clone}/frame_0002.exr")))
        .unwrap()
        .modified()
        .unwrap();
    let out = farm.client(&["rerender", "walk-4spp", "--frames", "2"]);
    assert!(
        out.starts_with(&format!("job {clone}: 1 frame(s) queued to render again")),
        "{out}"
    );
    let st = farm.wait_for_job(clone, Duration::from_secs(120));
    assert_eq!((st.state, st.frames_done), (JobState::Done, 2), "{st:?}");
    let after = std::fs::metadata(farm.data_dir().join(format!("jobs/{clone}/frame_0002.exr")))
        .unwrap()
        .modified()
        .unwrap();
    assert!(after > before, "frame 2 was not written again");
    assert!(
        farm.server_frame(clone, 2) == render_directly(&scene, 2, "4", farm.path()),
        "the rerendered frame 2 differs from tessera render at 4 spp"
    );
    let log = farm.client(&["logs", "walk-4spp"]);
    assert!(log.contains("frames_rerender  frames 2"), "{log}");
    // A frame the job does not have is refused with the reason.
    let o = tests::tessera(
        &[
            "rerender",
            "walk-4spp",
            "--frames",
            "7",
            "--server",
            &farm.url(),
        ],
        farm.path(),
    );
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains(&format!("job {clone} has no frame 7")),
        "{err}"
    );

    // The scene again by the short digest submit printed: not uploaded again.
    let digest = farm.job(first).spec.scene;
    let mut again = vec!["submit", &digest[..12], "--server"];
    let url = farm.url();
    again.extend([url.as_str(), "--frames", "1", "--name", "by-digest"]);
    again.extend(settings("2"));
    let out = tests::tessera_ok(&again, farm.path());
    let by_digest = tests::job_id_in(&out).unwrap_or_else(|| panic!("{out}"));
    assert_eq!(farm.job(by_digest).spec.scene, digest, "{out}");
    let o = tests::tessera(&["submit", "00000000", "--server", &url], farm.path());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("no scene with digest `00000000`"),
        "{err}"
    );

    // Priority and delete, by name.
    let out = farm.client(&["priority", "walk-4spp", "-7"]);
    assert_eq!(out.trim(), format!("job {clone} now has priority -7"));
    assert_eq!(farm.job(clone).spec.priority, -7);
    let out = farm.client(&["delete", "walk-4spp"]);
    assert_eq!(out.trim(), format!("job {clone} deleted with its files"));
    let gone = http::get(farm.port, &format!("/api/v1/jobs/{clone}"));
    assert_eq!(gone.status, 404);
    assert!(!farm
        .data_dir()
        .join("jobs")
        .join(clone.to_string())
        .exists());
    // A name that is not there, or that two jobs share, is a clear error.
    let o = tests::tessera(
        &["delete", "walk-4spp", "--server", &farm.url()],
        farm.path(),
    );
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("no job named `walk-4spp`"),
        "{err}"
    );
    farm.submit(&args);
    let o = tests::tessera(&["status", "walk", "--server", &farm.url()], farm.path());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("2 jobs are named `walk`"),
        "{err}"
    );
}

#[test]
fn retention_removes_old_finished_jobs_with_their_files_and_spares_jobs_with_work_left() {
    let mut farm = Farm::new();
    farm.start_server_with(60, &["--keep-jobs", "1"]);
    // The data folder's size is measured as the server starts.
    let measured = || {
        http::get(farm.port, "/metrics")
            .text()
            .lines()
            .find_map(|l| l.strip_prefix("tessera_data_folder_bytes "))
            .and_then(|v| v.parse::<f64>().ok())
    };
    tests::wait_until(
        "the data folder metric",
        Duration::from_secs(30),
        || measured().is_some_and(|bytes| bytes > 0.0),
        || farm.logs(),
    );

    farm.start_worker("w", 2);
    let scene = farm.demo_scene();
    let mut args = vec![scene.to_str().unwrap(), "--frames", "1"];
    args.extend(settings("1"));
    let old = farm.submit(&args);
    farm.wait_for_job(old, Duration::from_secs(120));
    let newer = farm.submit(&args);
    farm.wait_for_job(newer, Duration::from_secs(120));
    // A job with work left: paused before it can finish (30 frames).
    let mut long = vec![scene.to_str().unwrap(), "--frames", "1-30"];
    long.extend(settings("1"));
    let open = farm.submit(&long);
    farm.client(&["pause", &open.to_string()]);
    let jobs_dir = farm.data_dir().join("jobs");

    let out = farm.client(&["gc", "--dry-run"]);
    assert!(
        out.starts_with("would remove 1 finished job(s) (kept: 1), 0 unused scene(s)")
            && out.contains(&format!("  job {old} `job {old}`")),
        "{out}"
    );
    assert!(jobs_dir.join(old.to_string()).is_dir());

    let out = farm.client(&["gc"]);
    assert!(
        out.starts_with("removed 1 finished job(s) (kept: 1)"),
        "{out}"
    );
    assert_eq!(
        http::get(farm.port, &format!("/api/v1/jobs/{old}")).status,
        404
    );
    assert!(!jobs_dir.join(old.to_string()).exists());
    assert!(jobs_dir.join(newer.to_string()).is_dir());

    // Keeping none: the finished one goes, the paused one with work left stays.
    let out = farm.client(&["gc", "--keep-jobs", "0"]);
    assert!(
        out.contains(&format!("  job {newer} `job {newer}`")),
        "{out}"
    );
    let st = farm.job(open);
    assert_eq!(st.state, JobState::Paused, "{st:?}");
    let log = farm.client(&["logs", &open.to_string()]);
    assert!(log.contains("job_created"), "{log}");
    let bad = tests::tessera(
        &["gc", "--keep-jobs", "soon", "--server", &farm.url()],
        farm.path(),
    );
    let err = String::from_utf8_lossy(&bad.stderr);
    assert!(
        !bad.status.success() && err.contains("`soon`: expected"),
        "{err}"
    );
}

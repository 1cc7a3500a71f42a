//! The disk under the server's data folder fills up mid-job: uploads are answered 507
//! (the worker backs off and tries again), the server keeps answering, no half-written
//! file is left as a frame, and once space returns the job finishes by itself with every
//! frame equal to a direct `tessera render`.

use std::fs;
use std::path::Path;
use std::time::{Duration, Instant};

use proto::{JobList, JobSpec, JobState, JobStatus};
use tests::http::{self, Answer, Request};
use tests::{render_directly, settings, Farm, FRAMES};

/// The data folder's disk: room for the scene, the database (its WAL grows to about
/// 4 MiB before a checkpoint) and the frames, so only the filler makes it full.
const DISK_BYTES: u64 = 16 << 20;
/// Long enough that the lease held across the full-disk spell does not expire: the test
/// is about space, not about leases.
const LEASE_SECONDS: u64 = 30;
const SPP: &str = "16";

/// Every `frame_*.exr` of the job folders reads as a whole 32x24 frame, and no temp file
/// (a dot file) is left in the job or tile folders; returns how many frames there are.
fn frames_are_whole(data: &Path) -> usize {
    let mut frames = 0;
    for area in ["jobs", "tiles"] {
        let Ok(jobs) = fs::read_dir(data.join(area)) else {
            continue;
        };
        for job in jobs.flatten() {
            for file in fs::read_dir(job.path()).unwrap().flatten() {
                let name = file.file_name().to_string_lossy().into_owned();
                assert!(!name.starts_with('.'), "a temp file is left: {area}/{name}");
                if area == "jobs" && name.starts_with("frame_") && name.ends_with(".exr") {
                    let image = tracer::output::read_exr(&file.path())
                        .unwrap_or_else(|e| panic!("{name} is not a whole frame: {e}"));
                    let rect = image.layers.rect;
                    assert_eq!((rect.width, rect.height), (32, 24), "{name}");
                    frames += 1;
                }
            }
        }
    }
    frames
}

fn post_job(farm: &Farm, spec: &JobSpec) -> Answer {
    Request {
        method: "POST",
        path: "/api/v1/jobs",
        headers: vec![("Content-Type".into(), "application/json".into())],
        body: &serde_json::to_vec(spec).unwrap(),
    }
    .send(farm.port)
}

#[test]
fn a_full_disk_answers_507_and_the_job_finishes_once_space_returns() {
    let started = Instant::now();
    let mut farm = Farm::new();
    if let Err(why) = farm.use_small_disk(DISK_BYTES) {
        eprintln!("SKIPPED: this machine cannot give the server a small disk of its own: {why}");
        return;
    }
    farm.start_server(LEASE_SECONDS);
    let scene = farm.demo_scene();
    let mut args = vec![scene.to_str().unwrap(), "--frames", "1-1"];
    args.extend(settings(SPP));
    let first = farm.submit(&args);
    let w = farm.start_worker("worker", 2);
    let st = farm.wait_for_job(first, Duration::from_secs(120));
    assert_eq!(st.state, JobState::Done, "{st:?}");

    // The worker idles in a long poll; stopped, it takes the next job's first lease but
    // can upload nothing before the disk is full.
    farm.workers[w].signal(libc::SIGSTOP);
    let mut args = vec![scene.to_str().unwrap(), "--frames", FRAMES];
    args.extend(settings(SPP));
    let job = farm.submit(&args);
    let data = farm.data_dir();
    let filled = farm.fill_disk("filler");
    farm.workers[w].signal(libc::SIGCONT);

    let full_since = Instant::now();
    // The worker's next lease, taken while the tile uploads, may be refused with 507 too
    // (granting it writes to the database); what matters is the upload's.
    let refused_uploads = |log: &str| -> Vec<String> {
        log.lines()
            .filter(|l| l.contains("upload:") && l.contains("answered 507"))
            .map(str::to_string)
            .collect()
    };
    tests::wait_until(
        "uploads to be refused twice with 507",
        Duration::from_secs(60),
        || refused_uploads(&farm.workers[w].log()).len() >= 2,
        || farm.logs(),
    );
    let refused = &refused_uploads(&farm.workers[w].log())[0];
    assert!(refused.contains("the server's disk is full"), "{refused}");
    assert!(farm.server.as_mut().unwrap().running(), "{}", farm.logs());
    let health = http::get(farm.port, "/healthz");
    assert_eq!(health.status, 200, "{}", health.text());
    assert_eq!(
        frames_are_whole(&data),
        1,
        "only the first job's frame is in"
    );
    assert_eq!(farm.job(job).tasks.done, 0);
    // A job is many rows in one SQLite transaction: SQLITE_FULL rolls all of it back.
    let spec = st.spec;
    let refused = post_job(&farm, &spec);
    assert_eq!(refused.status, 507, "{}", refused.text());
    let err = refused.error();
    assert_eq!(err.error, "storage_full");
    assert!(
        err.message.starts_with("the server's disk is full"),
        "{err:?}"
    );

    let full_for = full_since.elapsed();
    fs::remove_file(data.join("filler")).unwrap();
    let st = farm.wait_for_job(job, Duration::from_secs(120));
    assert_eq!(st.state, JobState::Done, "{st:?}");
    assert_eq!((st.tasks.done, st.tasks.failed), (4, 0), "{st:?}");
    let log = farm.workers[w].log();
    assert!(log.contains("answers again"), "{log}");
    let jobs: JobList = http::get(farm.port, "/api/v1/jobs").json();
    assert_eq!(jobs.jobs.len(), 2, "the refused job left a trace: {jobs:?}");
    // The same request succeeds now that there is room.
    let again = post_job(&farm, &spec);
    assert_eq!(again.status, 201, "{}", again.text());
    let third = again.json::<JobStatus>().id;
    let st3 = farm.wait_for_job(third, Duration::from_secs(120));
    assert_eq!(st3.state, JobState::Done, "{st3:?}");
    assert_eq!(frames_are_whole(&data), 1 + 4 + 1);
    eprintln!(
        "disk full ({filled} bytes of filler) for {:.1} s: {} uploads and 1 job answered \
         507; all done {:.1} s after the test began",
        full_for.as_secs_f64(),
        log.matches("answered 507").count(),
        started.elapsed().as_secs_f64()
    );

    let direct: Vec<_> = (1..=4)
        .map(|f| render_directly(&scene, f, SPP, farm.path()))
        .collect();
    for other in [first, third] {
        assert!(
            farm.server_frame(other, 1) == direct[0],
            "job {other} frame 1 differs"
        );
    }
    for frame in 1..=4 {
        assert!(
            farm.server_frame(job, frame) == direct[frame as usize - 1],
            "frame {frame} differs from tessera render"
        );
    }
}

//! The soak: a farm that runs for a long time (`TESSERA_SOAK_SECONDS`, default 1800)
//! while faults are injected at random: workers killed with SIGKILL and started again,
//! workers stalled (SIGSTOP) past their lease and let go, the server killed with SIGKILL
//! and started again, the server's disk filled for a while (its data folder is on a small
//! tmpfs of its own). Jobs keep coming the whole time. At the end every frame of every
//! job must equal a direct `tessera render` of it bit for bit, and no task may have been
//! leased again after its tile was accepted. Not part of CI: `scripts/soak.sh` runs it
//! (ignored here) and prints the figures RELIABILITY.md records.

use std::collections::BTreeMap;
use std::time::{Duration, Instant};

use proto::JobState;
use tests::{job_id_in, render_directly, settings, tessera, Farm};

/// Leases are short, so a killed or stalled worker's tile goes back to the queue soon.
const LEASE_SECONDS: u64 = 6;
const WORKERS: usize = 3;
/// The server's disk: room for every job a long soak submits, filled now and then.
const DISK_BYTES: u64 = 512 << 20;

#[derive(Debug, Default)]
struct Figures {
    jobs: u64,
    frames: u64,
    workers_killed: u64,
    workers_stalled: u64,
    servers_killed: u64,
    disks_filled: u64,
    submissions_refused: u64,
    /// Faults that found a worker holding a lease.
    faults_on_leases: u64,
}

#[test]
#[ignore = "a long run: scripts/soak.sh"]
fn a_farm_under_random_faults_loses_nothing_and_renders_nothing_twice() {
    let seconds: u64 = std::env::var("TESSERA_SOAK_SECONDS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(1800);
    let seed: u64 = std::env::var("TESSERA_SOAK_SEED")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| fastrand::u64(..));
    // Samples per pixel: more makes each tile take longer, so more faults hit a worker
    // holding a lease.
    let spp = std::env::var("TESSERA_SOAK_SPP").unwrap_or_else(|_| "64".into());
    let spp = spp.as_str();
    println!("soak: {seconds} s, {spp} spp, TESSERA_SOAK_SEED={seed}");
    let mut rng = fastrand::Rng::with_seed(seed);

    let mut farm = Farm::new();
    let disk_faults = match farm.use_small_disk(DISK_BYTES) {
        Ok(()) => true,
        Err(why) => {
            eprintln!(
                "SKIPPED FAULT: no full-disk faults in this soak, this machine cannot give \
                 the server a small disk of its own: {why}"
            );
            false
        }
    };
    farm.start_server(LEASE_SECONDS);
    let names: Vec<String> = (1..=WORKERS).map(|k| format!("soak-{k}")).collect();
    // Which process in `farm.workers` is each worker now.
    let mut current: BTreeMap<String, usize> = BTreeMap::new();
    for name in &names {
        current.insert(name.clone(), farm.start_worker(name, 1));
    }
    let scene = farm.demo_scene();
    let scene_arg = scene.to_str().unwrap().to_string();

    let mut figures = Figures::default();
    let mut jobs: Vec<(u64, i32, i32)> = Vec::new();
    let started = Instant::now();
    let until = started + Duration::from_secs(seconds);
    let mut next_job = Instant::now();
    let mut next_fault = Instant::now() + Duration::from_secs(5);
    while Instant::now() < until {
        if Instant::now() >= next_job {
            let first = rng.i32(1..=20);
            let last = first + rng.i32(0..4);
            let frames = format!("{first}-{last}");
            let tile = ["8", "16", "32"][rng.usize(..3)];
            let url = farm.url();
            let mut args = vec![
                "submit",
                scene_arg.as_str(),
                "--server",
                url.as_str(),
                "--frames",
                frames.as_str(),
                "--tile",
                tile,
                "--passes",
                "1",
            ];
            args.extend(settings(spp));
            let out = tessera(&args, farm.path());
            match job_id_in(&String::from_utf8_lossy(&out.stdout)) {
                Some(id) if out.status.success() => {
                    jobs.push((id, first, last));
                    figures.jobs += 1;
                    figures.frames += (last - first + 1) as u64;
                }
                // The server may be down this moment: the user tries again later.
                _ => figures.submissions_refused += 1,
            }
            next_job = Instant::now() + Duration::from_secs(rng.u64(5..20));
        }
        if Instant::now() >= next_fault {
            // The worker a fault hits: one holding a lease when there is one, so that the
            // fault lands mid-tile rather than on a worker waiting for work.
            let busy: Vec<String> = farm
                .worker_list()
                .workers
                .into_iter()
                .filter(|w| w.online && w.current_task.is_some())
                .map(|w| w.name)
                .filter(|n| names.contains(n))
                .collect();
            let victim = if busy.is_empty() {
                names[rng.usize(..names.len())].clone()
            } else {
                busy[rng.usize(..busy.len())].clone()
            };
            figures.faults_on_leases += u64::from(!busy.is_empty());
            match rng.u8(..10) {
                0..=3 => {
                    let name = victim;
                    farm.workers[current[&name]].kill9();
                    std::thread::sleep(Duration::from_millis(rng.u64(0..3000)));
                    current.insert(name.clone(), farm.start_worker(&name, 1));
                    figures.workers_killed += 1;
                }
                4..=6 => {
                    let worker = &farm.workers[current[&victim]];
                    worker.signal(libc::SIGSTOP);
                    // Past its lease sometimes, so the tile goes to another worker and the
                    // stalled one's upload comes late.
                    std::thread::sleep(Duration::from_secs(rng.u64(1..(2 * LEASE_SECONDS))));
                    worker.signal(libc::SIGCONT);
                    figures.workers_stalled += 1;
                }
                9 if disk_faults => {
                    // Uploads, leases and submissions meet ENOSPC or SQLITE_FULL (507)
                    // for a while; then the space comes back.
                    farm.fill_disk("soak-filler");
                    std::thread::sleep(Duration::from_secs(rng.u64(2..20)));
                    std::fs::remove_file(farm.data_dir().join("soak-filler")).unwrap();
                    figures.disks_filled += 1;
                }
                _ => {
                    farm.server.as_mut().expect("the server runs").kill9();
                    std::thread::sleep(Duration::from_millis(rng.u64(0..3000)));
                    farm.start_server_with(LEASE_SECONDS, &[]);
                    figures.servers_killed += 1;
                }
            }
            next_fault = Instant::now() + Duration::from_secs(rng.u64(3..15));
        }
        std::thread::sleep(Duration::from_millis(200));
    }

    // Faults stop; every job must finish.
    for &(id, _, _) in &jobs {
        let st = farm.wait_for_job(id, Duration::from_secs(600));
        assert_eq!(
            st.state,
            JobState::Done,
            "job {id}: {st:?}\n{}",
            farm.logs()
        );
    }
    let mut direct = BTreeMap::new();
    for &(id, first, last) in &jobs {
        for frame in first..=last {
            let want = direct
                .entry(frame)
                .or_insert_with(|| render_directly(&scene, frame, spp, farm.path()));
            assert!(
                farm.server_frame(id, frame) == *want,
                "job {id} frame {frame} differs from tessera render"
            );
        }
    }
    // The server stopped (nothing writes while the database is copied), then a copy:
    // SQLite resolves the symbolic link `/proc/<pid>/root` of a small disk's path,
    // which would open an empty file in this process's own namespace instead.
    farm.server.as_mut().expect("the server runs").kill9();
    let copy = farm.path().join("database-copy");
    std::fs::create_dir_all(&copy).unwrap();
    for file in ["tessera.db", "tessera.db-wal"] {
        let from = farm.data_dir().join(file);
        if from.exists() {
            std::fs::copy(&from, copy.join(file)).unwrap();
        }
    }
    let db = rusqlite::Connection::open(copy.join("tessera.db")).unwrap();
    let (tasks, leased_after_done): (u64, u64) = db
        .query_row(
            "SELECT count(*), coalesce(sum(leased_ms > done_ms), 0) FROM tasks
             WHERE state = 'done'",
            [],
            |r| Ok((r.get(0)?, r.get(1)?)),
        )
        .unwrap();
    assert_eq!(
        leased_after_done, 0,
        "a task was leased after its tile was accepted"
    );
    let expired: u64 = db
        .query_row("SELECT coalesce(sum(failures), 0) FROM tasks", [], |r| {
            r.get(0)
        })
        .unwrap();
    println!(
        "soak done in {:.0} s (seed {seed}, {spp} spp): {} jobs, {} frames, {tasks} tasks ({expired} \
         attempts lost to faults); faults: {} workers killed, {} workers stalled, {} server \
         kills, {} full disks ({} of the faults while a worker held a lease); {} submissions \
         refused while the server was down or its disk full; frames lost: 0, frames different from a direct render: 0, tasks \
         leased after acceptance: 0",
        started.elapsed().as_secs_f64(),
        figures.jobs,
        figures.frames,
        figures.workers_killed,
        figures.workers_stalled,
        figures.servers_killed,
        figures.disks_filled,
        figures.faults_on_leases,
        figures.submissions_refused,
    );
}

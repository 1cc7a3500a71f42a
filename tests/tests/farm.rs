//! The whole farm as a user runs it: `tessera server`, `tessera worker` processes and the
//! client commands on 127.0.0.1, rendering the built-in animated demo exported as a GLB.

use std::path::Path;
use std::time::Duration;

use proto::JobState;
use tests::{render_directly, settings, tessera_ok, Farm, FRAMES};
use tracer::film::Layers;
use tracer::output::read_exr;

fn assert_close(what: &str, a: &[f32], b: &[f32], tolerance: f32) {
    assert_eq!(a.len(), b.len(), "{what}: sizes differ");
    for (i, (x, y)) in a.iter().zip(b).enumerate() {
        assert!(
            (x - y).abs() <= tolerance * x.abs().max(y.abs()).max(1.0),
            "{what}[{i}]: {x} vs {y}"
        );
    }
}

fn flat(layers: &Layers) -> (Vec<f32>, Vec<f32>) {
    let beauty = layers.beauty.iter().flat_map(|v| v.to_array()).collect();
    let albedo = layers.albedo.iter().flat_map(|v| v.to_array()).collect();
    (beauty, albedo)
}

/// A server, two one-thread workers, and the animated demo scene's GLB path.
fn two_worker_farm() -> (Farm, String) {
    let mut farm = Farm::new();
    farm.start_server(60);
    farm.start_worker("w1", 1);
    farm.start_worker("w2", 1);
    let scene = farm.demo_scene().to_str().unwrap().to_string();
    (farm, scene)
}

#[test]
fn two_workers_render_every_frame_as_tessera_render_does() {
    let (farm, scene) = two_worker_farm();
    let scene = scene.as_str();

    // One sample pass: tiles only, so every frame must be bit-identical.
    let mut args = vec![scene, "--frames", FRAMES, "--tile", "16", "--passes", "1"];
    args.extend(settings("4"));
    args.extend(["--wait", "--out", "tiles"]);
    let tiles_job = farm.submit(&args);
    // Two sample passes merged by sample weight: equal within float rounding.
    let mut args = vec![scene, "--frames", FRAMES, "--tile", "16", "--passes", "2"];
    args.extend(settings("4"));
    args.extend(["--wait", "--out", "passes"]);
    let passes_job = farm.submit(&args);

    for job in [tiles_job, passes_job] {
        let st = farm.job(job);
        assert_eq!(st.state, JobState::Done, "job {job}: {st:?}");
        assert_eq!((st.frames_done, st.frames_total), (4, 4));
    }
    // Both workers took part.
    let workers = farm.worker_list().workers;
    assert_eq!(workers.len(), 2);
    assert!(
        workers.iter().all(|w| w.tasks_done > 0),
        "a worker stayed idle: {workers:?}"
    );

    for frame in 1..=4 {
        let direct = render_directly(Path::new(scene), frame, "4", farm.path());
        let name = proto::job::frame_file_name(frame, 4, "exr");
        let tiled = read_exr(&farm.path().join("tiles").join(&name)).unwrap();
        assert_eq!(tiled.frame_size, (32, 24));
        assert!(
            tiled.layers == direct,
            "frame {frame}: the tiled farm render differs from tessera render"
        );
        let merged = read_exr(&farm.path().join("passes").join(&name)).unwrap();
        let (b0, a0) = flat(&direct);
        let (b1, a1) = flat(&merged.layers);
        assert_close(&format!("frame {frame} beauty"), &b0, &b1, 1e-5);
        assert_close(&format!("frame {frame} albedo"), &a0, &a1, 1e-5);
        assert!(
            farm.path()
                .join("passes")
                .join(proto::job::frame_file_name(frame, 4, "png"))
                .exists(),
            "the PNG preview of frame {frame} was downloaded"
        );
    }
}

/// The spectral showcase, exported by `tessera render --builtin fluorescence --export-glb`,
/// renders on the farm as `tessera render` renders it, bit for bit: frame 23 under the
/// white light, frame 24 after the switch to ultraviolet, darker and green.
#[test]
fn the_spectral_showcase_renders_on_the_farm_as_tessera_render_does() {
    let (farm, _) = two_worker_farm();
    let glb = farm.path().join("showcase.glb");
    let glb_arg = glb.to_str().unwrap();
    tessera_ok(
        &[
            "render",
            "--builtin",
            "fluorescence",
            "--export-glb",
            glb_arg,
        ],
        farm.path(),
    );
    let mut args = vec![
        glb_arg, "--frames", "23-24", "--tile", "16", "--passes", "1",
    ];
    args.extend(settings("4"));
    args.extend(["--wait", "--out", "showcase"]);
    let job = farm.submit(&args);
    assert_eq!(farm.job(job).state, JobState::Done);
    let mut means = Vec::new();
    for frame in [23, 24] {
        let direct = render_directly(&glb, frame, "4", farm.path());
        let name = proto::job::frame_file_name(frame, 24, "exr");
        let tiled = read_exr(&farm.path().join("showcase").join(&name)).unwrap();
        assert!(
            tiled.layers == direct,
            "frame {frame}: the farm's showcase differs from tessera render"
        );
        let sum: glam::Vec4 = direct.beauty.iter().sum();
        let brightest = direct
            .beauty
            .iter()
            .copied()
            .fold(glam::Vec4::ZERO, |a, b| if b.y > a.y { b } else { a });
        means.push((sum / direct.beauty.len() as f32, brightest));
    }
    let ((white, _), (uv, glow)) = (means[0], means[1]);
    assert!(
        uv.y < 0.1 * white.y,
        "the room goes dark: {white} then {uv}"
    );
    assert!(
        glow.y > glow.x && glow.y > glow.z,
        "and what glows is green: {glow}"
    );
}

#[test]
fn a_worker_started_before_the_server_waits_and_then_works() {
    let mut farm = Farm::new();
    let w = farm.start_worker("early", 1);
    // The worker retries against a port nothing listens on yet.
    std::thread::sleep(Duration::from_millis(1500));
    assert!(farm.workers[w].running(), "{}", farm.workers[w].log());
    farm.start_server(60);
    let scene = farm.demo_scene();
    let mut args = vec![scene.to_str().unwrap(), "--frames", "1-2", "--tile", "16"];
    args.extend(settings("2"));
    let job = farm.submit(&args);
    let st = farm.wait_for_job(job, Duration::from_secs(120));
    assert_eq!(st.state, JobState::Done, "{st:?}");
    let log = farm.workers[w].log();
    assert!(
        log.contains("unreachable"),
        "the worker said it waited:\n{log}"
    );
}

#[test]
fn sigterm_mid_task_gives_the_lease_back_and_loses_nothing() {
    let mut farm = Farm::new();
    farm.start_server(60);
    let scene = farm.demo_scene();
    // Enough samples per task that the worker is caught mid-render.
    let mut args = vec![scene.to_str().unwrap(), "--frames", "1-2", "--tile", "32"];
    args.extend(settings("512"));
    let job = farm.submit(&args);
    let w = farm.start_worker("stopping", 1);
    tests::wait_until(
        "the worker to hold a lease",
        Duration::from_secs(60),
        || farm.job(job).tasks.leased == 1,
        || farm.logs(),
    );
    let status = farm.workers[w].terminate(Duration::from_secs(20));
    assert!(status.success(), "SIGTERM exits 0: {status}");
    // The lease went back at once, not after the 60 s lease period.
    let st = farm.job(job);
    assert_eq!(st.tasks.leased, 0, "{st:?}");
    assert_eq!(st.tasks.failed, 0);

    farm.start_worker("finisher", 2);
    let st = farm.wait_for_job(job, Duration::from_secs(300));
    assert_eq!(st.state, JobState::Done, "{st:?}");
    assert_eq!(st.frames_done, 2);
}

#[test]
fn kill_9_of_the_server_mid_job_keeps_accepted_tiles_and_finishes() {
    let mut farm = Farm::new();
    farm.start_server(60);
    let scene = farm.demo_scene();
    let mut args = vec![scene.to_str().unwrap(), "--frames", "1-4", "--tile", "8"];
    args.extend(settings("256"));
    let job = farm.submit(&args);
    farm.start_worker("survivor", 1);
    tests::wait_until(
        "some tiles to be done",
        Duration::from_secs(120),
        || farm.job(job).tasks.done >= 6,
        || farm.logs(),
    );
    let before = farm.job(job).tasks;
    farm.server.as_mut().unwrap().kill9();
    let done_before = before.done;
    assert!(done_before < before.total(), "killed mid-job: {before:?}");
    // The worker uploads one tile while it renders the next, so up to two leases are open
    // at the kill; the restart revokes them, and only they may be rendered again.
    let db_path = farm.path().join("data").join("tessera.db");
    let leased_at_kill: u64 = rusqlite::Connection::open(&db_path)
        .unwrap()
        .query_row(
            "SELECT count(*) FROM tasks WHERE job_id = ?1 AND state = 'leased'",
            [job],
            |r| r.get(0),
        )
        .unwrap();
    assert!(
        leased_at_kill <= 2,
        "one single-threaded worker holds at most two leases, {leased_at_kill} were open"
    );

    // The worker keeps retrying; a new server on the same data takes the job up again.
    std::thread::sleep(Duration::from_millis(500));
    farm.start_server(60);
    let after_restart = farm.job(job);
    assert!(
        after_restart.tasks.done >= done_before,
        "accepted tiles survive: {} before, {} after",
        done_before,
        after_restart.tasks.done
    );
    let st = farm.wait_for_job(job, Duration::from_secs(300));
    assert_eq!(st.state, JobState::Done, "{st:?}");
    assert_eq!(st.frames_done, 4);
    let frames = farm.client(&["status", &job.to_string()]);
    assert!(frames.contains("done"), "{frames}");
    // No tile accepted before the kill was rendered again: a task leased once has attempt 1.
    let db = rusqlite::Connection::open(&db_path).unwrap();
    let again: u64 = db
        .query_row(
            "SELECT count(*) FROM tasks WHERE job_id = ?1 AND attempt > 1",
            [job],
            |r| r.get(0),
        )
        .unwrap();
    assert!(
        again <= leased_at_kill,
        "only the {leased_at_kill} tasks leased at the kill may be rendered again, {again} were"
    );
}

#[test]
fn tessera_demo_runs_a_farm_and_leaves_frames_and_nothing_running() {
    let dir = tempfile::tempdir().unwrap();
    let demo = [
        "demo",
        "--workers",
        "2",
        "--frames",
        "1-2",
        "--size",
        "32x24",
        "--spp",
        "2",
        "--dir",
        "demo",
    ];
    // Run twice in the same folder: the second run reuses it without piling up jobs or
    // workers.
    tessera_ok(&demo, dir.path());
    let out = tessera_ok(&demo, dir.path());
    let db = rusqlite::Connection::open(dir.path().join("demo/data/tessera.db")).unwrap();
    let count = |table: &str| -> i64 {
        db.query_row(&format!("SELECT count(*) FROM {table}"), [], |r| r.get(0))
            .unwrap()
    };
    assert_eq!((count("jobs"), count("workers")), (1, 2));
    assert!(
        out.contains("http://127.0.0.1:"),
        "the dashboard URL: {out}"
    );
    let frames = dir.path().join("demo").join("frames");
    for frame in 1..=2 {
        let exr = read_exr(&frames.join(proto::job::frame_file_name(frame, 2, "exr"))).unwrap();
        assert_eq!(exr.frame_size, (32, 24));
        assert!(frames
            .join(proto::job::frame_file_name(frame, 2, "png"))
            .exists());
    }
    // Both workers were stopped by the demo and said goodbye to the server.
    for k in 1..=2 {
        let log = std::fs::read_to_string(
            dir.path()
                .join("demo")
                .join("logs")
                .join(format!("worker-{k}.log")),
        )
        .unwrap();
        assert!(log.contains("left"), "worker {k} left the farm:\n{log}");
    }
}

#[test]
fn json_logs_name_the_request_and_the_task_on_every_line_about_them() {
    let mut farm = Farm::new();
    farm.start_server_with(60, &["--log-format", "json"]);
    let scene = farm.demo_scene();
    // One task (one frame, one tile), which the worker fails at once: no render, and a
    // line about the task on both sides.
    let mut args = vec![scene.to_str().unwrap(), "--frames", "1", "--tile", "32"];
    args.extend(settings("1"));
    let job = farm.submit(&args);
    let fault = format!("fail-job={job}");
    let w = farm.start_worker_with(
        "json",
        1,
        &["--log-format", "json", "--inject-fault", &fault],
    );
    let server_log = || farm.server.as_ref().unwrap().log();
    tests::wait_until(
        "the server to log the failed task",
        Duration::from_secs(60),
        || server_log().contains("failed task"),
        || farm.logs(),
    );
    let status = farm.workers[w].terminate(Duration::from_secs(20));
    assert!(status.success(), "{status}");

    // Every line is a JSON object; `span(line, name)` is one of its enclosing spans.
    let lines = |log: String| -> Vec<serde_json::Value> {
        log.lines()
            .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("{e}: {l}")))
            .collect()
    };
    let span = |line: &serde_json::Value, name: &str| -> serde_json::Value {
        let spans = line["spans"].as_array().cloned().unwrap_or_default();
        let found = spans.into_iter().find(|s| s["name"] == name);
        found.unwrap_or_else(|| panic!("no `{name}` span in {line}"))
    };
    let find = |lines: &[serde_json::Value], text: &str| -> serde_json::Value {
        let found = lines
            .iter()
            .find(|l| l["message"].as_str().is_some_and(|m| m.contains(text)));
        found
            .cloned()
            .unwrap_or_else(|| panic!("no line with `{text}` in {lines:#?}"))
    };

    let worker = lines(farm.workers[w].log());
    let lease = span(&find(&worker, "lease taken"), "task");
    assert_eq!(lease["job"].as_u64(), Some(job), "{lease}");
    assert_eq!(lease["attempt"].as_u64(), Some(1), "{lease}");
    let task = lease["id"].as_u64().expect("a task id");
    let failed = span(&find(&worker, "injected fault"), "task");
    assert_eq!(failed["id"].as_u64(), Some(task), "{failed}");

    let server = lines(server_log());
    let registered = span(&find(&server, "registered"), "request");
    let failure = find(&server, "failed task");
    let request = span(&failure, "request");
    assert_eq!(
        span(&failure, "task")["id"].as_u64(),
        Some(task),
        "{failure}"
    );
    let ids = [&registered, &request].map(|s| s["request_id"].as_str().unwrap_or_default());
    // UUIDs, one per request.
    assert!(ids.iter().all(|id| id.len() == 36), "{ids:?}");
    assert_ne!(ids[0], ids[1]);
}

/// The seconds a time-budget job may run past its budget: the last tasks are planned on
/// measured speeds, and CI's two cores are shared with the other tests.
const BUDGET_MARGIN_MS: i64 = 2_000;

/// "Frames 1-4 within 20 seconds on the workers I have": the job ends inside the budget
/// (plus [`BUDGET_MARGIN_MS`]) with every frame present and finite, and a smaller budget
/// on the same job reaches fewer samples.
#[test]
fn a_time_budget_job_ends_in_time_with_every_frame_and_more_time_buys_more_samples() {
    let (farm, scene) = two_worker_farm();
    let scene = scene.as_str();
    let mut reached = Vec::new();
    for budget in ["8", "20"] {
        // An spp cap the farm cannot reach in the budget: the clock decides.
        let mut args = vec![scene, "--frames", FRAMES, "--tile", "16"];
        args.extend(settings("65536"));
        let out = format!("budget-{budget}");
        args.extend(["--time-budget", budget, "--wait", "--out", &out]);
        let job = farm.submit(&args);
        let (st, frames) = farm.job_and_frames(job);
        assert_eq!(st.state, JobState::Done, "{st:?}");
        let took = st.finished_ms.unwrap() - st.created_ms;
        let budget_ms = budget.parse::<i64>().unwrap() * 1000;
        let plan = st.budget.clone().unwrap();
        eprintln!("budget {budget} s: took {took} ms; {plan:?}; frames {frames:?}");
        assert!(
            took <= budget_ms + BUDGET_MARGIN_MS,
            "a {budget} s budget took {took} ms: {plan:?}\n{}",
            farm.logs()
        );
        assert!(plan.passes_added > 0, "{plan:?}");
        let mut spp = 0.0;
        for f in &frames {
            let image = read_exr(&farm.path().join(&out).join(&f.file)).unwrap();
            let samples = &image.layers.samples;
            assert!(samples.iter().all(|&s| s >= 4.0), "frame {}", f.frame);
            let (beauty, albedo) = flat(&image.layers);
            assert!(beauty.iter().chain(&albedo).all(|v| v.is_finite()));
            let mean = samples.iter().sum::<f32>() as f64 / samples.len() as f64;
            assert_eq!(f.spp_mean, Some(mean), "frame {}", f.frame);
            spp += mean / frames.len() as f64;
        }
        assert_eq!(frames.len(), 4);
        reached.push(spp);
    }
    assert!(
        reached[1] > 1.5 * reached[0],
        "20 s reached {} spp on average, 8 s {}",
        reached[1],
        reached[0]
    );
}

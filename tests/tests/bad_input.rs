//! Bad input at a real farm with tokens: each request is refused with an error that names
//! the problem, nothing is created, and the farm goes on to render a good job exactly.

use std::path::Path;
use std::time::Duration;

use proto::JobState;
use tests::{render_directly, settings, tessera, Farm};

const WORKER_TOKEN: &str = "worker-secret";
const CLIENT_TOKEN: &str = "client-secret";

/// Runs a client command with `--server` and the given token; asserts it fails with
/// `expected` in its error output, and returns that output.
fn refused(farm: &Farm, args: &[&str], token: Option<&str>, expected: &str) -> String {
    let url = farm.url();
    let mut all = args.to_vec();
    all.extend(["--server", url.as_str()]);
    if let Some(t) = token {
        all.extend(["--token", t]);
    }
    let out = tessera(&all, farm.path());
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(!out.status.success(), "tessera {} succeeded", all.join(" "));
    assert!(
        stderr.contains(expected) && !stderr.contains("panicked"),
        "tessera {}: expected `{expected}` in:\n{stderr}",
        all.join(" ")
    );
    stderr
}

#[test]
fn bad_tokens_scenes_and_specs_are_refused_and_the_farm_goes_on() {
    let mut farm = Farm::new();
    farm.client_token = Some(CLIENT_TOKEN.into());
    farm.start_server_with(
        60,
        &[
            "--worker-token",
            WORKER_TOKEN,
            "--client-token",
            CLIENT_TOKEN,
            "--max-tasks-per-job",
            "1000",
        ],
    );
    let scene = farm.demo_scene();
    let demo = scene.to_str().unwrap();

    // Auth: no token, the wrong token, the worker's token on a client route.
    refused(&farm, &["status"], None, "401");
    refused(&farm, &["status"], Some("guess"), "401");
    refused(&farm, &["submit", demo], Some(WORKER_TOKEN), "401");
    // The client's token on the worker routes: the worker stops and says why.
    let w = farm.start_worker_with("wrong-token", 1, &["--token", CLIENT_TOKEN]);
    let status = farm.workers[w].wait(Duration::from_secs(30));
    assert!(!status.success());
    assert!(
        farm.workers[w].log().contains("token"),
        "{}",
        farm.workers[w].log()
    );

    // Scenes: not glTF at all, a truncated GLB.
    std::fs::write(farm.path().join("notes.glb"), b"these are not the frames").unwrap();
    refused(
        &farm,
        &["submit", "notes.glb"],
        Some(CLIENT_TOKEN),
        "not a glTF",
    );
    let glb = std::fs::read(&scene).unwrap();
    std::fs::write(farm.path().join("cut.glb"), &glb[..glb.len() / 2]).unwrap();
    refused(
        &farm,
        &["submit", "cut.glb"],
        Some(CLIENT_TOKEN),
        "truncated",
    );

    // Job specs: each error names the field.
    for (flags, field) in [
        (&["--spp", "0"][..], "spp"),
        (&["--spp", "2000000"], "spp"),
        (&["--camera", "7"], "camera"),
        (&["--animation", "nope"], "animation"),
        (&["--frames=-5-1"], "frames.start"),
        (&["--tile", "4"], "tile_size"),
        (
            &["--frames", "1-100", "--tile", "8", "--size", "64x64"],
            "tasks",
        ),
        (&["--frames", "5-1"], "frames"),
        (&["--size", "0x10"], "size"),
    ] {
        let mut args = vec!["submit", demo];
        args.extend(flags);
        refused(&farm, &args, Some(CLIENT_TOKEN), field);
    }

    // Nothing was created, and the farm renders a good job (a tile larger than the image
    // is one tile per frame) exactly as tessera render does.
    let jobs = farm.client(&["status", "--json"]);
    let jobs: proto::JobList = serde_json::from_str(&jobs).unwrap();
    assert!(jobs.jobs.is_empty(), "{jobs:?}");
    farm.start_worker_with("good", 2, &["--token", WORKER_TOKEN]);
    let mut args = vec![demo, "--frames", "1-2", "--tile", "64"];
    args.extend(settings("2"));
    let job = farm.submit(&args);
    let st = farm.wait_for_job(job, Duration::from_secs(120));
    assert_eq!(st.state, JobState::Done, "{st:?}");
    for frame in 1..=2 {
        let direct = render_directly(Path::new(demo), frame, "2", farm.path());
        assert!(farm.server_frame(job, frame) == direct, "frame {frame}");
    }
}

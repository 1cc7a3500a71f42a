//! Arbitrary bytes as the JSON body of `POST /api/v1/jobs`, through what the route does
//! with them: serde into `proto::JobSpec` (axum's `Json` extractor, under the route's body
//! limit), then `server::spec::plan` against a fixed scene summary and the default task
//! limit. A refusal is fine; a panic, a hang or a large allocation is a finding (the
//! task-limit check must come before anything proportional to the task count is built).
//! An accepted plan must also hold together: tiles cover the frame, passes cover the
//! samples, and the spec reads back from the JSON the scheduler stores.
#![no_main]

use libfuzzer_sys::fuzz_target;
use proto::{AnimationInfo, CameraInfo, JobSpec, SceneInfo};
use server::limits::{DEFAULT_MAX_TASKS_PER_JOB, MAX_JSON_BYTES};

/// What an upload of a small animated scene answers: two cameras (one unnamed) and two
/// animations, one short and one long enough to reach the frame-number limit at any fps.
fn scene() -> SceneInfo {
    let camera = |index, name: Option<&str>| CameraInfo {
        index,
        name: name.map(String::from),
    };
    let animation = |index, name: &str, start_seconds, end_seconds| AnimationInfo {
        index,
        name: Some(name.into()),
        start_seconds,
        end_seconds,
    };
    SceneInfo {
        digest: "5e".repeat(32),
        size: 1234,
        cameras: vec![camera(0, Some("Main")), camera(1, None)],
        animations: vec![
            animation(0, "Walk", 0.5, 2.0),
            animation(1, "Long", 0.0, 1.0e6),
        ],
        duration_seconds: 1.0e6,
        triangles: 12,
        lights: 1,
        meshes: 1,
        instances: 1,
        materials: 1,
        textures: 0,
        features: vec![],
        warnings: vec![],
    }
}

fuzz_target!(|data: &[u8]| {
    if data.len() > MAX_JSON_BYTES {
        return;
    }
    let Ok(mut spec) = serde_json::from_slice::<JobSpec>(data) else {
        return;
    };
    // The route refuses a digest it has no scene for before planning; plan against the
    // one scene there is.
    let scene = scene();
    spec.scene = scene.digest.clone();
    let Ok(plan) = server::spec::plan(spec, &scene, DEFAULT_MAX_TASKS_PER_JOB) else {
        return;
    };

    let (w, h) = (plan.spec.width, plan.spec.height);
    assert!(plan.task_count() > 0 && plan.task_count() <= DEFAULT_MAX_TASKS_PER_JOB);
    assert!(plan.tiles.iter().all(|t| t.area() > 0 && t.fits_in(w, h)));
    let covered: u64 = plan.tiles.iter().map(|t| t.area() as u64).sum();
    assert_eq!(covered, w as u64 * h as u64, "tiles cover the frame once");
    let mut next = 0;
    for pass in &plan.passes {
        assert!(pass.start == next && !pass.is_empty(), "{:?}", plan.passes);
        next = pass.end;
    }
    assert_eq!(next, plan.spec.spp, "passes cover every sample");
    let frames = plan.spec.frames.expect("frames are resolved");
    assert_eq!(plan.frames.len() as u64, frames.count());
    if plan.task_count() <= 4096 {
        assert_eq!(plan.tasks().count() as u64, plan.task_count());
    }
    // The scheduler stores the spec as JSON and reads it back for every lease.
    let json = serde_json::to_string(&plan.spec).expect("a spec serialises");
    let back: JobSpec = serde_json::from_str(&json)
        .unwrap_or_else(|e| panic!("the stored spec does not read back ({e}): {json}"));
    assert_eq!(back, plan.spec, "the stored spec reads back different");
});

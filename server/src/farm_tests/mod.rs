//! The farm's transactions (leases, job controls, checks, time budgets, identity) against
//! an in-memory database, with explicit times: one file per concern, the helpers here.

mod budgets;
mod checks;
mod controls;
mod denoise;
mod failures;
mod identity;
mod leases;
mod retention;
mod tags;
mod video;

use proto::{
    FailureAck, FrameRange, JobSpec, JobState, Lease, Rect, SampleSpan, SceneInfo, TaskToken,
};
use rusqlite::{params, Connection};
use tracer::film::SamplingSummary;

use crate::budget::replan_running;
use crate::config::Timing;
use crate::controls::{cancel, pause, resume, retry, submit};
use crate::db::frames::is_assembled;
use crate::db::tasks;
use crate::db::workers;
use crate::error::Error;
use crate::identity::{join, worker_of_credential, Joining};
use crate::intake::mark_assembled;
use crate::scheduler::*;
use crate::state::TaskState;
use crate::status::job_status;
use crate::verify::Verdict;

pub(super) const LEASE_MS: i64 = 10_000;
pub(super) const TIMING: Timing = Timing {
    lease_ms: LEASE_MS,
    block_after_failures: 2,
    verify_fraction: 0.0,
    max_tasks_per_job: 1_000_000,
};

pub(super) fn scene() -> SceneInfo {
    SceneInfo {
        digest: "a".repeat(64),
        size: 1,
        triangles: 1,
        meshes: 1,
        instances: 1,
        materials: 1,
        ..Default::default()
    }
}

pub(super) fn db() -> Connection {
    let mut c = Connection::open_in_memory().unwrap();
    crate::db::migrations::migrate(&mut c).unwrap();
    c.execute(
        "INSERT INTO scenes (digest, size, info, created_ms) VALUES (?1, 1, '{}', 0)",
        [scene().digest],
    )
    .unwrap();
    c
}

/// A job of `frames` frames of 16×16 in 8×8 tiles (4 tasks a frame).
pub(super) fn job(
    c: &mut Connection,
    frames: i32,
    priority: i32,
    max_attempts: u32,
    now: i64,
) -> u64 {
    let mut spec = JobSpec::new(scene().digest);
    spec.width = 16;
    spec.height = 16;
    spec.tile_size = Some(8);
    spec.spp = 4;
    spec.frames = Some(FrameRange {
        start: 1,
        end: frames,
        step: 1,
    });
    spec.priority = priority;
    spec.max_attempts = max_attempts;
    spec.shutter = [-0.25, 0.25];
    let plan = crate::spec::plan(spec, &scene(), 1_000).unwrap();
    submit(c, &plan, now).unwrap()
}

pub(super) fn worker(c: &mut Connection, name: &str, now: i64) -> u64 {
    join(c, &joining(name, None), now, TIMING.live_since(now))
        .unwrap()
        .id
}

/// A worker of 4 threads asking to join as `name`, with `credential` if it kept one.
pub(super) fn joining<'a>(name: &'a str, credential: Option<&'a str>) -> Joining<'a> {
    Joining {
        profile: workers::Profile {
            name,
            threads: 4,
            version: "test",
            platform: None,
            tags: &[],
            denoiser: None,
            encoder: None,
            step_ms_per_mp: [None; 2],
        },
        credential,
    }
}

/// Accepts `lease` from `w` at `t`, and assembles its frame when it completes one (as
/// the upload would); returns what the acceptance said.
pub(super) fn accept_assembling(c: &mut Connection, w: u64, lease: &Lease, t: i64) -> Accepted {
    let accepted = accept(c, w, lease.token, 1, 1, None, t, TIMING).unwrap();
    if let Accepted::New {
        job,
        frame,
        frame_complete: true,
        ..
    } = accepted
    {
        let summary = SamplingSummary {
            mean_samples: 4.0,
            min_samples: 4,
            max_samples: 4,
            mean_noise: None,
        };
        mark_assembled(c, job, frame, t, &summary, TIMING).unwrap();
    }
    accepted
}

/// The task a leased check repeats (`None` for a render task).
pub(super) fn check_of(c: &Connection, lease: &Lease) -> Option<u64> {
    tasks::load(c, lease.token.task_id)
        .unwrap()
        .unwrap()
        .check_of
}

pub(super) fn state_of(c: &Connection, task: u64) -> TaskState {
    tasks::load(c, task).unwrap().unwrap().state
}

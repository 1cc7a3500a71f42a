//! Denoising: a job that denoises gets a denoise task per frame once the frame is
//! assembled; only a worker with a denoiser leases it, the frame is done once it is, and a
//! job whose frames wait for a denoiser no live worker has says so without failing.

use proto::{FrameState, TaskKind};

use super::*;
use crate::scheduler::Accepted;

/// A worker that registered a denoiser.
fn denoiser(c: &mut Connection, name: &str, now: i64) -> u64 {
    let mut joining = joining(name, None);
    joining.profile.denoiser = Some("Open Image Denoise 2.5.1");
    join(c, &joining, now, TIMING.live_since(now)).unwrap().id
}

/// A job of one 16×16 frame in four 8×8 tiles, denoised or not.
fn denoised_job(c: &mut Connection, denoise: bool) -> u64 {
    let mut spec = JobSpec::new(scene().digest);
    (spec.width, spec.height, spec.tile_size, spec.spp) = (16, 16, Some(8), 4);
    spec.denoise = denoise;
    let plan = crate::spec::plan(spec, &scene(), 1_000).unwrap();
    submit(c, &plan, 0).unwrap()
}

/// Leases and accepts the job's four render tasks on `w`, and assembles the frame.
fn render_frame(c: &mut Connection, w: u64, t: i64) {
    for _ in 0..4 {
        let l = lease(c, w, t, TIMING).unwrap().unwrap();
        assert_eq!(l.kind, TaskKind::Render);
        accept_assembling(c, w, &l, t);
    }
}

fn frame_state(c: &Connection, job: u64) -> FrameState {
    crate::db::frames::status(c, job, 0).unwrap().state
}

#[test]
fn an_assembled_frame_waits_for_a_worker_with_a_denoiser_then_is_done() {
    let mut c = db();
    let j = denoised_job(&mut c, true);
    let plain = worker(&mut c, "plain", 0);
    render_frame(&mut c, plain, 1);

    // Assembled, not finished: its denoise task is queued, and no live worker can take it.
    assert_eq!(frame_state(&c, j), FrameState::Denoising);
    assert_eq!(lease(&mut c, plain, 2, TIMING).unwrap(), None);
    let st = job_status(&c, j, 2, TIMING.live_since(2)).unwrap();
    assert_eq!(
        (st.state, st.frames_done, st.finished_ms),
        (JobState::Running, 0, None)
    );
    assert_eq!(
        st.stuck, None,
        "workers may take its tasks: it is not stuck"
    );
    let waiting = st.waiting.expect("the job says what it waits for");
    assert!(
        waiting.contains("1 frame(s) wait to be denoised")
            && waiting.contains("tessera install oidn"),
        "{waiting}"
    );

    // A worker with a denoiser comes: it leases the whole frame, with no samples.
    let d = denoiser(&mut c, "oidn", 3);
    assert_eq!(
        job_status(&c, j, 3, TIMING.live_since(3)).unwrap().waiting,
        None
    );
    let l = lease(&mut c, d, 4, TIMING).unwrap().unwrap();
    assert_eq!(l.kind, TaskKind::Denoise);
    assert_eq!(
        (l.tile, l.samples),
        (
            Rect {
                x: 0,
                y: 0,
                width: 16,
                height: 16
            },
            SampleSpan { start: 0, end: 0 }
        )
    );
    assert!(matches!(
        accept(&mut c, d, l.token, 0, 300, None, 5, TIMING).unwrap(),
        Accepted::New { .. }
    ));
    assert_eq!(frame_state(&c, j), FrameState::Done);
    let st = job_status(&c, j, 6, TIMING.live_since(6)).unwrap();
    assert_eq!(
        (st.state, st.frames_done, st.finished_ms),
        (JobState::Done, 1, Some(5))
    );
    // The denoise task counts as a task, not as samples, and not in the worker's speed.
    assert_eq!((st.tasks.done, st.progress), (5, 1.0));
    let listed = workers::list(&c, 6, TIMING.live_since(6), 0)
        .unwrap()
        .workers;
    let d_info = listed.iter().find(|w| w.id == d).unwrap();
    assert_eq!(d_info.denoiser.as_deref(), Some("Open Image Denoise 2.5.1"));
    assert_eq!(d_info.samples_per_second, None);
}

#[test]
fn a_job_without_denoise_has_no_denoise_task_and_a_denoiser_renders_tiles_too() {
    let mut c = db();
    let j = denoised_job(&mut c, false);
    let d = denoiser(&mut c, "oidn", 0);
    render_frame(&mut c, d, 1);
    assert_eq!(frame_state(&c, j), FrameState::Done);
    assert_eq!(tasks::denoise_of_frame(&c, j, 0).unwrap(), None);
    let st = job_status(&c, j, 2, TIMING.live_since(2)).unwrap();
    assert_eq!((st.state, st.waiting), (JobState::Done, None));
}

#[test]
fn a_denoise_lease_that_expires_goes_back_and_a_rerender_denoises_again() {
    let mut c = db();
    let j = denoised_job(&mut c, true);
    let d = denoiser(&mut c, "oidn", 0);
    render_frame(&mut c, d, 1);
    let l = lease(&mut c, d, 2, TIMING).unwrap().unwrap();
    assert_eq!(l.kind, TaskKind::Denoise);
    // The worker dies with it: the lease expires and the task is queued again.
    expire(&mut c, 2 + LEASE_MS + 1, TIMING).unwrap();
    assert_eq!(state_of(&c, l.token.task_id), TaskState::Queued);
    assert_eq!(frame_state(&c, j), FrameState::Denoising);
    let again = lease(&mut c, d, LEASE_MS + 10, TIMING).unwrap().unwrap();
    assert_eq!(again.token.task_id, l.token.task_id);
    accept(&mut c, d, again.token, 0, 1, None, LEASE_MS + 11, TIMING).unwrap();
    assert_eq!(frame_state(&c, j), FrameState::Done);

    // Rendered again from scratch: the old denoise task goes, a new one comes with the
    // new assembly.
    crate::controls::rerender(&mut c, j, &[0], LEASE_MS + 12).unwrap();
    assert_eq!(tasks::denoise_of_frame(&c, j, 0).unwrap(), None);
    assert_eq!(frame_state(&c, j), FrameState::Queued);
    render_frame(&mut c, d, LEASE_MS + 13);
    assert_eq!(frame_state(&c, j), FrameState::Denoising);
    let l = lease(&mut c, d, LEASE_MS + 14, TIMING).unwrap().unwrap();
    assert_eq!(l.kind, TaskKind::Denoise);
}

/// The planner's figure for a worker's denoise step: what it timed when it started, then
/// what its denoise tasks took from lease to upload.
#[test]
fn a_workers_denoise_time_is_what_it_timed_then_what_its_tasks_took() {
    let mut c = db();
    let j = denoised_job(&mut c, true);
    let mut joining = joining("oidn", None);
    joining.profile.denoiser = Some("Open Image Denoise 2.5.1");
    joining.profile.step_ms_per_mp = [Some(4_000_000), None];
    let d = join(&mut c, &joining, 0, TIMING.live_since(0)).unwrap().id;
    let figure = |c: &Connection, t| {
        workers::step_ms_per_mp(c, j, workers::Step::Denoise, TIMING.live_since(t)).unwrap()
    };
    assert_eq!(figure(&c, 0), [4e6]);
    assert!(workers::step_ms_per_mp(&c, j, workers::Step::Encode, 0)
        .unwrap()
        .is_empty());
    render_frame(&mut c, d, 1);
    let l = lease(&mut c, d, 10, TIMING).unwrap().unwrap();
    assert_eq!(l.kind, TaskKind::Denoise);
    accept(&mut c, d, l.token, 0, 0, None, 522, TIMING).unwrap();
    // 512 ms for 256 pixels.
    assert_eq!(figure(&c, 522), [2e6]);
}

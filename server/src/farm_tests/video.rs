//! Video: a job that asks for one gets an encode task once every frame is finished
//! (denoised too, where it denoises); only a worker with an encoder leases it, with the
//! job's frames; the job is done once it is, and waits with a clear status while no live
//! worker can.

use proto::{FrameRange, TaskKind};

use super::*;

fn with_steps(c: &mut Connection, name: &str, denoiser: bool, encoder: bool, now: i64) -> u64 {
    let mut joining = joining(name, None);
    joining.profile.denoiser = denoiser.then_some("Open Image Denoise 2.5.1");
    joining.profile.encoder = encoder.then_some("FFmpeg with libx264");
    join(c, &joining, now, TIMING.live_since(now)).unwrap().id
}

/// A job of frames 1-2 of 8×8 in one tile each, with a video, denoised or not.
fn video_job(c: &mut Connection, denoise: bool) -> u64 {
    let mut spec = JobSpec::new(scene().digest);
    (spec.width, spec.height, spec.tile_size, spec.spp) = (8, 8, Some(8), 1);
    spec.frames = Some(FrameRange {
        start: 1,
        end: 2,
        step: 1,
    });
    spec.denoise = denoise;
    spec.video = true;
    let plan = crate::spec::plan(spec, &scene(), 1_000).unwrap();
    submit(c, &plan, 0).unwrap()
}

#[test]
fn the_video_is_encoded_once_every_frame_is_finished_by_a_worker_with_an_encoder() {
    let mut c = db();
    let j = video_job(&mut c, false);
    let plain = worker(&mut c, "plain", 0);
    let first = lease(&mut c, plain, 1, TIMING).unwrap().unwrap();
    accept_assembling(&mut c, plain, &first, 1);
    assert_eq!(
        tasks::encode_of_job(&c, j).unwrap(),
        None,
        "a frame is still to come"
    );
    let second = lease(&mut c, plain, 2, TIMING).unwrap().unwrap();
    accept_assembling(&mut c, plain, &second, 2);
    assert!(tasks::encode_of_job(&c, j).unwrap().is_some());

    // Nobody can encode: the job waits and says why.
    assert_eq!(lease(&mut c, plain, 3, TIMING).unwrap(), None);
    let st = job_status(&c, j, 3, TIMING.live_since(3)).unwrap();
    assert_eq!(
        (st.state, st.frames_done, st.video),
        (JobState::Running, 2, false)
    );
    assert!(st.waiting.unwrap().contains("tessera install ffmpeg"));

    let enc = with_steps(&mut c, "ffmpeg", false, true, 4);
    let l = lease(&mut c, enc, 5, TIMING).unwrap().unwrap();
    assert_eq!(l.kind, TaskKind::Encode);
    assert_eq!(
        l.sequence,
        Some(FrameRange {
            start: 1,
            end: 2,
            step: 1
        })
    );
    accept(&mut c, enc, l.token, 0, 40, None, 6, TIMING).unwrap();
    let st = job_status(&c, j, 7, TIMING.live_since(7)).unwrap();
    assert_eq!(
        (st.state, st.video, st.finished_ms),
        (JobState::Done, true, Some(6))
    );
}

#[test]
fn a_denoised_job_is_encoded_after_its_last_frame_is_denoised() {
    let mut c = db();
    let j = video_job(&mut c, true);
    let both = with_steps(&mut c, "both", true, true, 0);
    let mut kinds = Vec::new();
    let mut t = 1;
    while let Some(l) = lease(&mut c, both, t, TIMING).unwrap() {
        kinds.push(l.kind);
        accept_assembling(&mut c, both, &l, t);
        t += 1;
    }
    use TaskKind::*;
    assert_eq!(kinds, [Render, Denoise, Render, Denoise, Encode]);
    let st = job_status(&c, j, t, TIMING.live_since(t)).unwrap();
    assert_eq!(
        (st.state, st.frames_done, st.video),
        (JobState::Done, 2, true)
    );

    // Rendered again: the video goes with the frame and comes back after it.
    crate::controls::rerender(&mut c, j, &[2], t).unwrap();
    assert_eq!(tasks::encode_of_job(&c, j).unwrap(), None);
    assert!(!job_status(&c, j, t, TIMING.live_since(t)).unwrap().video);
    let mut kinds = Vec::new();
    while let Some(l) = lease(&mut c, both, t, TIMING).unwrap() {
        kinds.push(l.kind);
        accept_assembling(&mut c, both, &l, t);
    }
    assert_eq!(kinds, [Render, Denoise, Encode]);
}

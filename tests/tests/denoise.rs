//! A job that denoises, on a farm of real processes: its frames wait, with a clear status,
//! while no worker has Open Image Denoise (a worker pointed at a folder without it never
//! leases a denoise task); once one does, every frame gets a `denoised` layer equal to
//! the whole frame rendered by `tessera render` and denoised here: tiles assembled, then
//! denoised, are the whole frame denoised.
//!
//! Needs the library (`tessera install oidn`, which `scripts/test.sh` runs); without it
//! the test says so loudly and checks nothing.

use std::path::Path;
use std::time::Duration;

use proto::{FrameState, JobState};
use tests::{render_directly, settings, wait_until, Farm, FRAMES};

#[test]
fn frames_wait_for_a_denoiser_then_carry_the_whole_frame_denoised() {
    let oidn = match post::Oidn::load(None) {
        Ok(oidn) => oidn,
        Err(e) => {
            eprintln!("\n=== WARNING: SKIPPED: the farm's denoising test needs Open Image Denoise: {e} ===\n");
            return;
        }
    };
    let mut farm = Farm::new();
    farm.start_server(60);
    let empty = farm.path().join("no-oidn");
    std::fs::create_dir_all(&empty).unwrap();
    let empty = empty.to_str().unwrap().to_string();
    farm.start_worker_with("plain", 2, &["--oidn", &empty]);
    let scene = farm.demo_scene();
    let scene = scene.to_str().unwrap();
    let mut args = vec![scene, "--frames", FRAMES, "--tile", "16", "--denoise"];
    args.extend(settings("4"));
    let job = farm.submit(&args);

    // Every frame is rendered and assembled, then waits: the job says why, and is not
    // failed.
    wait_until(
        "every frame to wait for its denoise step",
        Duration::from_secs(120),
        || {
            let (_, frames) = farm.job_and_frames(job);
            frames.iter().all(|f| f.state == FrameState::Denoising)
        },
        || farm.logs(),
    );
    let st = farm.job(job);
    assert_eq!(
        (st.state, st.frames_done, st.tasks.leased),
        (JobState::Running, 0, 0)
    );
    let waiting = st.waiting.expect("the job says what it waits for");
    assert!(waiting.contains("tessera install oidn"), "{waiting}");
    assert!(farm
        .client(&["status", &job.to_string()])
        .contains("WAITING"));
    let plain = &farm.worker_list().workers[0];
    assert_eq!(plain.denoiser, None);

    // A worker that has the library finishes the job.
    farm.start_worker("oidn", 2);
    let st = farm.wait_for_job(job, Duration::from_secs(120));
    assert_eq!((st.state, st.frames_done), (JobState::Done, 4), "{st:?}");
    let workers = farm.worker_list().workers;
    let denoiser = workers.iter().find(|w| w.name == "oidn").unwrap();
    assert_eq!(
        denoiser.tasks_done, 4,
        "the new worker denoised the four frames"
    );
    assert_eq!(denoiser.denoiser.as_deref(), Some(post::DENOISER_NAME));

    for frame in 1..=4 {
        let farm_frame = farm.server_frame(job, frame);
        let direct = render_directly(Path::new(scene), frame, "4", farm.path());
        let mut noisy = farm_frame.clone();
        noisy.denoised.clear();
        assert!(
            noisy == direct,
            "frame {frame}: the noisy layers are the direct render"
        );
        let expected = post::denoise_layers(&oidn, &direct, 0).unwrap();
        let bits = |v: &[glam::Vec3]| -> Vec<u32> {
            v.iter()
                .flat_map(|p| p.to_array())
                .map(f32::to_bits)
                .collect()
        };
        assert_eq!(
            bits(&farm_frame.denoised),
            bits(&expected),
            "frame {frame}: the farm's denoised layer differs from the whole frame denoised"
        );
    }
}

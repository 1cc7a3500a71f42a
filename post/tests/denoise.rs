//! Open Image Denoise on real renders: the demo scene at 4 and 16 spp, denoised, against a
//! 4096-spp reference; a frame assembled from tiles denoises to the same bits as the
//! whole frame rendered at once.
//!
//! Needs the library (`tessera install oidn`; `scripts/test.sh` runs it first). Without it
//! these tests say so loudly and pass without checking anything.

use std::sync::{Arc, OnceLock};

use glam::Vec3;
use post::Oidn;
use tracer::film::{Layers, SampleRange, TileRect};
use tracer::render::{prepare_frame, render_region, FrameOptions, PreparedFrame, RenderSettings};

/// The installed library, or `None` after a loud warning.
fn oidn() -> Option<&'static Oidn> {
    static OIDN: OnceLock<Option<Oidn>> = OnceLock::new();
    OIDN.get_or_init(|| match Oidn::load(None) {
        Ok(oidn) => Some(oidn),
        Err(e) => {
            eprintln!(
                "\n=== WARNING: SKIPPED: the denoising tests need Open Image Denoise: {e} ===\n"
            );
            None
        }
    })
    .as_ref()
}

/// Frame 12 of the demo (both balls in flight), 96x54, with the demo's motion blur.
fn demo_frame() -> PreparedFrame {
    let options = FrameOptions {
        frame: 12,
        width: 96,
        height: 54,
        shutter: tracer::motion::Shutter {
            open: -0.25,
            close: 0.25,
        },
        ..FrameOptions::default()
    };
    prepare_frame(Arc::new(tracer::demo::animated_demo_scene()), &options).unwrap()
}

fn render(frame: &PreparedFrame, rect: TileRect, samples: SampleRange) -> Layers {
    render_region(frame, &RenderSettings::DEFAULT, rect, samples, 16, &|_| {}).resolve()
}

/// Mean squared error of `image` against `reference`, over RGB.
fn mse(image: &mut dyn Iterator<Item = Vec3>, reference: &[Vec3]) -> f64 {
    let sum: f64 = image
        .zip(reference)
        .map(|(a, &b)| f64::from((a - b).length_squared()))
        .sum();
    sum / (3 * reference.len()) as f64
}

/// MSE of the values clamped to 0..1, the range a display shows.
fn display_mse(image: &mut dyn Iterator<Item = Vec3>, reference: &[Vec3]) -> f64 {
    let clamp = |v: Vec3| v.clamp(Vec3::ZERO, Vec3::ONE);
    let reference: Vec<Vec3> = reference.iter().map(|&r| clamp(r)).collect();
    mse(&mut image.map(clamp), &reference)
}

/// Relative MSE, `(x - ref)² / (ref² + 0.01)`: the usual measure for HDR images, where a
/// few bright pixels would otherwise decide plain MSE.
fn rel_mse(image: &mut dyn Iterator<Item = Vec3>, reference: &[Vec3]) -> f64 {
    let sum: f64 = image
        .zip(reference)
        .map(|(a, &b)| {
            let d = a - b;
            f64::from((d * d / (b * b + Vec3::splat(0.01))).element_sum())
        })
        .sum();
    sum / (3 * reference.len()) as f64
}

#[test]
fn denoised_demo_frames_are_closer_to_the_reference_than_noisy_ones() {
    let Some(oidn) = oidn() else { return };
    let frame = demo_frame();
    let full = TileRect::new(0, 0, 96, 54);
    let reference: Vec<Vec3> = render(&frame, full, SampleRange::new(0, 4096))
        .beauty
        .iter()
        .map(|b| b.truncate())
        .collect();
    for spp in [4, 16] {
        // Samples past the reference's: an image independent of it.
        let noisy = render(&frame, full, SampleRange::new(8192, 8192 + spp));
        let denoised = post::denoise_layers(oidn, &noisy, 0).unwrap();
        let noisy_rgb = || noisy.beauty.iter().map(|b| b.truncate());
        let errors = |f: fn(&mut dyn Iterator<Item = Vec3>, &[Vec3]) -> f64| {
            (
                f(&mut noisy_rgb(), &reference),
                f(&mut denoised.iter().copied(), &reference),
            )
        };
        let relative = errors(rel_mse);
        let display = errors(display_mse);
        let plain = errors(mse);
        eprintln!(
            "demo frame 12, 96x54, {spp} spp against 4096 spp, noisy -> denoised: relative \
             MSE {:.3e} -> {:.3e} ({:.1}x lower), display MSE {:.3e} -> {:.3e} ({:.1}x \
             lower), plain MSE {:.3e} -> {:.3e}",
            relative.0,
            relative.1,
            relative.0 / relative.1,
            display.0,
            display.1,
            display.0 / display.1,
            plain.0,
            plain.1,
        );
        // Measured: relative 51x and 32x lower, display 3.0x and 7.5x. Plain MSE is left
        // out of the check: the demo's caustic fireflies (hundreds of times the walls'
        // radiance) decide it, and the denoiser spreads them into blotches rather than
        // removing their energy.
        assert!(
            relative.1 * 8.0 < relative.0 && display.1 * 2.0 < display.0,
            "{spp} spp: denoising did not bring the frame closer to the reference"
        );
    }
}

#[test]
fn a_frame_assembled_from_tiles_denoises_to_the_bits_of_the_whole_frame() {
    let Some(oidn) = oidn() else { return };
    let frame = demo_frame();
    let full = TileRect::new(0, 0, 96, 54);
    let samples = SampleRange::new(0, 4);
    let whole = render(&frame, full, samples);
    let mut assembled = Layers::new(full);
    for tile in full.tiles(32) {
        assembled.paste(&render(&frame, tile, samples));
    }
    assert_eq!(assembled, whole, "tiles assemble to the whole frame");
    let a = post::denoise_layers(oidn, &whole, 0).unwrap();
    let b = post::denoise_layers(oidn, &assembled, 0).unwrap();
    let bits = |v: &[Vec3]| -> Vec<u32> {
        v.iter()
            .flat_map(|p| p.to_array())
            .map(f32::to_bits)
            .collect()
    };
    assert_eq!(bits(&a), bits(&b));
    // Not the identity: the denoiser changed the beauty.
    assert!(a
        .iter()
        .zip(&whole.beauty)
        .any(|(d, n)| (*d - n.truncate()).abs().max_element() > 1e-3));
}

#[test]
fn images_of_different_sizes_are_refused_by_name() {
    let Some(oidn) = oidn() else { return };
    let beauty = vec![glam::Vec4::ONE; 12];
    let albedo = vec![Vec3::ONE; 12];
    let normal = vec![Vec3::Z; 11];
    let err = oidn
        .denoise(
            &post::NoisyImage {
                width: 4,
                height: 3,
                beauty: &beauty,
                albedo: &albedo,
                normal: &normal,
            },
            1,
        )
        .unwrap_err();
    assert!(
        err.to_string().contains("the normal has 11 pixels"),
        "{err}"
    );
}

#[test]
fn a_folder_without_the_library_says_what_to_run() {
    let dir = tempfile::tempdir().unwrap();
    let err = Oidn::load(Some(dir.path())).unwrap_err();
    let text = err.to_string();
    assert!(text.contains("tessera install oidn"), "{text}");
    assert!(
        text.contains(&dir.path().display().to_string()),
        "names where it looked: {text}"
    );
}

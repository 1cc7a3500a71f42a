//! Helpers shared by the integration tests.
#![allow(dead_code)] // each test binary uses its own subset

pub mod gltf_doc;

use std::sync::Arc;

use glam::{DMat4, DVec3, Vec2, Vec3};
use tracer::camera::Projection;
use tracer::film::{Layers, SampleRange, TileBuffer, TileRect};
use tracer::light::Environment;
use tracer::material::Material;
use tracer::render::{prepare_frame, render_region, FrameOptions, PreparedFrame, RenderSettings};
use tracer::scene::{CameraDef, Scene, SceneBuilder};
use tracer::shapes::{quad, uv_sphere};
use tracer::spectrum;

/// A perspective camera (vertical field of view `yfov`) at `z` on the Z axis, looking
/// down −Z at the origin.
pub fn camera_on_z(b: &mut SceneBuilder, z: f64, yfov: f32) {
    let camera = CameraDef {
        name: None,
        projection: Projection::Perspective {
            yfov,
            aspect_ratio: None,
            znear: 0.01,
        },
    };
    b.camera(camera, DMat4::from_translation(DVec3::new(0.0, 0.0, z)));
}

/// A unit sphere of `material` in a uniform environment of radiance 1, seen by a camera
/// at z = 4: a white furnace for a white material.
pub fn furnace(material: Material) -> Scene {
    let mut b = SceneBuilder::default();
    let m = b.material(material);
    b.mesh("sphere", vec![uv_sphere(m, 64, 128)], DMat4::IDENTITY);
    camera_on_z(&mut b, 4.0, 0.6);
    b.environment(Environment::Constant(Vec3::ONE));
    b.finish()
}

/// Renders frame 0 of `scene` at `size` × `size` pixels and `spp` samples per pixel,
/// paths up to `max_depth` bounces, on 16 threads' worth of work.
pub fn render_square(scene: Scene, size: u32, spp: u32, max_depth: u32) -> Layers {
    let options = FrameOptions {
        width: size,
        height: size,
        ..Default::default()
    };
    let frame = prepare_frame(Arc::new(scene), &options).expect("scene prepares");
    let settings = RenderSettings {
        max_depth,
        ..RenderSettings::default()
    };
    render_rect(&frame, &settings, TileRect::new(0, 0, size, size), spp)
}

/// Renders `rect` of `frame` at samples 0..`spp`, on 16 threads' worth of work.
pub fn render_rect(
    frame: &PreparedFrame,
    settings: &RenderSettings,
    rect: TileRect,
    spp: u32,
) -> Layers {
    render_region(frame, settings, rect, SampleRange::new(0, spp), 16, &|_| {}).resolve()
}

/// Every nm of the band the renderer carries (360–830 nm), at the middles of 1 nm bins.
pub fn band() -> impl Iterator<Item = f32> {
    let (lo, hi) = (spectrum::LAMBDA_MIN, spectrum::LAMBDA_MAX);
    (0..(hi - lo) as u32).map(move |i| lo + i as f32 + 0.5)
}

/// The linear Rec. 709 colour the film gives light of spectral radiance `l(λ)`: the CIE
/// observer over [`band`], scaled so that a flat spectrum of 1 has luminance 1.
pub fn colour_of_spectrum(l: impl Fn(f32) -> f64) -> Vec3 {
    let (mut xyz, mut y) = (DVec3::ZERO, 0.0);
    for nm in band() {
        let cmf = spectrum::cmf(nm).as_dvec3();
        xyz += cmf * l(nm);
        y += cmf.y;
    }
    spectrum::XYZ_TO_REC709 * (xyz / y).as_vec3()
}

/// A quad of `material` in the z = 0 plane, facing +z and 18 units a side, and a camera at
/// z = 1 ([`camera_on_z`]) that sees nothing else.
pub fn plane_in_view(b: &mut SceneBuilder, material: u32) {
    let c = [(-9.0, -9.0), (9.0, -9.0), (9.0, 9.0), (-9.0, 9.0)].map(|(x, y)| Vec3::new(x, y, 0.0));
    b.mesh("plane", vec![quad(c, material)], DMat4::IDENTITY);
    camera_on_z(b, 1.0, 0.5);
}

/// The mean colour over the whole of `frame` at `spp` samples per pixel and one bounce:
/// what a plane under a light shows.
pub fn mean_one_bounce(frame: &PreparedFrame, spp: u32) -> Vec3 {
    let settings = RenderSettings {
        max_depth: 1,
        ..RenderSettings::DEFAULT
    };
    let rect = TileRect::new(0, 0, frame.width, frame.height);
    let layers = render_rect(frame, &settings, rect, spp);
    let sum: DVec3 = layers.beauty.iter().map(|p| p.truncate().as_dvec3()).sum();
    (sum / layers.beauty.len() as f64).as_vec3()
}

/// SplitMix64: small, deterministic, good enough for Monte Carlo tests and test geometry.
pub struct Rng(pub u64);

impl Rng {
    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in [0, 1).
    pub fn f32(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 / (1u64 << 24) as f32
    }

    /// Uniform in [0, 1), double precision.
    pub fn f64(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Uniform in [0, 1)².
    pub fn vec2(&mut self) -> Vec2 {
        Vec2::new(self.f32(), self.f32())
    }

    /// Uniform in [-1, 1)³.
    pub fn cube(&mut self) -> Vec3 {
        Vec3::new(self.f32(), self.f32(), self.f32()) * 2.0 - 1.0
    }

    /// Uniform on the unit sphere.
    pub fn dir(&mut self) -> Vec3 {
        loop {
            let v = self.cube();
            let l2 = v.length_squared();
            if l2 > 1e-4 && l2 <= 1.0 {
                return v / l2.sqrt();
            }
        }
    }

    /// Uniform in 0..n.
    pub fn below(&mut self, n: usize) -> usize {
        (self.next_u64() % n as u64) as usize
    }
}

/// `scene` prepared at frame 0, `width`×`height`.
pub fn frame(scene: Scene, width: u32, height: u32) -> PreparedFrame {
    let options = FrameOptions {
        width,
        height,
        ..Default::default()
    };
    prepare_frame(Arc::new(scene), &options).expect("scene prepares")
}

/// The whole of `frame` at `settings` and `spp`, as sums (tiles of 16).
pub fn render(frame: &PreparedFrame, settings: &RenderSettings, spp: u32) -> TileBuffer {
    let rect = TileRect::new(0, 0, frame.width, frame.height);
    render_region(frame, settings, rect, SampleRange::new(0, spp), 16, &|_| {})
}

/// The still demo at 24x24.
pub fn demo_frame() -> PreparedFrame {
    frame(tracer::demo::demo_scene(), 24, 24)
}

/// The measured Cornell box's frame `number` at 24x24.
pub fn cornell_frame(number: i32) -> PreparedFrame {
    let options = FrameOptions {
        frame: number,
        width: 24,
        height: 24,
        ..Default::default()
    };
    prepare_frame(Arc::new(tracer::demo::cornell_box()), &options).expect("scene prepares")
}

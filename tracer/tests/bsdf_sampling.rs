//! The BSDF contract the integrator relies on, through the public API only: sampled
//! values agree with `eval`/`pdf`, delta samples carry the throughput weight, refraction
//! scales radiance by 1/η² on the way in and η² on the way out, and white materials
//! reflect what they receive. (The statistical tests of every sampling routine live
//! beside the maths, in `src/bsdf/tests.rs`.)

// Test scenes and closed forms use the platform's maths; tracer::math is for the tracer.
#![allow(clippy::disallowed_methods)]

use glam::{Vec2, Vec3};
use tracer::bsdf::{precompute_tables, Bsdf, SurfaceParams};

/// A small deterministic generator (xorshift64*).
struct Rng(u64);

impl Rng {
    fn f32(&mut self) -> f32 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        let x = self.0.wrapping_mul(0x2545_F491_4F6C_DD1D);
        (x >> 40) as f32 / (1u64 << 24) as f32
    }
}

fn params(metallic: f32, roughness: f32, ior: f32, transmission: f32) -> SurfaceParams {
    SurfaceParams {
        base_color: Vec3::ONE,
        metallic,
        roughness,
        ior,
        specular: 1.0,
        specular_color: Vec3::ONE,
        transmission,
        ..SurfaceParams::default()
    }
}

fn wo(deg: f32, below: bool) -> Vec3 {
    let (s, c) = deg.to_radians().sin_cos();
    Vec3::new(s, 0.0, if below { -c } else { c })
}

#[test]
fn samples_agree_with_eval_and_pdf() {
    precompute_tables(true, false, false);
    let mut rng = Rng(0x9E37_79B9_7F4A_7C15);
    for p in [
        params(1.0, 0.4, 1.5, 0.0),
        params(0.0, 0.4, 1.5, 0.0),
        params(0.0, 0.4, 1.5, 1.0),
        params(0.3, 0.7, 2.0, 0.5),
    ] {
        let bsdf = Bsdf::new(p);
        assert!(!bsdf.is_delta());
        for below in [false, true] {
            let wo = wo(50.0, below);
            for _ in 0..2000 {
                let Some(s) = bsdf.sample(wo, rng.f32(), Vec2::new(rng.f32(), rng.f32())) else {
                    continue;
                };
                assert!(!s.delta);
                let (f, pdf) = bsdf.eval_and_pdf(wo, s.wi);
                assert!(
                    (pdf - s.pdf).abs() <= 1e-3 * pdf,
                    "{p:?}: {pdf} vs {}",
                    s.pdf
                );
                assert!((f - s.f).abs().max_element() <= 1e-3 * f.max_element());
            }
        }
    }
}

#[test]
fn smooth_glass_is_delta_and_scales_radiance_by_eta_squared() {
    let eta = 1.5;
    let bsdf = Bsdf::new(params(0.0, 0.0, eta, 1.0));
    assert!(bsdf.is_delta() && bsdf.eta() == eta);
    let outside = wo(0.0, false);
    assert_eq!(bsdf.eval(outside, -outside), Vec3::ZERO);
    assert_eq!(bsdf.pdf(outside, -outside), 0.0);
    // At normal incidence F = 0.04: reflect with probability 0.04 (weight 1), refract
    // with probability 0.96 (weight 1/η² going in, η² coming out).
    let reflect = bsdf.sample(outside, 0.01, Vec2::ZERO).unwrap();
    assert!(reflect.delta && (reflect.wi - Vec3::Z).length() < 1e-6);
    assert!((reflect.f.x * reflect.wi.z / reflect.pdf - 1.0).abs() < 1e-5);
    let enter = bsdf.sample(outside, 0.5, Vec2::ZERO).unwrap();
    assert!(enter.delta && (enter.wi + Vec3::Z).length() < 1e-6);
    assert!((enter.f.x * -enter.wi.z / enter.pdf - 1.0 / (eta * eta)).abs() < 1e-5);
    let leave = bsdf.sample(wo(0.0, true), 0.5, Vec2::ZERO).unwrap();
    assert!((leave.f.x * leave.wi.z / leave.pdf - eta * eta).abs() < 1e-4);
}

#[test]
fn white_opaque_materials_reflect_everything() {
    let mut rng = Rng(12345);
    for p in [params(1.0, 0.8, 1.5, 0.0), params(0.0, 0.8, 1.5, 0.0)] {
        let bsdf = Bsdf::new(p);
        let n = 100_000;
        let mut sum = 0.0;
        for _ in 0..n {
            if let Some(s) =
                bsdf.sample(wo(40.0, false), rng.f32(), Vec2::new(rng.f32(), rng.f32()))
            {
                sum += s.f.x * s.wi.z.abs() / s.pdf;
            }
        }
        let albedo = sum / n as f32;
        assert!((albedo - 1.0).abs() < 0.01, "{p:?}: {albedo}");
    }
}

//! Tests of KHR_materials_anisotropy: the anisotropic GGX against its closed forms
//! (normalisation, Smith's projected area), chi-square fits of its sampling at several
//! azimuths of `wo` (what a rotation of the direction amounts to in the shading frame),
//! white furnaces of anisotropic metal, and strength 0 leaving the BSDF as it was.

use super::chi2::Rng;
use super::microfacet::Ggx;
use super::tests::{chi2_case, directional_albedo};
use super::*;
use std::f64::consts::PI;

/// Chi-square tests in this file: four families × 2 roughness × 3 polar × 3 azimuth
/// angles, the transmitting ones from both sides (two more families' worth).
const CHI2_TESTS: usize = 6 * 2 * 3 * 3;

/// Azimuths of `wo` (degrees from the direction of anisotropy).
const AZIMUTHS: [f32; 3] = [0.0, 45.0, 90.0];

fn anisotropic(params: SurfaceParams, strength: f32) -> SurfaceParams {
    SurfaceParams {
        extensions: Some(ExtensionParams {
            anisotropy: strength,
            ..ExtensionParams::default()
        }),
        ..params
    }
}

fn metal(roughness: f32) -> SurfaceParams {
    SurfaceParams {
        base_color: Vec3::ONE,
        metallic: 1.0,
        roughness,
        ..SurfaceParams::default()
    }
}

/// `deg` from the normal, at azimuth `az` degrees from the x axis; below when asked.
fn wo_at(deg: f32, az: f32, below: bool) -> Vec3 {
    let (s, c) = deg.to_radians().sin_cos();
    let (sa, ca) = az.to_radians().sin_cos();
    Vec3::new(s * ca, s * sa, if below { -c } else { c })
}

/// ∫ g(m) dω over the upper hemisphere by a fine (cos θ, φ) grid, in f64.
fn hemisphere(g: impl Fn(Vec3) -> f64) -> f64 {
    let (nz, nphi) = (1500usize, 1500usize);
    let mut sum = 0.0;
    for a in 0..nz {
        // Concentrated towards the normal, where a narrow lobe lives: z = 1 − t².
        let t = (a as f64 + 0.5) / nz as f64;
        let z = 1.0 - t * t;
        let dz = 2.0 * t / nz as f64;
        let r = (1.0 - z * z).max(0.0).sqrt();
        for b in 0..nphi {
            let phi = 2.0 * PI * (b as f64 + 0.5) / nphi as f64;
            let m = Vec3::new((r * phi.cos()) as f32, (r * phi.sin()) as f32, z as f32);
            sum += g(m) * dz;
        }
    }
    sum * 2.0 * PI / nphi as f64
}

/// The closed forms every microfacet distribution satisfies: projected microfacet area
/// ∫ D(m) m·n dω = 1, and Smith's ∫ D(m) max(0, wo·m) dω = wo·n (1 + Λ(wo)), which ties
/// Λ of the anisotropic distribution to its D along every azimuth.
#[test]
fn anisotropic_ggx_meets_its_closed_forms() {
    for (ax, ay) in [(0.3, 0.3), (0.6, 0.1), (1.0, 0.05), (0.2, 0.8)] {
        let ggx = Ggx { ax, ay };
        let area = hemisphere(|m| f64::from(ggx.d(m) * m.z));
        assert!((area - 1.0).abs() < 2e-3, "({ax}, {ay}): ∫ D cos = {area}");
        for (deg, az) in [(30.0, 0.0), (60.0, 45.0), (75.0, 90.0), (50.0, 200.0)] {
            let wo = wo_at(deg, az, false);
            let projected = hemisphere(|m| f64::from(ggx.d(m) * wo.dot(m).max(0.0)));
            let smith = f64::from(wo.z * (1.0 + ggx.lambda(wo)));
            assert!(
                (projected / smith - 1.0).abs() < 3e-3,
                "({ax}, {ay}) wo {wo}: ∫ D (wo·m)+ = {projected}, wo·n (1 + Λ) = {smith}"
            );
        }
    }
}

/// Strength 0 is the isotropic BSDF, bit for bit, and so is the extension absent.
#[test]
fn strength_zero_is_the_isotropic_bsdf_bit_for_bit() {
    let mut rng = Rng::new(3);
    for roughness in [0.0, 0.3, 0.8] {
        for transmission in [0.0, 1.0] {
            let plain = SurfaceParams {
                transmission,
                ..metal(roughness)
            };
            let plain = SurfaceParams {
                metallic: 0.3,
                ..plain
            };
            let (a, b) = (Bsdf::new(plain), Bsdf::new(anisotropic(plain, 0.0)));
            for _ in 0..200 {
                let wo = wo_at(80.0 * rng.f32(), 360.0 * rng.f32(), rng.f32() < 0.5);
                let wi = wo_at(89.0 * rng.f32(), 360.0 * rng.f32(), rng.f32() < 0.5);
                assert_eq!(a.eval(wo, wi), b.eval(wo, wi));
                assert_eq!(a.pdf(wo, wi), b.pdf(wo, wi));
                let (ul, u) = (rng.f32(), Vec2::new(rng.f32(), rng.f32()));
                let (sa, sb) = (a.sample(wo, ul, u), b.sample(wo, ul, u));
                assert_eq!(
                    sa.map(|s| (s.wi, s.f, s.pdf)),
                    sb.map(|s| (s.wi, s.f, s.pdf))
                );
            }
        }
    }
}

/// The highlight stretches along the direction of anisotropy (the frame's x axis): seen
/// from the normal, reflections spread along x, and full strength on a mirror makes the
/// lobe rough (not a delta lobe any more) along x only.
#[test]
fn the_highlight_stretches_along_the_direction() {
    for roughness in [0.0, 0.2] {
        let bsdf = Bsdf::new(anisotropic(metal(roughness), 0.8));
        assert!(!bsdf.is_delta());
        let mut rng = Rng::new(5);
        let (mut xx, mut yy) = (0.0f64, 0.0f64);
        for _ in 0..20_000 {
            let u = Vec2::new(rng.f32(), rng.f32());
            let s = bsdf
                .sample(Vec3::Z, rng.f32(), u)
                .expect("a metal reflects");
            xx += f64::from(s.wi.x * s.wi.x);
            yy += f64::from(s.wi.y * s.wi.y);
        }
        assert!(
            xx > 4.0 * yy,
            "roughness {roughness}: spread x² {xx} y² {yy}"
        );
    }
}

fn chi2_family(name: &str, make: impl Fn(f32) -> SurfaceParams, sides: &[bool]) -> Vec<String> {
    let mut failures = Vec::new();
    let mut seed = 100;
    // Roughness 0.2 and up: at 0.1 the lobe is a ridge 0.01 wide in one direction, and
    // near grazing the harness's integration of the pdf over its cells misses 0.15% of
    // it (a 6000 × 6000 grid finds all of it).
    for roughness in [0.2, 0.5] {
        for deg in [0.0, 50.0, 85.0] {
            for az in AZIMUTHS {
                for &below in sides {
                    seed += 1;
                    let label = format!("{name} roughness {roughness} {deg}° az {az}°");
                    let wo = wo_at(deg, az, below);
                    failures.extend(chi2_case(&label, make(roughness), wo, seed, CHI2_TESTS));
                }
            }
        }
    }
    failures
}

#[test]
fn chi2_anisotropic_lobes() {
    let glass = |r: f32, thin: bool| SurfaceParams {
        base_color: Vec3::ONE,
        metallic: 0.0,
        roughness: r,
        transmission: 1.0,
        thin_walled: thin,
        ..SurfaceParams::default()
    };
    let mut failures = chi2_family("metal", |r| anisotropic(metal(r), 0.9), &[false]);
    failures.extend(chi2_family(
        "plastic",
        |r| {
            anisotropic(
                SurfaceParams {
                    base_color: Vec3::splat(0.5),
                    metallic: 0.0,
                    ..metal(r)
                },
                0.6,
            )
        },
        &[false],
    ));
    failures.extend(chi2_family(
        "glass",
        |r| anisotropic(glass(r, false), 0.7),
        &[false, true],
    ));
    failures.extend(chi2_family(
        "thin wall",
        |r| anisotropic(glass(r, true), 0.7),
        &[false, true],
    ));
    assert!(
        failures.is_empty(),
        "chi-square failures:\n{}",
        failures.join("\n")
    );
}

/// White anisotropic metal and plastic in a white furnace. The metal's F0 is 1, so every
/// photon is reflected and its directional albedo is 1 where Turquin's compensation has
/// the lobe's own E1 (`bsdf/anisotropy.rs`); the plastic's diffuse base takes what the
/// specular layer leaves, by an albedo looked up at the equivalent isotropic α. Neither
/// may exceed 1 (beyond the Monte Carlo noise), and both stay close to it.
#[test]
fn furnace_anisotropic_metal_and_plastic() {
    let mut report = Vec::new();
    let mut bad = false;
    let plastic = |r: f32| SurfaceParams {
        metallic: 0.0,
        ..metal(r)
    };
    // The metal's compensation is exact in E1 (the noise is 0.2%); the plastic's albedo
    // scaling reads Ew, which near grazing along the smooth axis changes faster than the
    // table's μ nodes follow (worst 0.7%, at 88°; the isotropic plastic is held to 1%).
    type Make<'a> = &'a dyn Fn(f32) -> SurfaceParams;
    let cases: [(&str, Make, f32); 2] = [("metal", &metal, 1.005), ("plastic", &plastic, 1.01)];
    for (name, make, limit) in cases {
        for roughness in [0.0, 0.2, 0.5, 0.8] {
            for strength in [0.5, 1.0] {
                let bsdf = Bsdf::new(anisotropic(make(roughness), strength));
                for deg in [0.0, 45.0, 75.0, 88.0] {
                    for az in AZIMUTHS {
                        let e = directional_albedo(&bsdf, wo_at(deg, az, false), 100_000, 9).x;
                        report.push(format!(
                            "{name} r={roughness} s={strength} {deg}° az {az}°: {e:.4}"
                        ));
                        bad |= !(e <= limit && e > 0.97);
                    }
                }
            }
        }
    }
    println!("{}", report.join("\n"));
    assert!(!bad, "furnace out of tolerance:\n{}", report.join("\n"));
}

//! Tests of the clear coat and sheen layers: chi-square fits of their sampling, the sheen
//! albedo table against a finer quadrature, white furnaces with their closed forms, and
//! factors of zero leaving the base as it was, bit for bit.

use super::chi2::{self, Rng};
use super::*;

/// Angles (degrees from the normal) of the chi-square tests.
const ANGLES: [f32; 3] = [0.0, 50.0, 85.0];
/// Roughness values (the layer's) of the chi-square tests.
const ROUGHNESS: [f32; 3] = [0.2, 0.5, 1.0];
/// Chi-square tests in this file (four families), for the Šidák correction.
const CHI2_TESTS: usize = 4 * 9;

fn wo_at(deg: f32) -> Vec3 {
    let (s, c) = crate::math::sin_cos(deg.to_radians());
    Vec3::new(s, 0.0, c)
}

fn base(color: Vec3, metallic: f32, roughness: f32) -> SurfaceParams {
    SurfaceParams {
        base_color: color,
        metallic,
        roughness,
        ..SurfaceParams::default()
    }
}

/// A Lambertian base of colour `color` (no specular layer).
fn lambert(color: Vec3) -> SurfaceParams {
    SurfaceParams {
        specular: 0.0,
        ..base(color, 0.0, 1.0)
    }
}

/// A base that reflects nothing.
fn black() -> SurfaceParams {
    lambert(Vec3::ZERO)
}

fn coated(params: SurfaceParams, weight: f32, roughness: f32) -> SurfaceParams {
    let layers = params.extensions.unwrap_or_default();
    SurfaceParams {
        extensions: Some(ExtensionParams {
            clearcoat: weight,
            clearcoat_roughness: roughness,
            ..layers
        }),
        ..params
    }
}

fn with_sheen(params: SurfaceParams, color: Vec3, roughness: f32) -> SurfaceParams {
    let layers = params.extensions.unwrap_or_default();
    SurfaceParams {
        extensions: Some(ExtensionParams {
            sheen_color: color,
            sheen_roughness: roughness,
            ..layers
        }),
        ..params
    }
}

/// Chi-square tests of one family over [`ANGLES`] × [`ROUGHNESS`]; `make(r)` builds the
/// material for layer roughness `r`.
fn chi2_family(name: &str, make: impl Fn(f32) -> SurfaceParams, seed: u64) {
    let threshold = chi2::sidak(0.01, CHI2_TESTS);
    let mut failures = Vec::new();
    for (k, &r) in ROUGHNESS.iter().enumerate() {
        for (j, &deg) in ANGLES.iter().enumerate() {
            let bsdf = Bsdf::new(make(r));
            let wo = wo_at(deg);
            let outcome = chi2::run(
                chi2::Config::default(),
                seed * 100 + (k * 10 + j) as u64,
                |rng| {
                    let s = bsdf.sample(wo, rng.f32(), Vec2::new(rng.f32(), rng.f32()))?;
                    assert!(!s.delta, "{name}: a delta sample from rough lobes");
                    Some(s.wi)
                },
                |wi| bsdf.pdf(wo, wi),
            );
            if outcome.p_value < threshold {
                failures.push(format!(
                    "{name} roughness {r} angle {deg}: chi2 {:.1} dof {} p {:.2e}; pdf mass \
                     {:.5}, rejected {:.5}; worst {:?}",
                    outcome.stat,
                    outcome.dof,
                    outcome.p_value,
                    outcome.pdf_mass,
                    outcome.rejected,
                    outcome.worst
                ));
            }
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

#[test]
fn chi2_clearcoat_over_plastic() {
    let plastic = base(Vec3::new(0.8, 0.3, 0.2), 0.0, 0.6);
    chi2_family("coat over plastic", |r| coated(plastic, 1.0, r), 1);
}

#[test]
fn chi2_sheen_over_diffuse() {
    let diffuse = lambert(Vec3::new(0.2, 0.3, 0.8));
    chi2_family(
        "sheen over diffuse",
        |r| with_sheen(diffuse, Vec3::new(1.0, 0.8, 0.6), r),
        2,
    );
}

#[test]
fn chi2_sheen_alone() {
    // A black base: the sheen's own sampling, alone, against its pdf.
    chi2_family("sheen alone", |r| with_sheen(black(), Vec3::ONE, r), 3);
}

#[test]
fn chi2_coat_and_sheen_over_metal() {
    let metal = base(Vec3::new(0.9, 0.7, 0.4), 1.0, 0.4);
    chi2_family(
        "coat and sheen over metal",
        |r| coated(with_sheen(metal, Vec3::splat(0.5), 1.0 - 0.5 * r), 0.7, r),
        4,
    );
}

#[test]
fn the_sheen_albedo_table_matches_a_finer_quadrature() {
    let mut worst = (0.0f32, 0.0, 0.0);
    for alpha in [0.07, 0.1, 0.25, 0.5, 0.8, 1.0] {
        for mu in [0.01, 0.1, 0.3, 0.6, 0.9, 1.0] {
            let fine = sheen::albedo_by_quadrature(mu, alpha, 600, 300);
            let err = (sheen::albedo(mu, alpha) - fine).abs();
            if err > worst.0 {
                worst = (err, mu, alpha);
            }
            assert!(
                fine > 0.0 && fine < 1.0,
                "albedo {fine} at μ {mu}, α {alpha}"
            );
        }
    }
    assert!(worst.0 < 3e-3, "table off by {:?} (error, μ, α)", worst);
}

/// Directional albedo ∫ f |cos| dωi at `wo` of the BSDF of `params`, by sampling.
fn albedo(params: SurfaceParams, wo: Vec3, n: usize, seed: u64) -> Vec3 {
    super::tests::directional_albedo(&Bsdf::new(params), wo, n, seed)
}

#[test]
fn sampling_the_sheen_alone_integrates_to_its_table() {
    // Over a black base only the sheen reflects: its albedo by importance sampling must
    // be the tabulated one (which the albedo scaling of every sheen relies on).
    for alpha in [0.07, 0.3, 1.0] {
        for deg in [0.0, 45.0, 80.0] {
            let wo = wo_at(deg);
            let params = with_sheen(black(), Vec3::ONE, alpha);
            let e = albedo(params, wo, 200_000, 5).x;
            let table = sheen::albedo(wo.z, alpha);
            assert!(
                (e - table).abs() < 0.01 * table.max(0.05),
                "α {alpha}, {deg}°: sampled {e}, table {table}"
            );
        }
    }
}

#[test]
fn a_coat_over_white_lambert_is_a_white_furnace() {
    // The coat reflects E_coat(μo) and the base, of albedo exactly 1, returns all it is
    // given: 1 − E_coat(μo). Any weight, any coat roughness, smooth included.
    let white = lambert(Vec3::ONE);
    for weight in [0.3, 1.0] {
        for roughness in [0.0, 0.1, 0.5, 1.0] {
            for deg in [0.0, 45.0, 80.0, 89.0] {
                let e = albedo(coated(white, weight, roughness), wo_at(deg), 100_000, 6);
                assert!(
                    (e - Vec3::ONE).abs().max_element() < 5e-3,
                    "weight {weight} roughness {roughness} {deg}°: {e}"
                );
            }
        }
    }
}

#[test]
fn a_smooth_coat_over_black_reflects_its_fresnel() {
    for deg in [0.0, 60.0, 85.0] {
        let wo = wo_at(deg);
        let e = albedo(coated(black(), 1.0, 0.0), wo, 10_000, 7);
        let f = fresnel::schlick_scalar(coat::F0, wo.z);
        assert!((e.x - f).abs() < 1e-4 * f, "{deg}°: {e} vs Fresnel {f}");
    }
}

/// Checks every (roughness, angle) of `make` has a furnace albedo in [lo, 1 + tol];
/// prints the figures.
fn furnace(name: &str, make: impl Fn(f32) -> SurfaceParams, lo: f32, tol: f32) {
    let mut report = Vec::new();
    let mut bad = false;
    for r in [0.0, 0.2, 0.5, 1.0] {
        for deg in [0.0, 30.0, 60.0, 80.0, 89.0] {
            let e = albedo(make(r), wo_at(deg), 60_000, 8).max_element();
            report.push(format!("{name} r={r} {deg}°: {e:.4}"));
            bad |= !(lo..=1.0 + tol).contains(&e);
        }
    }
    println!("{}", report.join("\n"));
    assert!(
        !bad,
        "furnace out of [{lo}, {}]:\n{}",
        1.0 + tol,
        report.join("\n")
    );
}

#[test]
fn furnace_clearcoat_over_white_metal() {
    // The metal's own furnace holds within 1% (`furnace_white_metal`); the coat adds its
    // albedo and takes the same from the metal.
    furnace(
        "coat over metal",
        |r| coated(base(Vec3::ONE, 1.0, 0.5), 1.0, r),
        0.985,
        0.01,
    );
}

#[test]
fn furnace_sheen_over_white_diffuse() {
    // The sheen reflects E(μo) and takes as much from a base that returns all: 1.
    let white = lambert(Vec3::ONE);
    furnace(
        "sheen over diffuse",
        |r| with_sheen(white, Vec3::ONE, r),
        0.99,
        0.01,
    );
}

#[test]
fn furnace_coat_and_sheen_over_white_plastic() {
    // White plastic's own furnace holds within 1% (`furnace_white_plastic`).
    furnace(
        "coat and sheen over plastic",
        |r| coated(with_sheen(base(Vec3::ONE, 0.0, r), Vec3::ONE, 0.5), 1.0, r),
        0.985,
        0.01,
    );
}

#[test]
fn a_tilted_coat_keeps_energy() {
    // A coat on its own normal map, over white Lambert: never above 1.
    let white = lambert(Vec3::ONE);
    let bsdf = Bsdf::new(coated(white, 1.0, 0.3));
    for tilt in [0.2f32, 0.6] {
        let n = Vec3::new(tilt.sin(), 0.0, tilt.cos());
        for deg in [0.0, 40.0, 70.0] {
            let wo = wo_at(deg);
            let at = bsdf.at_coated(wo, Some(n)).unwrap();
            let mut rng = Rng::new(9);
            let mut sum = 0.0;
            let count = 100_000;
            for _ in 0..count {
                if let Some(s) = at.sample(rng.f32(), Vec2::new(rng.f32(), rng.f32())) {
                    sum += s.f.x * s.wi.z.abs() / s.pdf;
                    let (f, pdf) = at.eval_and_pdf(s.wi);
                    if !s.delta {
                        assert!((pdf - s.pdf).abs() <= 1e-3 * pdf, "{pdf} vs {}", s.pdf);
                        assert!((f.x - s.f.x).abs() <= 1e-3 * f.x);
                    }
                }
            }
            let e = sum / count as f32;
            assert!(e <= 1.005, "tilt {tilt}, {deg}°: {e}");
        }
    }
}

#[test]
fn layers_of_zero_leave_the_base_bit_for_bit() {
    let mut rng = Rng::new(10);
    // Roughnesses without factors: nothing to layer. An iridescence factor of 0, or a
    // film of thickness 0 (KHR_materials_iridescence): no film.
    let zeros = [
        ExtensionParams {
            clearcoat_roughness: 0.7,
            sheen_roughness: 0.4,
            iridescence_ior: 1.8,
            iridescence_thickness: 400.0,
            ..ExtensionParams::default()
        },
        ExtensionParams {
            iridescence: 1.0,
            iridescence_ior: 1.8,
            ..ExtensionParams::default()
        },
    ];
    for base in [
        base(Vec3::new(0.8, 0.4, 0.2), 0.0, 0.5),
        base(Vec3::ONE, 1.0, 0.2),
        SurfaceParams {
            transmission: 1.0,
            ..base(Vec3::ONE, 0.0, 0.3)
        },
    ] {
        let plain = Bsdf::new(base);
        for layers in zeros {
            let zero = Bsdf::new(SurfaceParams {
                extensions: Some(layers),
                ..base
            });
            assert!(zero.layers.is_none() && zero.film.is_none());
            for _ in 0..200 {
                let wo = Vec3::new(rng.f32() - 0.5, rng.f32() - 0.5, rng.f32() - 0.3).normalize();
                let wi = Vec3::new(rng.f32() - 0.5, rng.f32() - 0.5, rng.f32() - 0.5).normalize();
                let u = (rng.f32(), Vec2::new(rng.f32(), rng.f32()));
                assert_eq!(plain.eval_and_pdf(wo, wi), zero.eval_and_pdf(wo, wi));
                let (a, b) = (plain.sample(wo, u.0, u.1), zero.sample(wo, u.0, u.1));
                assert_eq!(a.map(|s| (s.wi, s.f, s.pdf)), b.map(|s| (s.wi, s.f, s.pdf)));
            }
        }
    }
}

//! Tests of the BSDF against known answers: chi-square fits of every sampling routine,
//! sample/pdf/eval consistency, robustness on degenerate inputs, and white furnaces.

use super::chi2::{self, Rng};
use super::*;
use std::f32::consts::PI;

/// Incident angles (degrees from the normal) of the chi-square tests.
const ANGLES: [f32; 4] = [0.0, 45.0, 80.0, 89.9];
/// Roughness values of the chi-square tests.
const ROUGHNESS: [f32; 4] = [0.1, 0.3, 0.6, 1.0];
/// Number of chi-square tests in this file, for the Šidák correction: conductor (16),
/// plastic (16), glass at two IORs from both sides (64), three mixes from both sides (96).
const CHI2_TESTS: usize = 16 + 16 + 64 + 96;

fn material(
    base: Vec3,
    metallic: f32,
    roughness: f32,
    ior: f32,
    transmission: f32,
) -> SurfaceParams {
    SurfaceParams {
        base_color: base,
        metallic,
        roughness,
        ior,
        specular: 1.0,
        specular_color: Vec3::ONE,
        transmission,
    }
}

/// The direction `deg` degrees from the normal in the xz-plane, mirrored below the
/// surface when `below`.
fn wo_at(deg: f32, below: bool) -> Vec3 {
    let (s, c) = deg.to_radians().sin_cos();
    Vec3::new(s, 0.0, if below { -c } else { c })
}

/// Runs the chi-square test of `sample` against `pdf` for one (material, wo) and returns
/// a line for the failure report, or `None` when it passes.
fn chi2_case(label: &str, params: SurfaceParams, wo: Vec3, seed: u64) -> Option<String> {
    let bsdf = Bsdf::new(params);
    let outcome = chi2::run(
        chi2::Config::default(),
        seed,
        |rng| {
            let s = bsdf.sample(wo, rng.f32(), Vec2::new(rng.f32(), rng.f32()))?;
            assert!(!s.delta, "{label}: delta sample in a rough material");
            Some(s.wi)
        },
        |wi| bsdf.pdf(wo, wi),
    );
    let threshold = chi2::sidak(0.01, CHI2_TESTS);
    (outcome.p_value < threshold).then(|| format!("{label} wo={wo:?}: {outcome:?}"))
}

/// Chi-square tests over every angle and roughness for one material family.
fn chi2_family(name: &str, make: impl Fn(f32) -> SurfaceParams, sides: &[bool]) {
    let mut failures = Vec::new();
    let mut seed = 1;
    for &roughness in &ROUGHNESS {
        for &deg in &ANGLES {
            for &below in sides {
                seed += 1;
                let label = format!("{name} roughness {roughness} angle {deg} below {below}");
                failures.extend(chi2_case(&label, make(roughness), wo_at(deg, below), seed));
            }
        }
    }
    assert!(failures.is_empty(), "chi-square failures:\n{}", failures.join("\n"));
}

#[test]
fn chi2_ggx_conductor() {
    chi2_family(
        "conductor",
        |r| material(Vec3::new(0.9, 0.6, 0.3), 1.0, r, 1.5, 0.0),
        &[false],
    );
}

#[test]
fn chi2_plastic() {
    chi2_family(
        "plastic",
        |r| material(Vec3::new(0.2, 0.5, 0.8), 0.0, r, 1.5, 0.0),
        &[false],
    );
}

#[test]
fn chi2_rough_dielectric_reflection_and_transmission() {
    for ior in [1.5, 1.1] {
        chi2_family(
            &format!("glass ior {ior}"),
            |r| material(Vec3::ONE, 0.0, r, ior, 1.0),
            &[false, true],
        );
    }
}

#[test]
fn chi2_gltf_mixes() {
    chi2_family(
        "metal/plastic mix",
        |r| material(Vec3::new(0.8, 0.4, 0.2), 0.5, r, 1.5, 0.0),
        &[false, true],
    );
    chi2_family(
        "plastic/glass mix",
        |r| material(Vec3::new(0.3, 0.9, 0.6), 0.0, r, 1.33, 0.5),
        &[false, true],
    );
    chi2_family(
        "metal/plastic/glass with coloured specular",
        |r| SurfaceParams {
            specular: 0.6,
            specular_color: Vec3::new(1.0, 0.5, 2.0),
            ..material(Vec3::new(0.7, 0.7, 0.3), 0.3, r, 2.0, 0.6)
        },
        &[false, true],
    );
}

/// A uniformly random direction on the sphere, sometimes nudged to grazing or to ±Z.
fn random_direction(rng: &mut Rng) -> Vec3 {
    let z = match rng.next_u32() % 8 {
        0 => (rng.f32() - 0.5) * 1e-4,
        1 => {
            if rng.f32() < 0.5 {
                1.0
            } else {
                -1.0
            }
        }
        _ => 1.0 - 2.0 * rng.f32(),
    };
    let phi = 2.0 * PI * rng.f32();
    let r = (1.0 - z * z).max(0.0).sqrt();
    Vec3::new(r * phi.cos(), r * phi.sin(), z).normalize()
}

/// Random materials covering smooth and rough lobes, every mix and the extreme IORs.
fn random_material(rng: &mut Rng) -> SurfaceParams {
    let pick = |rng: &mut Rng, v: &[f32]| v[rng.next_u32() as usize % v.len()];
    let roughness = pick(rng, &[0.0, 1e-4, 0.04, 0.1, 0.5, 1.0, -1.0]);
    let roughness = if roughness < 0.0 { rng.f32() } else { roughness };
    let metallic = pick(rng, &[0.0, 1.0, 0.5, -1.0]);
    let metallic = if metallic < 0.0 { rng.f32() } else { metallic };
    SurfaceParams {
        base_color: Vec3::new(rng.f32(), rng.f32(), rng.f32()) * pick(rng, &[0.0, 1.0, 1.0]),
        metallic,
        roughness,
        ior: pick(rng, &[1.0, 1.0001, 1.0005, 1.002, 1.33, 1.5, 2.4, 10.0]),
        specular: pick(rng, &[1.0, 0.0, 0.5]),
        specular_color: pick(rng, &[1.0, 0.3, 2.0]) * Vec3::new(1.0, rng.f32(), 1.0),
        transmission: pick(rng, &[0.0, 1.0, 0.5]),
    }
}

fn rel_close(a: f32, b: f32, tol: f32) -> bool {
    (a - b).abs() <= tol * a.abs().max(b.abs()) + 1e-30
}

#[test]
fn sample_agrees_with_pdf_and_eval() {
    let mut rng = Rng::new(7);
    let mut checked = 0;
    for _ in 0..4000 {
        let params = random_material(&mut rng);
        let bsdf = Bsdf::new(params);
        let wo = random_direction(&mut rng);
        for _ in 0..16 {
            let Some(s) = bsdf.sample(wo, rng.f32(), Vec2::new(rng.f32(), rng.f32())) else {
                continue;
            };
            assert!(s.wi.is_finite() && (s.wi.length() - 1.0).abs() < 1e-3, "{s:?}");
            assert!(s.f.is_finite() && s.f.min_element() >= 0.0, "{params:?} {wo} {s:?}");
            assert!(s.pdf.is_finite() && s.pdf > 0.0, "{params:?} {wo} {s:?}");
            let weight = s.f * s.wi.z.abs() / s.pdf;
            assert!(weight.is_finite(), "{params:?} {wo} {s:?}");
            if s.delta {
                continue;
            }
            // Rough lobes narrower than f32 can resolve (α·|η − 1| ~ 1e-6) are left to
            // the finiteness checks above.
            let pdf = bsdf.pdf(wo, s.wi);
            let f = bsdf.eval(wo, s.wi);
            assert!(rel_close(pdf, s.pdf, 1e-3), "{params:?} {wo} {s:?}: pdf {pdf}");
            for k in 0..3 {
                assert!(rel_close(f[k], s.f[k], 1e-3), "{params:?} {wo} {s:?}: f {f}");
            }
            checked += 1;
        }
    }
    assert!(checked > 10_000, "only {checked} continuous samples");
}

#[test]
fn eval_and_pdf_are_finite_and_non_negative_everywhere() {
    let mut rng = Rng::new(11);
    let special = [
        Vec3::Z,
        -Vec3::Z,
        Vec3::X,
        Vec3::new(1.0, 0.0, 1e-7).normalize(),
        Vec3::new(1.0, 0.0, -1e-7).normalize(),
        Vec3::new(1.0, 0.0, 2e-6).normalize(),
        Vec3::new(0.0, 1.0, -3e-6).normalize(),
        Vec3::new(1.0, 0.0, 1e-3).normalize(),
    ];
    let us = [0.0, 0.5, 0.999_999_9, 1.0];
    for _ in 0..3000 {
        let bsdf = Bsdf::new(random_material(&mut rng));
        let mut dirs = special.to_vec();
        dirs.extend((0..4).map(|_| random_direction(&mut rng)));
        for &wo in &dirs {
            for &wi in &dirs {
                let f = bsdf.eval(wo, wi);
                let pdf = bsdf.pdf(wo, wi);
                assert!(f.is_finite() && f.min_element() >= 0.0, "{bsdf:?} {wo} {wi} {f}");
                assert!(pdf.is_finite() && pdf >= 0.0, "{bsdf:?} {wo} {wi} {pdf}");
            }
            for &a in &us {
                for &b in &us {
                    if let Some(s) = bsdf.sample(wo, a, Vec2::new(b, a)) {
                        let w = s.f * s.wi.z.abs() / s.pdf;
                        assert!(w.is_finite() && w.min_element() >= 0.0, "{bsdf:?} {wo} {s:?}");
                    }
                }
            }
        }
    }
}

#[test]
fn degenerate_parameters_stay_finite() {
    let nasty = [
        SurfaceParams {
            base_color: Vec3::new(f32::NAN, 2.0, -1.0),
            metallic: f32::NAN,
            roughness: f32::INFINITY,
            ior: f32::NAN,
            specular: -3.0,
            specular_color: Vec3::splat(f32::INFINITY),
            transmission: 7.0,
        },
        SurfaceParams {
            ior: 0.0,
            ..SurfaceParams::default()
        },
        SurfaceParams {
            ior: 1e30,
            transmission: 1.0,
            metallic: 0.0,
            ..SurfaceParams::default()
        },
    ];
    let mut rng = Rng::new(3);
    for params in nasty {
        let bsdf = Bsdf::new(params);
        assert!(bsdf.albedo().is_finite() && bsdf.eta().is_finite());
        for _ in 0..2000 {
            let (wo, wi) = (random_direction(&mut rng), random_direction(&mut rng));
            assert!(bsdf.eval(wo, wi).is_finite() && bsdf.pdf(wo, wi).is_finite());
            if let Some(s) = bsdf.sample(wo, rng.f32(), Vec2::new(rng.f32(), rng.f32())) {
                assert!((s.f * s.wi.z.abs() / s.pdf).is_finite(), "{params:?} {s:?}");
            }
        }
    }
}

#[test]
fn specular_zero_is_exactly_lambertian() {
    let mut rng = Rng::new(5);
    for &roughness in &[0.0, 0.01, 0.3, 1.0] {
        for &ior in &[1.0, 1.5, 10.0] {
            let base = Vec3::new(0.8, 0.5, 0.1);
            let bsdf = Bsdf::new(SurfaceParams {
                specular: 0.0,
                specular_color: Vec3::new(2.0, 1.0, 0.5),
                ..material(base, 0.0, roughness, ior, 0.0)
            });
            assert!(!bsdf.is_delta());
            for _ in 0..500 {
                let mut wo = random_direction(&mut rng);
                let mut wi = random_direction(&mut rng);
                wo.z = wo.z.abs().max(1e-3);
                wi.z = wi.z.abs().max(1e-3);
                let (wo, wi) = (wo.normalize(), wi.normalize());
                assert_eq!(bsdf.eval(wo, wi), base * FRAC_1_PI);
                assert!(rel_close(bsdf.eval(wo, wi).x, base.x / PI, 1e-6));
                assert!(rel_close(bsdf.pdf(wo, wi), wi.z / PI, 1e-6));
                let s = bsdf.sample(wo, rng.f32(), Vec2::new(rng.f32(), rng.f32()));
                if let Some(s) = s {
                    assert!(!s.delta);
                    assert!((s.f * s.wi.z / s.pdf - base).abs().max_element() < 1e-5);
                }
            }
        }
    }
}

#[test]
fn index_matched_glass_passes_everything_straight_through() {
    let base = Vec3::new(1.0, 0.7, 0.4);
    for roughness in [0.0, 0.5, 1.0] {
        let bsdf = Bsdf::new(material(base, 0.0, roughness, 1.0, 1.0));
        assert!(bsdf.is_delta());
        for wo in [wo_at(0.0, false), wo_at(60.0, false), wo_at(89.0, true)] {
            let s = bsdf.sample(wo, 0.3, Vec2::new(0.2, 0.9)).expect("a sample");
            assert!(s.delta);
            assert!((s.wi + wo).length() < 1e-6, "{wo} {s:?}");
            assert!((s.f * s.wi.z.abs() / s.pdf - base).abs().max_element() < 1e-5);
        }
    }
}

#[test]
fn is_delta_and_albedo() {
    assert!(Bsdf::new(material(Vec3::ONE, 1.0, 0.0, 1.5, 0.0)).is_delta());
    assert!(Bsdf::new(material(Vec3::ONE, 0.0, 0.0, 1.5, 1.0)).is_delta());
    assert!(!Bsdf::new(material(Vec3::ONE, 0.0, 0.0, 1.5, 0.0)).is_delta());
    assert!(!Bsdf::new(material(Vec3::ONE, 1.0, 0.2, 1.5, 0.0)).is_delta());
    let b = Vec3::new(0.2, 0.4, 0.6);
    assert_eq!(Bsdf::new(material(b, 1.0, 0.5, 1.5, 0.0)).albedo(), b);
    let plastic = Bsdf::new(material(b, 0.0, 0.5, 1.5, 0.0)).albedo();
    assert!((plastic - (b * 0.96 + Vec3::splat(0.04))).abs().max_element() < 1e-6);
    assert_eq!(Bsdf::new(material(Vec3::ONE, 0.2, 0.5, 1.7, 0.0)).eta(), 1.7);
}

/// Directional albedo ∫ f |cos| dωi at `wo`, by sampling.
fn directional_albedo(bsdf: &Bsdf, wo: Vec3, n: usize, seed: u64) -> Vec3 {
    let mut rng = Rng::new(seed);
    let mut sum = Vec3::ZERO;
    for _ in 0..n {
        if let Some(s) = bsdf.sample(wo, rng.f32(), Vec2::new(rng.f32(), rng.f32())) {
            sum += s.f * s.wi.z.abs() / s.pdf;
        }
    }
    sum / n as f32
}

#[test]
fn furnace_lambertian() {
    let bsdf = Bsdf::new(SurfaceParams {
        specular: 0.0,
        ..material(Vec3::ONE, 0.0, 0.5, 1.5, 0.0)
    });
    for deg in [0.0, 45.0, 80.0, 89.9] {
        let e = directional_albedo(&bsdf, wo_at(deg, false), 200_000, 1);
        assert!((e - Vec3::ONE).abs().max_element() < 5e-3, "{deg}: {e}");
    }
}

/// The worst |albedo − 1| of `params(roughness)` over the furnace angles, printed.
fn furnace_opaque(name: &str, make: impl Fn(f32) -> SurfaceParams, tol: f32) {
    let mut report = Vec::new();
    let mut bad = false;
    for roughness in [0.0, 0.1, 0.3, 0.6, 1.0] {
        let bsdf = Bsdf::new(make(roughness));
        for deg in [0.0, 30.0, 60.0, 80.0, 89.0] {
            let e = directional_albedo(&bsdf, wo_at(deg, false), 200_000, 2).x;
            report.push(format!("{name} r={roughness} {deg}°: {e:.4}"));
            bad |= (e - 1.0).abs() > tol;
        }
    }
    println!("{}", report.join("\n"));
    assert!(!bad, "furnace out of tolerance:\n{}", report.join("\n"));
}

#[test]
fn furnace_white_metal() {
    furnace_opaque("metal", |r| material(Vec3::ONE, 1.0, r, 1.5, 0.0), 0.01);
}

#[test]
fn furnace_white_plastic() {
    for ior in [1.0, 1.5, 3.0, 10.0] {
        furnace_opaque(
            &format!("plastic ior {ior}"),
            |r| material(Vec3::ONE, 0.0, r, ior, 0.0),
            0.01,
        );
    }
}

/// A unit sphere of this material in a white furnace (radiance 1 everywhere), seen by
/// parallel rays: the mean radiance of the paths that hit it. Paths are followed through
/// the sphere exactly: a chord of a sphere meets both ends at the same angle, so the next
/// hit inside sees `|cos|` of the refracted or internally reflected direction again.
fn sphere_furnace(params: SurfaceParams, paths: usize, seed: u64) -> f32 {
    let bsdf = Bsdf::new(params);
    let mut rng = Rng::new(seed);
    let mut sum = 0.0f64;
    for _ in 0..paths {
        // Parallel rays hit a sphere with cos θ distributed as 2μ dμ.
        let mu = rng.f32().sqrt().max(1e-4);
        let mut wo = Vec3::new((1.0 - mu * mu).max(0.0).sqrt(), 0.0, mu);
        let mut throughput = 1.0f32;
        for _bounce in 0..1000 {
            let Some(s) = bsdf.sample(wo, rng.f32(), Vec2::new(rng.f32(), rng.f32())) else {
                throughput = 0.0;
                break;
            };
            throughput *= s.f.x * s.wi.z.abs() / s.pdf;
            // From outside, wi below the surface enters; from inside, it reflects back in.
            if s.wi.z > 0.0 {
                break;
            }
            // The next hit from inside, at the same angle to the normal there.
            let m = s.wi.z.abs();
            wo = Vec3::new((1.0 - m * m).max(0.0).sqrt(), 0.0, -m);
        }
        sum += f64::from(throughput);
    }
    (sum / paths as f64) as f32
}

#[test]
fn furnace_glass_sphere() {
    let mut report = Vec::new();
    let mut bad = false;
    for roughness in [0.0, 0.1, 0.3, 0.6, 1.0] {
        for ior in [1.0, 1.0001, 1.05, 1.33, 1.5, 2.4, 10.0] {
            let e = sphere_furnace(material(Vec3::ONE, 0.0, roughness, ior, 1.0), 100_000, 3);
            report.push(format!("glass r={roughness} ior={ior}: {e:.4}"));
            bad |= (e - 1.0).abs() > 0.01;
        }
    }
    println!("{}", report.join("\n"));
    assert!(!bad, "furnace out of tolerance:\n{}", report.join("\n"));
}

#[test]
fn scratch_sphere_caps() {
    for (roughness, ior) in [(1.0f32, 10.0f32), (1.0, 2.4), (0.6, 10.0), (0.1, 10.0)] {
        let bsdf = Bsdf::new(material(Vec3::ONE, 0.0, roughness, ior, 1.0));
        let mut rng = Rng::new(3);
        let (mut capped, mut none, mut sum, mut bounces) = (0, 0, 0.0f64, 0u64);
        let n = 20000;
        for _ in 0..n {
            let mu = rng.f32().sqrt().max(1e-4);
            let mut wo = Vec3::new((1.0 - mu * mu).max(0.0).sqrt(), 0.0, mu);
            let mut t = 1.0f32;
            let mut k = 0;
            loop {
                k += 1;
                if k > 100000 { capped += 1; t = 0.0; break; }
                let Some(s) = bsdf.sample(wo, rng.f32(), Vec2::new(rng.f32(), rng.f32())) else { none += 1; t = 0.0; break; };
                t *= s.f.x * s.wi.z.abs() / s.pdf;
                if s.wi.z > 0.0 { break; }
                let m = s.wi.z.abs();
                wo = Vec3::new((1.0 - m * m).max(0.0).sqrt(), 0.0, -m);
            }
            bounces += k as u64;
            sum += t as f64;
        }
        println!("r {roughness} ior {ior}: E {:.4} capped {capped} none {none} mean bounces {}", sum / n as f64, bounces as f64 / n as f64);
    }
}

#[test]
fn scratch_glass_albedo() {
    for (roughness, ior) in [(1.0f32, 10.0f32), (1.0, 2.4), (0.6, 10.0), (0.3, 1.5)] {
        let bsdf = Bsdf::new(material(Vec3::ONE, 0.0, roughness, ior, 1.0));
        for below in [false, true] {
            let eta_rel = if below { 1.0 / ior } else { ior };
            let mut line = format!("r {roughness} ior {ior} below {below}:");
            for mu in [0.01f32, 0.1, 0.3, 0.5, 0.7, 0.9, 0.99, 1.0] {
                let wo = Vec3::new((1.0 - mu * mu).sqrt(), 0.0, if below { -mu } else { mu });
                let mut rng = Rng::new(1);
                let (mut sum, mut none) = (0.0f64, 0);
                let n = 100000;
                for _ in 0..n {
                    match bsdf.sample(wo, rng.f32(), Vec2::new(rng.f32(), rng.f32())) {
                        Some(s) => {
                            let mut w = s.f.x * s.wi.z.abs() / s.pdf;
                            if s.wi.z * wo.z < 0.0 { w *= eta_rel * eta_rel; }
                            sum += w as f64;
                        }
                        None => none += 1,
                    }
                }
                let [a, b, _] = tables::dielectric_albedo(mu, roughness * roughness, eta_rel); let e = a + b;
                line += &format!(" mu {mu}: {:.3} (rej {:.2} Eq {:.3})", sum / n as f64, none as f64 / n as f64, e);
            }
            println!("{line}");
        }
    }
}

#[test]
fn scratch_sphere_tail() {
    for (roughness, ior) in [(1.0f32, 10.0f32), (1.0, 2.4)] {
        let bsdf = Bsdf::new(material(Vec3::ONE, 0.0, roughness, ior, 1.0));
        let mut rng = Rng::new(9);
        let n = 1_000_000;
        let mut by_k = vec![0.0f64; 64];
        let mut cnt_k = vec![0u64; 64];
        let mut wmax = 0.0f32;
        for _ in 0..n {
            let mu = rng.f32().sqrt().max(1e-4);
            let mut wo = Vec3::new((1.0 - mu * mu).max(0.0).sqrt(), 0.0, mu);
            let mut t = 1.0f32;
            let mut k = 0usize;
            let ok = loop {
                k += 1;
                let Some(s) = bsdf.sample(wo, rng.f32(), Vec2::new(rng.f32(), rng.f32())) else { break false; };
                t *= s.f.x * s.wi.z.abs() / s.pdf;
                if s.wi.z > 0.0 { break true; }
                let m = s.wi.z.abs();
                wo = Vec3::new((1.0 - m * m).max(0.0).sqrt(), 0.0, -m);
            };
            if ok { by_k[k.min(63)] += t as f64; cnt_k[k.min(63)] += 1; wmax = wmax.max(t); }
        }
        let tot: f64 = by_k.iter().sum::<f64>() / n as f64;
        println!("r {roughness} ior {ior}: E {tot:.4} wmax {wmax}");
        for k in 1..20 { println!("  k {k}: contrib {:.4} paths {}", by_k[k] / n as f64, cnt_k[k]); }
    }
}

#[test]
fn scratch_inside_grazing() {
    let bsdf = Bsdf::new(material(Vec3::ONE, 0.0, 0.6, 1.5, 1.0));
    let wo = wo_at(89.9, true);
    let mut rng = Rng::new(1);
    let n = 400000;
    let (mut refl, mut trans, mut none) = (0, 0, 0);
    // Also accumulate E[1/pdf] per hemisphere-band, i.e. solid angle estimate
    let mut band = [0f64; 8];
    let mut band_n = [0u64; 8];
    for _ in 0..n {
        match bsdf.sample(wo, rng.f32(), Vec2::new(rng.f32(), rng.f32())) {
            Some(s) => {
                if s.wi.z < 0.0 { refl += 1 } else { trans += 1 }
                let b = (((s.wi.z + 1.0) * 4.0) as usize).min(7);
                band_n[b] += 1;
                band[b] += 1.0 / s.pdf as f64;
            }
            None => none += 1,
        }
    }
    println!("refl {} trans {} none {}", refl as f64 / n as f64, trans as f64 / n as f64, none as f64 / n as f64);
    // integrate pdf over hemispheres by brute force on a fine grid
    let (nt, np) = (2000, 1000);
    let (mut ir, mut it) = (0f64, 0f64);
    let mut ib = [0f64; 8];
    for a in 0..nt { for b in 0..np {
        let c = -1.0 + 2.0 * (a as f64 + 0.5) / nt as f64;
        let p = 2.0 * std::f64::consts::PI * (b as f64 + 0.5) / np as f64;
        let s = (1.0 - c * c).sqrt();
        let wi = Vec3::new((s * p.cos()) as f32, (s * p.sin()) as f32, c as f32);
        let v = bsdf.pdf(wo, wi) as f64 * (2.0 / nt as f64) * (2.0 * std::f64::consts::PI / np as f64);
        if c < 0.0 { ir += v } else { it += v }
        ib[(((c + 1.0) * 4.0) as usize).min(7)] += v;
    }}
    println!("pdf mass refl {ir} trans {it}");
    println!("bands sample {:?}", band_n.iter().map(|&x| x as f64 / n as f64).collect::<Vec<_>>());
    println!("bands pdf    {:?}", ib);
    println!("solid angle est {:?}", band.iter().map(|x| x / n as f64).collect::<Vec<_>>());
}

#[test]
fn scratch_vndf_tail() {
    let alpha = 0.36f32;
    let wo = Vec3::new((1.0f32 - 0.0017f32 * 0.0017).sqrt(), 0.0, 0.0017);
    let mut rng = Rng::new(5);
    let n = 4_000_000;
    let mut cnt = [0u64; 4];
    let th = [0.5f32, 0.745, 0.8, 0.9];
    for _ in 0..n {
        let wm = microfacet::sample_visible_normal(wo, alpha, Vec2::new(rng.f32(), rng.f32()));
        for k in 0..4 { if wo.dot(wm) > th[k] { cnt[k] += 1; } }
    }
    // integrate D_wo over hemisphere of wm
    let (nt, np) = (4000, 2000);
    let mut acc = [0f64; 4];
    let mut tot = 0f64;
    for a in 0..nt { for b in 0..np {
        let c = (a as f64 + 0.5) / nt as f64;
        let p = 2.0 * std::f64::consts::PI * (b as f64 + 0.5) / np as f64;
        let s = (1.0 - c * c).sqrt();
        let wm = Vec3::new((s * p.cos()) as f32, (s * p.sin()) as f32, c as f32);
        let v = microfacet::pdf_visible_normal(wo, wm, alpha) as f64 / nt as f64 * 2.0 * std::f64::consts::PI / np as f64;
        tot += v;
        for k in 0..4 { if wo.dot(wm) > th[k] { acc[k] += v; } }
    }}
    println!("tot {tot}");
    for k in 0..4 { println!("wo.wm > {}: sample {} integral {}", th[k], cnt[k] as f64 / n as f64, acc[k]); }
}

#[test]
fn scratch_inside_trans() {
    let bsdf = Bsdf::new(material(Vec3::ONE, 0.0, 0.6, 1.5, 1.0));
    for deg in [89.9f32, 80.0, 45.0] {
    let wo = wo_at(deg, true);
    let mut rng = Rng::new(1);
    let n = 4_000_000;
    let mut bands = [0f64; 10];
    for _ in 0..n {
        if let Some(s) = bsdf.sample(wo, rng.f32(), Vec2::new(rng.f32(), rng.f32())) {
            if s.wi.z > 0.0 { bands[((s.wi.z * 10.0) as usize).min(9)] += 1.0 / n as f64; }
        }
    }
    let (nt, np) = (4000, 1000);
    let mut ib = [0f64; 10];
    for a in 0..nt { for b in 0..np {
        let c = (a as f64 + 0.5) / nt as f64;
        let p = 2.0 * std::f64::consts::PI * (b as f64 + 0.5) / np as f64;
        let s = (1.0 - c * c).sqrt();
        let wi = Vec3::new((s * p.cos()) as f32, (s * p.sin()) as f32, c as f32);
        ib[((c * 10.0) as usize).min(9)] += bsdf.pdf(wo, wi) as f64 / nt as f64 * 2.0 * std::f64::consts::PI / np as f64;
    }}
    println!("deg {deg}");
    println!("sample {:?}", bands.map(|x| (x * 1e5).round() / 1e5));
    println!("pdf    {:?}", ib.map(|x| (x * 1e5).round() / 1e5));
    }
}

#[test]
fn scratch_hv_precision() {
    let alpha = 1.0f32;
    let wo = Vec3::new((1.0f32 - 0.0017453f32 * 0.0017453).sqrt(), 0.0, 0.0017453);
    let mut rng = Rng::new(5);
    let mut worst = 0.0f32;
    let mut bad = 0;
    let mut badt = 0;
    for _ in 0..1_000_000 {
        let wm = microfacet::sample_visible_normal(wo, alpha, Vec2::new(rng.f32(), rng.f32()));
        let wi = microfacet::reflect(wo, wm);
        if wi.z > 1e-6 {
            let wm2 = (wo + wi).normalize();
            let d = (wm - wm2).length();
            if d > 1e-3 { bad += 1; }
            worst = worst.max(d);
        }
        if let Some(wt) = microfacet::refract(wo, wm, 1.0 / 1.5) {
            if wt.z < -1e-6 {
                let mut h = (wo + wt / 1.5).normalize();
                if h.z < 0.0 { h = -h; }
                if (h - wm).length() > 1e-3 { badt += 1; if badt < 5 { println!("wm {wm} wt {wt} h {h}"); } }
            }
        }
    }
    println!("worst {worst} bad {bad} badt {badt}");
}

#[test]
fn scratch_cells() {
    let bsdf = Bsdf::new(material(Vec3::ONE, 0.0, 1.0, 1.5, 1.0));
    let wo = wo_at(89.9, true);
    let (nc, np) = (32usize, 64usize);
    let mut rng = Rng::new(1);
    let n = 2_000_000;
    let mut hist = vec![0f64; nc * np];
    for _ in 0..n {
        if let Some(s) = bsdf.sample(wo, rng.f32(), Vec2::new(rng.f32(), rng.f32())) {
            let c = (((s.wi.z + 1.0) * 0.5 * nc as f32) as usize).min(nc - 1);
            let mut phi = s.wi.y.atan2(s.wi.x); if phi < 0.0 { phi += 2.0 * PI; }
            let p = ((phi / (2.0 * PI) * np as f32) as usize).min(np - 1);
            hist[c * np + p] += 1.0;
        }
    }
    let k = 48;
    let mut rows = Vec::new();
    let (mut chi, mut dof) = (0.0, 0);
    let mut cells = Vec::new();
    for ci in 0..nc { 
        let (mut so, mut se) = (0.0, 0.0);
        for pi in 0..np {
        let mut acc = 0f64;
        for a in 0..k { for b in 0..k {
            let c = -1.0 + 2.0 * (ci as f64 + (a as f64 + 0.5) / k as f64) / nc as f64;
            let p = 2.0 * std::f64::consts::PI * (pi as f64 + (b as f64 + 0.5) / k as f64) / np as f64;
            let s = (1.0 - c * c).sqrt();
            let wi = Vec3::new((s * p.cos()) as f32, (s * p.sin()) as f32, c as f32);
            acc += bsdf.pdf(wo, wi) as f64;
        }}
        let e = acc / (k * k) as f64 * (2.0 / nc as f64) * (2.0 * std::f64::consts::PI / np as f64) * n as f64;
        so += hist[ci * np + pi]; se += e;
        let o = hist[ci * np + pi];
        if e > 5.0 { chi += (o - e) * (o - e) / e; dof += 1; cells.push(((o - e) * (o - e) / e, ci, pi, o, e)); }
        }
        rows.push(format!("cos row {ci}: obs {so} exp {se:.0} ratio {:.4}", so / se));
    }
    cells.sort_by(|a, b| b.0.total_cmp(&a.0));
    println!("chi {chi} dof {dof}");
    for c in &cells[..15] { println!("cell {:?}", c); }
}

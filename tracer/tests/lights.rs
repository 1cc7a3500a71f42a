//! Light sampling checked against known answers: pdfs integrate to the probability mass of
//! the non-delta lights, `sample` agrees with the separate pdf queries, sampled directions
//! follow their pdf, environment maps are oriented and importance-sampled as documented,
//! and punctual lights deliver the glTF units.

// Test scenes and closed forms use the platform's maths; tracer::math is for the tracer.
#![allow(clippy::disallowed_methods)]

use std::f64::consts::PI;

use glam::{Affine3A, DVec3, Quat, Vec2, Vec3};
use tracer::geometry::Aabb;
use tracer::light::{
    spot_attenuation, EmissiveTriangle, Emitter, Environment, EnvironmentMap, LightError, LightSet,
    PunctualLight,
};

mod common;
use common::Rng;

/// Direction of a cell of an `n` × `n` jittered grid over the sphere, equal-area in
/// (z, φ): each cell has solid angle 4π / n².
fn stratified_sphere(i: usize, j: usize, n: usize, rng: &mut Rng) -> Vec3 {
    let z = 1.0 - 2.0 * (i as f64 + rng.f64()) / n as f64;
    let phi = 2.0 * PI * (j as f64 + rng.f64()) / n as f64;
    let r = (1.0 - z * z).max(0.0).sqrt();
    DVec3::new(r * phi.cos(), r * phi.sin(), z).as_vec3()
}

/// Brute-force ray/triangle test in double precision: the hit point, if any.
fn hit_triangle(o: Vec3, d: Vec3, p: [Vec3; 3]) -> Option<Vec3> {
    let (o, d) = (o.as_dvec3(), d.as_dvec3());
    let (p0, p1, p2) = (p[0].as_dvec3(), p[1].as_dvec3(), p[2].as_dvec3());
    let (e1, e2) = (p1 - p0, p2 - p0);
    let s1 = d.cross(e2);
    let div = s1.dot(e1);
    if div == 0.0 {
        return None;
    }
    let s = o - p0;
    let b1 = s.dot(s1) / div;
    let s2 = s.cross(e1);
    let b2 = d.dot(s2) / div;
    let t = e2.dot(s2) / div;
    // A hair of tolerance: sampled points on an edge must count as hits.
    let eps = 1e-6;
    (b1 >= -eps && b2 >= -eps && b1 + b2 <= 1.0 + eps && t > 0.0).then(|| (o + d * t).as_vec3())
}

fn normal(p: [Vec3; 3]) -> Vec3 {
    (p[1] - p[0]).cross(p[2] - p[0]).normalize()
}

fn luminance(c: Vec3) -> f64 {
    (0.2126 * c.x + 0.7152 * c.y + 0.0722 * c.z) as f64
}

fn tri(
    p: [Vec3; 3],
    emission: Vec3,
    double_sided: bool,
    instance: u32,
    triangle: u32,
) -> EmissiveTriangle {
    EmissiveTriangle {
        p,
        emission,
        double_sided,
        // Emitter::Triangle samples, which the integrator evaluates.
        uniform: false,
        mirrored: false,
        instance,
        triangle,
        spectrum: None,
    }
}

/// A small map with smooth variation, a bright spot and a dark band.
fn test_map(width: usize, height: usize) -> EnvironmentMap {
    let mut pixels = Vec::with_capacity(width * height);
    for y in 0..height {
        for x in 0..width {
            let u = (x as f32 + 0.5) / width as f32;
            let v = (y as f32 + 0.5) / height as f32;
            let mut c = Vec3::new(0.2 + u, 0.5 + 0.5 * (6.0 * u).sin(), 1.0 - v);
            if (0.45..0.55).contains(&v) {
                c = Vec3::ZERO;
            }
            if x == width / 3 && y == height / 4 {
                c = Vec3::splat(200.0);
            }
            pixels.push(c);
        }
    }
    EnvironmentMap::from_pixels(width, height, pixels).unwrap()
}

/// Sum over every light of the set of the solid-angle pdf of direction `w` from `p`
/// (triangles by brute-force intersection; every hit counts, not only the nearest).
fn total_pdf(set: &LightSet, tris: &[EmissiveTriangle], p: Vec3, w: Vec3) -> f64 {
    let mut pdf = set.pdf_environment(w) as f64;
    for t in tris {
        if let Some(q) = hit_triangle(p, w, t.p) {
            pdf += set.pdf_triangle(t.instance, t.triangle, p, q, normal(t.p)) as f64;
        }
    }
    pdf
}

/// A scene of triangles seen under moderate and huge solid angles, an environment map and
/// a point light, around the reference point `p`.
fn mixed_scene() -> (LightSet, Vec<EmissiveTriangle>, Vec3) {
    let p = Vec3::new(0.1, 0.2, 0.05);
    let tris = vec![
        // Moderate solid angles: spherical sampling.
        tri(
            [
                Vec3::new(-1.0, -0.5, -1.0),
                Vec3::new(1.0, -0.7, -1.2),
                Vec3::new(0.2, 1.0, -0.9),
            ],
            Vec3::new(2.0, 1.0, 0.5),
            false,
            0,
            7,
        ),
        tri(
            [
                Vec3::new(2.0, 0.0, 0.0),
                Vec3::new(2.0, 1.5, 0.5),
                Vec3::new(2.2, 0.3, 1.4),
            ],
            Vec3::splat(5.0),
            true,
            1,
            0,
        ),
        // A large floor just below p: solid angle close to 2π, area sampling.
        tri(
            [
                Vec3::new(-30.0, -0.02, -30.0),
                Vec3::new(0.0, -0.02, 40.0),
                Vec3::new(30.0, -0.02, -30.0),
            ],
            Vec3::splat(0.01),
            false,
            2,
            3,
        ),
        // Behind the first one as seen from p: overlapping in direction space.
        tri(
            [
                Vec3::new(-0.5, -0.5, -3.0),
                Vec3::new(0.5, -0.5, -3.0),
                Vec3::new(0.0, 0.5, -3.0),
            ],
            Vec3::splat(1.0),
            true,
            0,
            8,
        ),
    ];
    let point = (
        PunctualLight::Point {
            intensity: Vec3::new(3.0, 2.0, 1.0),
            range: None,
        },
        Affine3A::from_translation(Vec3::new(0.0, 3.0, 0.0)),
        None,
    );
    let bounds = Aabb::from_points(Vec3::splat(-3.0), Vec3::splat(3.0));
    let set = LightSet::new(
        vec![point],
        tris.clone(),
        Environment::Map(test_map(32, 16)),
        bounds,
    );
    (set, tris, p)
}

#[test]
fn pdf_integrates_to_the_non_delta_probability_over_the_sphere() {
    let (set, tris, p) = mixed_scene();
    // Probability of choosing the (delta) point light, measured by sampling with a fine
    // grid of u_light, and checked against the documented power estimates.
    let n_sel = 200_000;
    let delta = (0..n_sel)
        .filter(|&i| {
            let u = (i as f32 + 0.5) / n_sel as f32;
            set.sample(p, None, u, Vec2::splat(0.5))
                .is_some_and(|s| s.delta)
        })
        .count() as f64
        / n_sel as f64;
    let radius = 0.5 * (6.0f64 * 6.0 * 3.0).sqrt();
    let point_power = 4.0 * PI * luminance(Vec3::new(3.0, 2.0, 1.0));
    let tri_power: f64 = tris
        .iter()
        .map(|t| {
            let area = 0.5 * (t.p[1] - t.p[0]).cross(t.p[2] - t.p[0]).length() as f64;
            area * PI * luminance(t.emission) * if t.double_sided { 2.0 } else { 1.0 }
        })
        .sum();
    let env_power = PI * radius * radius * test_map(32, 16).luminance_integral() as f64;
    let expected_delta = point_power / (point_power + tri_power + env_power);
    assert!(
        (delta - expected_delta).abs() < 1e-3,
        "delta mass {delta} vs {expected_delta}"
    );

    let n = 2000;
    let mut rng = Rng(42);
    let mut integral = 0.0f64;
    for i in 0..n {
        for j in 0..n {
            let w = stratified_sphere(i, j, n, &mut rng);
            integral += total_pdf(&set, &tris, p, w);
        }
    }
    integral *= 4.0 * PI / (n * n) as f64;
    let expected = 1.0 - delta;
    assert!(
        (integral - expected).abs() < 0.01 * expected,
        "∫pdf = {integral}, expected {expected}"
    );
}

#[test]
fn pdf_of_a_tiny_far_triangle_integrates_to_one() {
    // Solid angle ~1e-5 sr: area sampling. Integrate over a cone that holds it.
    let t = tri(
        [
            Vec3::new(0.0, 0.0, -50.0),
            Vec3::new(0.2, 0.0, -50.0),
            Vec3::new(0.05, 0.15, -50.5),
        ],
        Vec3::splat(1e6),
        false,
        3,
        9,
    );
    let set = LightSet::new(
        vec![],
        vec![t],
        Environment::Black,
        Aabb::from_points(Vec3::splat(-60.0), Vec3::splat(60.0)),
    );
    let p = Vec3::new(0.01, 0.02, 0.0);
    let axis = ((t.p[0] + t.p[1] + t.p[2]) / 3.0 - p).normalize();
    let cos_max =
        t.p.iter()
            .map(|&v| (v - p).normalize().dot(axis))
            .fold(1.0f32, f32::min) as f64
            - 1e-6;
    let frame = glam::Quat::from_rotation_arc(Vec3::Z, axis);
    let cone = 2.0 * PI * (1.0 - cos_max);
    let n = 1000;
    let mut rng = Rng(5);
    let mut integral = 0.0;
    for i in 0..n {
        for j in 0..n {
            let z = 1.0 - (1.0 - cos_max) * (i as f64 + rng.f64()) / n as f64;
            let phi = 2.0 * PI * (j as f64 + rng.f64()) / n as f64;
            let r = (1.0 - z * z).max(0.0).sqrt();
            let w = frame * DVec3::new(r * phi.cos(), r * phi.sin(), z).as_vec3();
            integral += total_pdf(&set, &[t], p, w);
        }
    }
    integral *= cone / (n * n) as f64;
    assert!((integral - 1.0).abs() < 0.01, "∫pdf = {integral}");
}

#[test]
fn sample_pdf_equals_the_separate_pdf_queries() {
    let (set, tris, _) = mixed_scene();
    let mut rng = Rng(9);
    let (mut n_tri, mut n_env, mut n_delta) = (0, 0, 0);
    for k in 0..20_000 {
        let p = Vec3::new(
            rng.f32() * 4.0 - 2.0,
            rng.f32() * 2.0,
            rng.f32() * 4.0 - 2.0,
        );
        let Some(s) = set.sample(p, None, rng.f32(), rng.vec2()) else {
            continue;
        };
        assert!(
            s.pdf > 0.0 && s.pdf.is_finite(),
            "sample {k}: pdf {}",
            s.pdf
        );
        assert!((s.wi.length() - 1.0).abs() < 1e-5);
        match s.emitter {
            Emitter::Triangle {
                instance,
                triangle,
                b1,
                b2,
                normal: n,
            } => {
                n_tri += 1;
                let t = tris
                    .iter()
                    .find(|t| t.instance == instance && t.triangle == triangle)
                    .unwrap();
                let q = t.p[0] * (1.0 - b1 - b2) + t.p[1] * b1 + t.p[2] * b2;
                let q_ray = p + s.wi * s.distance;
                assert!(
                    (q - q_ray).length() < 1e-4 * (1.0 + s.distance),
                    "{q} vs {q_ray}"
                );
                assert!(
                    (0.0..=1.0).contains(&b1) && (0.0..=1.0).contains(&b2) && b1 + b2 <= 1.0 + 1e-6
                );
                assert!((n - normal(t.p)).length() < 1e-5);
                let pdf = set.pdf_triangle(instance, triangle, p, q, n);
                assert!(
                    (pdf - s.pdf).abs() <= 1e-3 * s.pdf,
                    "triangle {instance}/{triangle}: {pdf} vs {}",
                    s.pdf
                );
            }
            Emitter::Radiance(l) if !s.delta => {
                n_env += 1;
                assert_eq!(s.distance, f32::INFINITY);
                let pdf = set.pdf_environment(s.wi);
                assert!(
                    (pdf - s.pdf).abs() <= 1e-4 * s.pdf,
                    "environment: {pdf} vs {}",
                    s.pdf
                );
                assert_eq!(l, set.environment().radiance(s.wi));
            }
            Emitter::Radiance(_) => n_delta += 1,
        }
    }
    assert!(
        n_tri > 1000 && n_env > 1000 && n_delta > 100,
        "{n_tri} {n_env} {n_delta}"
    );
    // A triangle that is not in the set has no light pdf.
    assert_eq!(set.pdf_triangle(99, 99, Vec3::ZERO, Vec3::X, Vec3::Z), 0.0);
}

#[test]
fn sampled_directions_follow_the_pdf() {
    // For a mixture, non-delta samples have density Σ pdf over all lights, so
    // E[h(ω) / Σ pdf(ω)] = ∫ h dω over the directions where some light has density (all
    // but the environment's black band where no triangle is seen), integrated here
    // independently of the sampler.
    let (set, tris, p) = mixed_scene();
    let h = |w: Vec3| ((w.x + 2.0) as f64).powi(2);
    let mut rng = Rng(77);
    let m = 1000;
    let mut expected = 0.0;
    for i in 0..m {
        for j in 0..m {
            let w = stratified_sphere(i, j, m, &mut rng);
            if total_pdf(&set, &tris, p, w) > 0.0 {
                expected += h(w);
            }
        }
    }
    expected *= 4.0 * PI / (m * m) as f64;
    assert!(
        expected < 4.0 * PI / 3.0 + 16.0 * PI - 1.0,
        "the black band is missing"
    );
    let n = 1_000_000;
    let (mut sum, mut missed) = (0.0, 0);
    for _ in 0..n {
        let Some(s) = set.sample(p, None, rng.f32(), rng.vec2()) else {
            continue;
        };
        if s.delta {
            continue;
        }
        let pdf = total_pdf(&set, &tris, p, s.wi);
        if pdf > 0.0 {
            sum += h(s.wi) / pdf;
        } else {
            // Only possible for a point on a triangle's edge that the test's own ray test
            // misses.
            missed += 1;
        }
    }
    assert!(missed <= 10, "{missed} samples where no light has density");
    let est = sum / n as f64;
    assert!(
        (est - expected).abs() < 0.02 * expected,
        "{est} vs {expected}"
    );
}

#[test]
fn environment_pdf_integrates_to_one_and_matches_samples() {
    for rotation in [
        Quat::IDENTITY,
        Quat::from_euler(glam::EulerRot::YXZ, 0.7, -0.4, 1.9),
    ] {
        let env = Environment::Map(test_map(64, 32).with_rotation(rotation));
        let n = 1500;
        let mut rng = Rng(3);
        let mut integral = 0.0;
        for i in 0..n {
            for j in 0..n {
                integral += env.pdf(stratified_sphere(i, j, n, &mut rng)) as f64;
            }
        }
        integral *= 4.0 * PI / (n * n) as f64;
        assert!((integral - 1.0).abs() < 0.01, "∫pdf = {integral}");

        // Samples: pdf agrees with pdf(dir), and E[lum(L) / pdf] = ∫ lum(L) dω.
        let total = env.luminance_integral() as f64;
        let m = 200_000;
        let mut est = 0.0;
        for _ in 0..m {
            let (w, l, pdf) = env.sample(rng.vec2()).unwrap();
            assert!((env.pdf(w) - pdf).abs() <= 1e-4 * pdf);
            assert_eq!(l, env.radiance(w));
            est += luminance(l) / pdf as f64;
        }
        est /= m as f64;
        assert!((est - total).abs() < 0.01 * total, "{est} vs {total}");
    }
}

#[test]
fn one_bright_pixel_draws_most_samples() {
    let (w, h) = (64, 32);
    let mut pixels = vec![Vec3::splat(0.01); w * h];
    let (bx, by) = (40, 10);
    pixels[by * w + bx] = Vec3::splat(1e4);
    let map = EnvironmentMap::from_pixels(w, h, pixels).unwrap();
    let centre = map.uv_to_direction(Vec2::new(
        (bx as f32 + 0.5) / w as f32,
        (by as f32 + 0.5) / h as f32,
    ));
    assert_eq!(map.radiance(centre), Vec3::splat(1e4));
    let mut rng = Rng(8);
    let n = 100_000;
    let hits = (0..n)
        .filter(|_| {
            let (d, l, _) = map.sample(rng.vec2()).unwrap();
            let uv = map.direction_to_uv(d);
            let inside = (uv.x * w as f32) as usize == bx && (uv.y * h as f32) as usize == by;
            assert_eq!(inside, l == Vec3::splat(1e4));
            inside
        })
        .count() as f64
        / n as f64;
    // Expected share: weight of the pixel among all, weights ∝ luminance × sin θ(row).
    let sin = |y: usize| (PI * (y as f64 + 0.5) / h as f64).sin();
    let dim: f64 = (0..h).map(|y| sin(y) * w as f64 * 0.01).sum::<f64>() - 0.01 * sin(by);
    let expected = 1e4 * sin(by) / (1e4 * sin(by) + dim);
    assert!(expected > 0.9);
    assert!((hits - expected).abs() < 0.005, "{hits} vs {expected}");
}

#[test]
fn constant_environment_is_sampled_uniformly() {
    let env = Environment::Constant(Vec3::new(0.5, 1.0, 2.0));
    let mut rng = Rng(1);
    let mut mean = DVec3::ZERO;
    let n = 100_000;
    for _ in 0..n {
        let (w, l, pdf) = env.sample(rng.vec2()).unwrap();
        assert_eq!(pdf, 1.0 / (4.0 * std::f32::consts::PI));
        assert_eq!(l, Vec3::new(0.5, 1.0, 2.0));
        assert!((w.length() - 1.0).abs() < 1e-5);
        mean += w.as_dvec3();
    }
    assert!((mean / n as f64).length() < 0.01);
    assert_eq!(
        env.pdf(Vec3::new(0.3, -2.0, 1.0)),
        1.0 / (4.0 * std::f32::consts::PI)
    );
    assert!(Environment::Black.sample(Vec2::splat(0.5)).is_none());
    assert_eq!(Environment::Black.pdf(Vec3::Y), 0.0);
    assert_eq!(Environment::Black.radiance(Vec3::Y), Vec3::ZERO);
}

#[test]
fn environment_orientation_follows_the_documented_convention() {
    // 4 × 2 map: each pixel a different colour.
    let pixels: Vec<Vec3> = (0..8).map(|i| Vec3::new(i as f32, 1.0, 0.0)).collect();
    let map = EnvironmentMap::from_pixels(4, 2, pixels).unwrap();
    let px = |x: usize, y: usize| Vec3::new((y * 4 + x) as f32, 1.0, 0.0);
    let d = |x: f32, y: f32, z: f32| Vec3::new(x, y, z).normalize();
    // Centre (u = 0.5) looks along +X; u = 0.75 along +Z; u = 0.25 along −Z; v = 0 is up.
    assert_eq!(map.radiance(d(1.0, 0.3, 0.01)), px(2, 0));
    assert_eq!(map.radiance(d(1.0, -0.3, -0.01)), px(1, 1));
    assert_eq!(map.radiance(d(-0.01, 0.3, 1.0)), px(3, 0));
    assert_eq!(map.radiance(d(0.01, 0.3, 1.0)), px(2, 0));
    assert_eq!(map.radiance(d(0.01, 0.3, -1.0)), px(1, 0));
    assert_eq!(map.radiance(d(-0.01, -0.3, -1.0)), px(0, 1));
    let uv = map.direction_to_uv(Vec3::X);
    assert!((uv - Vec2::new(0.5, 0.5)).length() < 1e-6);
    assert!(map.direction_to_uv(Vec3::Y).y.abs() < 1e-6);
    assert!((map.direction_to_uv(Vec3::Z).x - 0.75).abs() < 1e-6);
    for uv in [
        Vec2::new(0.1, 0.2),
        Vec2::new(0.8, 0.9),
        Vec2::new(0.5, 0.5),
    ] {
        assert!((map.direction_to_uv(map.uv_to_direction(uv)) - uv).length() < 1e-5);
    }
    // Turning the map by a quarter turn about +Y moves what was along +X to rotation·X.
    let rot = Quat::from_rotation_y(std::f32::consts::FRAC_PI_2);
    let turned = map.clone().with_rotation(rot);
    for dir in [d(1.0, 0.3, 0.01), d(0.01, -0.3, 1.0), d(-0.5, 0.2, -1.0)] {
        assert_eq!(turned.radiance(rot * dir), map.radiance(dir));
    }
}

#[test]
fn environment_map_loads_from_exr() {
    let dir = std::env::temp_dir().join(format!("tessera-lights-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("env.exr");
    let (w, h) = (8usize, 4usize);
    exr::prelude::write_rgba_file(&path, w, h, |x, y| (x as f32, y as f32, 0.5, 1.0)).unwrap();
    let map = EnvironmentMap::load(&path).unwrap();
    assert_eq!((map.width(), map.height()), (w, h));
    assert_eq!(map.pixel(5, 2), Vec3::new(5.0, 2.0, 0.5));
    let bytes = std::fs::read(&path).unwrap();
    let decoded = EnvironmentMap::decode(&bytes, "env.exr").unwrap();
    assert_eq!(decoded.pixel(7, 3), Vec3::new(7.0, 3.0, 0.5));
    std::fs::remove_dir_all(&dir).unwrap();

    let err = EnvironmentMap::load(dir.join("missing.exr")).unwrap_err();
    assert!(matches!(err, LightError::Exr { .. }));
    assert!(err.to_string().contains("missing.exr"), "{err}");
    assert!(matches!(
        EnvironmentMap::decode(b"not an exr", "x"),
        Err(LightError::Exr { .. })
    ));
    assert!(matches!(
        EnvironmentMap::from_pixels(3, 2, vec![Vec3::ONE; 5]),
        Err(LightError::Size { .. })
    ));
    assert!(EnvironmentMap::from_pixels(0, 0, vec![]).is_err());
    // Non-finite and negative pixels read as black.
    let m = EnvironmentMap::from_pixels(
        2,
        1,
        vec![Vec3::new(f32::NAN, -1.0, f32::INFINITY), Vec3::ONE],
    )
    .unwrap();
    assert_eq!(m.pixel(0, 0), Vec3::ZERO);
}

#[test]
fn point_light_gives_intensity_over_distance_squared() {
    let intensity = Vec3::new(3.0, 6.0, 9.0);
    // Scale in the node transform does not change the light.
    let to_world = Affine3A::from_scale_rotation_translation(
        Vec3::splat(5.0),
        Quat::from_rotation_x(0.3),
        Vec3::new(1.0, 2.0, -2.0),
    );
    let set = LightSet::new(
        vec![(
            PunctualLight::Point {
                intensity,
                range: Some(0.1),
            },
            to_world,
            None,
        )],
        vec![],
        Environment::Black,
        Aabb::EMPTY,
    );
    let p = Vec3::new(1.0, 2.0, 2.0);
    let s = set
        .sample(p, Some(Vec3::Z), 0.3, Vec2::new(0.1, 0.9))
        .unwrap();
    assert!(s.delta);
    assert_eq!(s.pdf, 1.0);
    assert!((s.distance - 4.0).abs() < 1e-5);
    assert!((s.wi - Vec3::NEG_Z).length() < 1e-6);
    let Emitter::Radiance(l) = s.emitter else {
        panic!("punctual lights give radiance")
    };
    assert!((l - intensity / 16.0).length() < 1e-5, "{l}");
    // A white Lambertian surface facing the light reflects ρ/π · cos · L / pdf.
    let reflected = (1.0 / std::f32::consts::PI) * 1.0 * l / s.pdf;
    assert!((reflected - intensity / (16.0 * std::f32::consts::PI)).length() < 1e-5);
}

#[test]
fn directional_light_gives_its_illuminance() {
    let illuminance = Vec3::new(2.0, 2.0, 1.0);
    // Turn −Z to −Y: the light travels downwards, so it arrives from +Y.
    let to_world = Affine3A::from_rotation_x(-std::f32::consts::FRAC_PI_2)
        * Affine3A::from_scale(Vec3::splat(0.01));
    let set = LightSet::new(
        vec![(PunctualLight::Directional { illuminance }, to_world, None)],
        vec![],
        Environment::Black,
        Aabb::from_points(Vec3::splat(-1.0), Vec3::ONE),
    );
    for p in [Vec3::ZERO, Vec3::new(100.0, -50.0, 3.0)] {
        let s = set.sample(p, None, 0.7, Vec2::ZERO).unwrap();
        assert!(s.delta && s.pdf == 1.0 && s.distance == f32::INFINITY);
        assert!((s.wi - Vec3::Y).length() < 1e-6, "{}", s.wi);
        assert_eq!(s.emitter, Emitter::Radiance(illuminance));
    }
}

#[test]
fn spot_falloff_is_full_inside_zero_outside_and_monotone_between() {
    let (inner, outer) = (0.3f32, 0.6f32);
    let mut previous = f32::INFINITY;
    let n = 10_000;
    for i in 0..=n {
        let angle = std::f32::consts::PI * i as f32 / n as f32;
        let a = spot_attenuation(angle, inner, outer);
        assert!((0.0..=1.0).contains(&a));
        if angle <= inner {
            assert_eq!(a, 1.0, "inside the inner cone at {angle}");
        }
        if angle >= outer {
            assert_eq!(a, 0.0, "outside the outer cone at {angle}");
        }
        assert!(a <= previous, "not monotone at {angle}");
        // Continuous: no jump larger than the slope allows on this grid.
        assert!(
            previous == f32::INFINITY || previous - a < 0.01,
            "jump at {angle}"
        );
        previous = a;
    }
    assert!((0.0..1.0).contains(&spot_attenuation(0.45, inner, outer)));
    assert!(spot_attenuation(0.45, inner, outer) > 0.0);
    // Zero-angle and inverted cones stay finite.
    for (angle, i, o) in [
        (0.0, 0.0, 0.0),
        (0.1, 0.0, 0.0),
        (0.2, 0.5, 0.1),
        (0.0, f32::NAN, 0.2),
    ] {
        let a = spot_attenuation(angle, i, o);
        assert!(
            a.is_finite() && (0.0..=1.0).contains(&a),
            "{angle} {i} {o}: {a}"
        );
    }
}

#[test]
fn spot_light_in_the_set_applies_falloff_and_inverse_square() {
    let intensity = Vec3::splat(8.0);
    // At (0, 4, 0) pointing down (−Z turned to −Y).
    let to_world = Affine3A::from_rotation_translation(
        Quat::from_rotation_x(-std::f32::consts::FRAC_PI_2),
        Vec3::new(0.0, 4.0, 0.0),
    );
    let spot = PunctualLight::Spot {
        intensity,
        range: None,
        inner_cone: 0.2,
        outer_cone: 0.5,
    };
    let set = LightSet::new(
        vec![(spot, to_world, None)],
        vec![],
        Environment::Black,
        Aabb::EMPTY,
    );
    // Straight below: full intensity.
    let s = set.sample(Vec3::ZERO, None, 0.5, Vec2::ZERO).unwrap();
    assert_eq!(s.emitter, Emitter::Radiance(intensity / 16.0));
    // In the falloff band.
    let angle = 0.35f32;
    let p = Vec3::new(4.0 * angle.tan(), 0.0, 0.0);
    let s = set.sample(p, None, 0.5, Vec2::ZERO).unwrap();
    let d2 = (Vec3::new(0.0, 4.0, 0.0) - p).length_squared();
    let Emitter::Radiance(l) = s.emitter else {
        panic!()
    };
    let expected = intensity * spot_attenuation(angle, 0.2, 0.5) / d2;
    assert!(
        (l - expected).length() < 1e-4 * expected.length(),
        "{l} vs {expected}"
    );
    // Outside the cone: nothing.
    assert!(set
        .sample(Vec3::new(4.0, 0.0, 0.0), None, 0.5, Vec2::ZERO)
        .is_none());
    // A zero-angle cone emits nothing and is left out: no NaN, no sample.
    let zero = PunctualLight::Spot {
        intensity,
        range: None,
        inner_cone: 0.0,
        outer_cone: 0.0,
    };
    let set = LightSet::new(
        vec![(zero, to_world, None)],
        vec![],
        Environment::Black,
        Aabb::EMPTY,
    );
    assert!(set.is_empty());
    assert!(set.sample(Vec3::ZERO, None, 0.5, Vec2::ZERO).is_none());
}

#[test]
fn no_lights_means_no_samples() {
    let set = LightSet::default();
    assert!(set.is_empty());
    assert!(set
        .sample(Vec3::ZERO, None, 0.5, Vec2::splat(0.5))
        .is_none());
    assert_eq!(set.pdf_environment(Vec3::Y), 0.0);
    assert_eq!(set.pdf_triangle(0, 0, Vec3::ZERO, Vec3::X, Vec3::Y), 0.0);
    // Lights that cannot emit are dropped: zero-area triangles, black emission, black
    // environment, zero intensity.
    let set = LightSet::new(
        vec![(
            PunctualLight::Point {
                intensity: Vec3::ZERO,
                range: None,
            },
            Affine3A::IDENTITY,
            None,
        )],
        vec![
            tri([Vec3::ZERO, Vec3::X, Vec3::X * 2.0], Vec3::ONE, true, 0, 0),
            tri([Vec3::ZERO, Vec3::X, Vec3::Y], Vec3::ZERO, true, 0, 1),
            tri(
                [Vec3::ZERO, Vec3::X, Vec3::splat(f32::NAN)],
                Vec3::ONE,
                true,
                0,
                2,
            ),
        ],
        Environment::Constant(Vec3::ZERO),
        Aabb::EMPTY,
    );
    assert!(set.is_empty());
    assert_eq!(set.len(), 0);
    assert!(set.sample(Vec3::Z, None, 0.1, Vec2::splat(0.3)).is_none());
}

#[test]
fn many_triangles_of_wild_emission_stay_finite() {
    // 12,000 triangles on a grid, emission from 1e-6 to 1e6, some degenerate.
    let mut tris = Vec::new();
    let mut rng = Rng(21);
    for i in 0..12_000u32 {
        let (x, z) = ((i % 120) as f32 * 0.1, (i / 120) as f32 * 0.1);
        let base = Vec3::new(x, 0.0, z);
        let p = if i % 97 == 0 {
            [base, base, base + Vec3::X * 0.05] // zero area
        } else {
            [
                base,
                base + Vec3::new(0.0, 0.0, 0.08),
                base + Vec3::new(0.08, 0.0, 0.0),
            ]
        };
        let emission = Vec3::splat(10f32.powf(rng.f32() * 12.0 - 6.0));
        tris.push(tri(p, emission, i % 3 == 0, 5, i));
    }
    let degenerate = tris.iter().filter(|t| t.triangle % 97 == 0).count();
    let bounds = Aabb::from_points(Vec3::ZERO, Vec3::new(12.0, 1.0, 10.0));
    let set = LightSet::new(
        vec![],
        tris.clone(),
        Environment::Constant(Vec3::splat(1e-3)),
        bounds,
    );
    assert_eq!(set.len(), tris.len() - degenerate + 1);
    assert_eq!(set.pdf_triangle(5, 97, Vec3::Y, Vec3::ZERO, Vec3::Y), 0.0);
    // Reference points above the grid, in its plane and exactly on a light.
    let refs = [
        Vec3::new(3.0, 0.5, 3.0),
        Vec3::new(6.0, 0.0, 5.0),
        Vec3::new(0.02, 0.0, 0.02),
        Vec3::new(-5.0, 1e-7, 2.0),
    ];
    for p in refs {
        for _ in 0..20_000 {
            if let Some(s) = set.sample(p, None, rng.f32(), rng.vec2()) {
                assert!(s.pdf > 0.0 && s.pdf.is_finite(), "pdf {} at {p}", s.pdf);
                assert!(s.wi.is_finite() && (s.wi.length() - 1.0).abs() < 1e-4);
                assert!(s.distance > 0.0);
                if let Emitter::Triangle {
                    instance,
                    triangle,
                    b1,
                    b2,
                    normal,
                } = s.emitter
                {
                    assert!(b1.is_finite() && b2.is_finite() && normal.is_finite());
                    let q = p + s.wi * s.distance;
                    let pdf = set.pdf_triangle(instance, triangle, p, q, normal);
                    assert!(
                        pdf.is_finite() && (pdf - s.pdf).abs() <= 1e-2 * s.pdf,
                        "{pdf} vs {}",
                        s.pdf
                    );
                }
            }
        }
    }
}

/// A triangle of uniform emission is sampled as the radiance it sends, or as nothing
/// towards the back of a single-sided one; a mirroring instance turns its front face
/// against the winding (glTF), which the sampler must know as the integrator did.
#[test]
fn uniform_triangles_carry_their_radiance_and_front_face() {
    let emission = Vec3::new(3.0, 2.0, 1.0);
    // Counter-clockwise seen from +Z: cross(p1 − p0, p2 − p0) points along +Z.
    let p = [
        Vec3::new(-1.0, -1.0, 0.0),
        Vec3::new(1.0, -1.0, 0.0),
        Vec3::new(0.0, 1.0, 0.0),
    ];
    let (above, below) = (Vec3::new(0.1, 0.0, 2.0), Vec3::new(0.1, 0.0, -2.0));
    let seen = |double_sided: bool, mirrored: bool, from: Vec3| {
        let t = EmissiveTriangle {
            uniform: true,
            mirrored,
            ..tri(p, emission, double_sided, 0, 0)
        };
        let set = LightSet::new(vec![], vec![t], Environment::Black, Aabb::EMPTY);
        let s = set.sample(from, None, 0.5, Vec2::new(0.3, 0.6));
        s.map(|s| {
            assert!(s.pdf > 0.0 && !s.delta);
            s.emitter
        })
    };
    let lit = Some(Emitter::Radiance(emission));
    assert_eq!(seen(false, false, above), lit);
    assert_eq!(seen(false, false, below), None);
    assert_eq!(seen(false, true, above), None);
    assert_eq!(seen(false, true, below), lit);
    for (mirrored, from) in [(false, above), (false, below), (true, above), (true, below)] {
        assert_eq!(seen(true, mirrored, from), lit);
    }
    // Textured or vertex-coloured emission is left to the integrator, from either side.
    let varying = LightSet::new(
        vec![],
        vec![tri(p, emission, false, 0, 0)],
        Environment::Black,
        Aabb::EMPTY,
    );
    let s = varying
        .sample(below, None, 0.5, Vec2::new(0.3, 0.6))
        .unwrap();
    assert!(matches!(s.emitter, Emitter::Triangle { .. }));
}

/// A single-sided emitter lights only what its front face looks at, also placed by a
/// mirroring transform, whose front face glTF turns against the winding.
#[test]
fn a_single_sided_emitter_lights_its_front_also_when_mirrored() {
    use glam::{DMat4, Vec4};
    use tracer::material::Material;
    use tracer::scene::SceneBuilder;
    use tracer::shapes::quad;

    // `facing` is the emitter's normal in its mesh; `mirror` scales the mesh by −1 in x,
    // which leaves the (symmetric) quad where it was.
    let wall = |facing: f32, mirror: bool| {
        let mut b = SceneBuilder::default();
        let white = b.material(Material {
            base_color: Vec4::new(0.8, 0.8, 0.8, 1.0),
            metallic: 0.0,
            specular: 0.0,
            ..Material::default()
        });
        let light = b.material(Material {
            emissive: Vec3::splat(4.0),
            double_sided: false,
            ..Material::default()
        });
        let s = 3.0;
        let wall = [[-s, -s], [s, -s], [s, s], [-s, s]].map(|[x, y]| Vec3::new(x, y, 0.0));
        b.mesh("wall", vec![quad(wall, white)], DMat4::IDENTITY);
        let e = 0.5;
        let mut corners = [[-e, -e], [e, -e], [e, e], [-e, e]].map(|[x, y]| Vec3::new(x, y, 1.0));
        if facing < 0.0 {
            corners.reverse();
        }
        let place = if mirror {
            DMat4::from_scale(DVec3::new(-1.0, 1.0, 1.0))
        } else {
            DMat4::IDENTITY
        };
        b.mesh("emitter", vec![quad(corners, light)], place);
        common::camera_on_z(&mut b, 4.0, 0.6);
        b.environment(Environment::Black);
        // The wall's pixels alone (depth 4; the emitter's at 3, and its silhouette between).
        let layers = common::render_square(b.finish(), 16, 16, 4);
        let on_wall: Vec<Vec3> = (layers.beauty.iter().zip(&layers.depth))
            .filter(|(_, d)| **d > 3.999)
            .map(|(p, _)| p.truncate())
            .collect();
        assert!(on_wall.len() > 100);
        on_wall.iter().sum::<Vec3>() / on_wall.len() as f32
    };
    let lit = wall(-1.0, false);
    assert!(lit.x > 0.05, "the emitter faces the wall: {lit}");
    let mirrored = wall(-1.0, true);
    assert!(
        ((mirrored - lit) / lit).abs().max_element() < 0.03,
        "mirrored {mirrored} vs {lit}"
    );
    for mirror in [false, true] {
        let away = wall(1.0, mirror);
        assert_eq!(
            away,
            Vec3::ZERO,
            "the emitter faces away, mirrored: {mirror}"
        );
    }
}

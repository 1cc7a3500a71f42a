//! Tests of the two transmissions that do not enter a solid: the thin wall (glTF's
//! transmission without KHR_materials_volume) and KHR_materials_diffuse_transmission.
//! Chi-square fits of their sampling, their symmetry, and white furnaces.

use super::chi2::Rng;
use super::tests::{chi2_family, furnace_opaque, material, random_direction, wo_at, ROUGHNESS};
use super::*;

/// A thin wall (transmission without KHR_materials_volume) of tinted glass half mixed
/// with plastic, so that both of its lobes and the folds meet the others.
fn thin_wall(roughness: f32, ior: f32) -> SurfaceParams {
    SurfaceParams {
        thin_walled: true,
        ..material(Vec3::new(0.9, 0.6, 0.8), 0.0, roughness, ior, 0.7)
    }
}

#[test]
fn chi2_thin_wall() {
    chi2_family(
        "thin wall",
        |r| thin_wall(r, 1.5),
        &ROUGHNESS,
        &[false, true],
    );
}

#[test]
fn thin_wall_is_the_same_from_both_sides_and_passes_light_straight() {
    let mut rng = Rng::new(5);
    for roughness in [0.0, 0.3, 1.0] {
        let bsdf = Bsdf::new(thin_wall(roughness, 1.5));
        for _ in 0..200 {
            let (wo, wi) = (random_direction(&mut rng), random_direction(&mut rng));
            let (f, pdf) = bsdf.eval_and_pdf(wo, wi);
            let (g, pdf_g) = bsdf.eval_and_pdf(flip(wo), flip(wi));
            assert_eq!((f, pdf), (g, pdf_g), "{roughness} {wo} {wi}");
        }
    }
    // Smooth: what is not reflected leaves along −wo, tinted by (1 − F)·base, no 1/η².
    let bsdf = Bsdf::new(SurfaceParams {
        thin_walled: true,
        ..material(Vec3::new(0.5, 0.25, 1.0), 0.0, 0.0, 1.5, 1.0)
    });
    let wo = wo_at(40.0, false);
    let s = bsdf.sample(wo, 0.99, Vec2::splat(0.5)).expect("transmits");
    let fr = fresnel::dielectric(wo.z, 1.5);
    assert!(s.delta && s.wi == -wo, "{s:?}");
    assert!((s.pdf - (1.0 - fr)).abs() < 1e-6 && fr > 0.0, "{s:?}");
    // Transmitted with probability 1 − F, carrying (1 − F)·base: the weight is the base.
    let weight = s.f * s.wi.z.abs() / s.pdf;
    assert!(
        (weight - Vec3::new(0.5, 0.25, 1.0)).abs().max_element() < 1e-5,
        "{weight}"
    );
}

/// Plastic whose diffuse base passes `dt` of its light to the other side
/// (KHR_materials_diffuse_transmission) in `color`.
fn translucent(base: Vec3, roughness: f32, dt: f32, color: Vec3) -> SurfaceParams {
    SurfaceParams {
        extensions: Some(ExtensionParams {
            diffuse_transmission: dt,
            diffuse_transmission_color: color,
            ..ExtensionParams::default()
        }),
        ..material(base, 0.0, roughness, 1.5, 0.0)
    }
}

#[test]
fn chi2_diffuse_transmission() {
    chi2_family(
        "diffuse transmission",
        |r| translucent(Vec3::new(0.2, 0.8, 0.4), r, 0.6, Vec3::new(0.9, 0.5, 0.1)),
        &ROUGHNESS,
        &[false, true],
    );
}

#[test]
fn furnace_white_diffuse_transmission() {
    // The specular layer takes what it reflects; the diffuse base under it splits the
    // rest between its two sides, and a white base on both loses nothing.
    for dt in [0.3, 1.0] {
        furnace_opaque(
            &format!("diffuse transmission {dt}"),
            |r| translucent(Vec3::ONE, r, dt, Vec3::ONE),
            0.01,
        );
    }
    // The share transmitted is dt times what the layer leaves: with no specular layer,
    // dt itself, at every angle.
    let bsdf = Bsdf::new(SurfaceParams {
        specular: 0.0,
        ..translucent(Vec3::ONE, 0.5, 0.3, Vec3::ONE)
    });
    let mut rng = Rng::new(9);
    for deg in [0.0, 45.0, 85.0] {
        let wo = wo_at(deg, false);
        let n = 100_000;
        let mut through = 0.0;
        for _ in 0..n {
            if let Some(s) = bsdf.sample(wo, rng.f32(), Vec2::new(rng.f32(), rng.f32())) {
                if s.wi.z < 0.0 {
                    through += s.f.x * -s.wi.z / s.pdf;
                }
            }
        }
        let t = through / n as f32;
        assert!((t - 0.3).abs() < 0.005, "{deg}°: transmits {t}");
    }
}

#[test]
fn furnace_white_thin_wall() {
    // Reflection and transmission share one GGX lobe whose Fresnel terms sum to 1, and
    // its Turquin factor is exact there: a white wall returns everything.
    for ior in [1.05, 1.5, 10.0] {
        furnace_opaque(
            &format!("thin wall ior {ior}"),
            |r| SurfaceParams {
                thin_walled: true,
                ..material(Vec3::ONE, 0.0, r, ior, 1.0)
            },
            0.01,
        );
    }
}

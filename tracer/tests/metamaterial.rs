//! TESSERA_materials_metamaterial: negative refraction against the closed forms only such
//! a medium has. A slab of n = −1, impedance-matched, images a point a distance `a` in
//! front of it to a point `d − a` behind it (Veselago's flat lens): a pinhole camera at
//! that image point sees the point source along every one of its rays. Its interface
//! reflects nothing at any angle; any other one follows Stokes' reciprocity; a sphere of
//! it in a white furnace loses nothing.

// Closed forms use the platform's maths; tracer::math is for the tracer.
#![allow(clippy::disallowed_methods)]

use glam::{DMat4, DVec3, Vec2, Vec3, Vec4};
use tracer::bsdf::{Bsdf, ExtensionParams, SurfaceParams};
use tracer::camera::Projection;
use tracer::film::Layers;
use tracer::light::Environment;
use tracer::loader;
use tracer::material::{Material, Metamaterial};
use tracer::scene::{CameraDef, Scene, SceneBuilder};
use tracer::shapes::{cube, quad, uv_sphere};

mod common;

const SIZE: u32 = 32;

fn render(scene: Scene, spp: u32) -> Layers {
    common::render_square(scene, SIZE, spp, 64)
}

/// Clear glass of this negative index and impedance.
fn negative(index: f32, impedance: f32) -> Material {
    Material {
        base_color: Vec4::ONE,
        metallic: 0.0,
        roughness: 0.0,
        transmission: 1.0,
        metamaterial: Some(Metamaterial {
            refractive_index: index,
            impedance,
        }),
        ..Material::default()
    }
}

/// A slab of `slab` between z = −0.5 and z = 0.5 (thickness d = 1), wide enough for
/// rays 88° off its normal; a small emitter of radiance 1 facing it at z = 0.5 + a; and a
/// pinhole camera looking at the slab from z = −0.5 − `behind`, with a 115° field of view.
fn lens(slab: Material, a: f64, behind: f64) -> Scene {
    let mut b = SceneBuilder::default();
    let m = b.material(slab);
    b.mesh(
        "slab",
        vec![cube(m)],
        DMat4::from_scale(DVec3::new(200.0, 200.0, 1.0)),
    );
    let light = b.material(Material {
        base_color: Vec4::new(0.0, 0.0, 0.0, 1.0),
        emissive: Vec3::ONE,
        ..Material::default()
    });
    let (r, z) = (0.05, (0.5 + a) as f32);
    // Facing −z, towards the slab.
    b.mesh(
        "emitter",
        vec![quad(
            [
                Vec3::new(-r, -r, z),
                Vec3::new(-r, r, z),
                Vec3::new(r, r, z),
                Vec3::new(r, -r, z),
            ],
            light,
        )],
        DMat4::IDENTITY,
    );
    // glTF cameras look down their −z: turned around to look up +z.
    b.camera(
        CameraDef {
            name: None,
            projection: Projection::Perspective {
                yfov: 2.0,
                aspect_ratio: None,
                znear: 1e-3,
            },
        },
        DMat4::from_translation(DVec3::new(0.0, 0.0, -0.5 - behind))
            * DMat4::from_rotation_y(std::f64::consts::PI),
    );
    b.environment(Environment::Black);
    b.finish()
}

/// The fraction of pixels that see the emitter (radiance above half), and their mean.
fn lit(layers: &Layers) -> (f64, f64) {
    let seen: Vec<f64> = layers
        .beauty
        .iter()
        .map(|p| f64::from(p.x))
        .filter(|v| *v > 0.5)
        .collect();
    let mean = seen.iter().sum::<f64>() / seen.len().max(1) as f64;
    (seen.len() as f64 / layers.beauty.len() as f64, mean)
}

#[test]
fn a_slab_of_index_minus_one_is_a_perfect_lens() {
    let a = 0.3;
    // At the image point, d − a behind the slab: every ray of the camera, whatever its
    // angle, is carried back to the emitter's centre.
    let focused = render(lens(negative(-1.0, 1.0), a, 1.0 - a), 4);
    let (fraction, mean) = lit(&focused);
    println!(
        "at the image point: {:.1}% of pixels see the emitter, at {mean:.6}",
        fraction * 100.0
    );
    assert_eq!(fraction, 1.0, "every pixel sees the point source");
    let worst = focused
        .beauty
        .iter()
        .map(|p| (p.truncate() - Vec3::ONE).abs().max_element())
        .fold(0.0f32, f32::max);
    assert!(
        worst < 1e-5,
        "a matched n = −1 slab passes everything: {worst}"
    );

    // Half a slab's thickness further back, the rays cross the emitter's plane spread
    // out: only those close to the axis meet it.
    let (fraction, _) = lit(&render(lens(negative(-1.0, 1.0), a, 1.5 - a), 4));
    println!("0.5 further back: {:.1}% of pixels", fraction * 100.0);
    assert!(fraction < 0.1, "out of focus: {fraction}");

    // An ordinary glass slab (n = +1.5) at the same place images nothing there.
    let glass = Material {
        metamaterial: None,
        ior: 1.5,
        thickness: 1.0,
        ..negative(-1.0, 1.0)
    };
    let (fraction, _) = lit(&render(lens(glass, a, 1.0 - a), 4));
    println!("glass of n = +1.5: {:.1}% of pixels", fraction * 100.0);
    assert!(fraction < 0.1, "glass focused the point: {fraction}");
}

fn params(index: f32, impedance: f32) -> SurfaceParams {
    SurfaceParams {
        metallic: 0.0,
        roughness: 0.0,
        transmission: 1.0,
        base_color: Vec3::ONE,
        extensions: Some(ExtensionParams {
            metamaterial_index: index,
            metamaterial_impedance: impedance,
            ..ExtensionParams::default()
        }),
        ..SurfaceParams::default()
    }
}

/// The reflectance at `wo` (the probability of the reflected sample, the only lobe
/// choice), and the refracted direction.
fn interface(bsdf: &Bsdf, wo: Vec3) -> (f32, Option<Vec3>) {
    let reflected = bsdf.sample(wo, 0.0, Vec2::ZERO);
    let r = reflected
        .filter(|s| s.wi.z * wo.z > 0.0)
        .map_or(0.0, |s| s.pdf);
    let refracted = bsdf.sample(wo, 0.999_999, Vec2::ZERO).map(|s| s.wi);
    (r, refracted)
}

#[test]
fn negative_refraction_bends_to_the_same_side_and_is_reciprocal() {
    for deg in [0.0f32, 20.0, 45.0, 70.0, 85.0] {
        let wo = Vec3::new(deg.to_radians().sin(), 0.0, deg.to_radians().cos());
        // Matched n = −1: nothing reflected, and the ray continues mirrored in the normal.
        let (r, wi) = interface(&Bsdf::new(params(-1.0, 1.0)), wo);
        let wi = wi.expect("refracts");
        assert!(r < 1e-7, "{deg}°: reflects {r}");
        assert!(
            (wi - Vec3::new(wo.x, wo.y, -wo.z)).length() < 1e-6,
            "{deg}°: {wi}"
        );

        // n = −1.8, impedance 0.6: Snell with the sign of the index, and Stokes: what
        // reflects from outside at θ reflects from inside at the refracted θt.
        let bsdf = Bsdf::new(params(-1.8, 0.6));
        let (r_out, wi) = interface(&bsdf, wo);
        let wi = wi.expect("refracts");
        assert!(wi.x * wo.x >= 0.0, "{deg}°: bent to the other side: {wi}");
        let sin_t = (1.0 - wi.z * wi.z).sqrt();
        assert!(
            (1.8 * sin_t - deg.to_radians().sin()).abs() < 1e-5,
            "{deg}°: {wi}"
        );
        // Seen from inside, along the refracted ray.
        let (r_in, back) = interface(&bsdf, wi);
        assert!(
            (r_in - r_out).abs() < 1e-5,
            "{deg}°: {r_out} out, {r_in} in"
        );
        // And the way back is the way in.
        assert!((back.expect("leaves") - wo).length() < 1e-5, "{deg}°");
    }
}

#[test]
fn a_metamaterial_sphere_in_a_white_furnace_loses_nothing() {
    // Every choice at a clear interface carries its probability's share of the energy,
    // and a chord of a sphere meets both ends at one angle, so no light is trapped: every
    // path returns exactly 1, whatever n and Z.
    for (n, z) in [(-1.0, 1.0), (-1.5, 0.7), (-0.6, 2.0)] {
        let mut b = SceneBuilder::default();
        let m = b.material(negative(n, z));
        b.mesh("sphere", vec![uv_sphere(m, 32, 64)], DMat4::IDENTITY);
        b.camera(
            CameraDef {
                name: None,
                projection: Projection::Perspective {
                    yfov: 0.6,
                    aspect_ratio: None,
                    znear: 1e-3,
                },
            },
            DMat4::from_translation(DVec3::new(0.0, 0.0, 4.0)),
        );
        b.environment(Environment::Constant(Vec3::ONE));
        let layers = render(b.finish(), 8);
        let worst = layers
            .beauty
            .iter()
            .map(|p| (p.truncate() - Vec3::ONE).abs().max_element())
            .fold(0.0f32, f32::max);
        println!("n {n}, Z {z}: largest deviation from 1: {worst:.2e}");
        assert!(worst < 1e-4, "n {n}, Z {z}: {worst}");
    }
}

#[test]
fn the_extension_is_read_and_refused_as_documented() {
    let doc = |ext: &str| {
        format!(
            r#"{{"asset":{{"version":"2.0"}},"extensionsUsed":["KHR_materials_transmission","TESSERA_materials_metamaterial"],
            "materials":[{{"extensions":{{"KHR_materials_transmission":{{"transmissionFactor":1}},
            "TESSERA_materials_metamaterial":{ext}}}}}]}}"#
        )
    };
    let scene = loader::load_slice(
        doc(r#"{"refractiveIndex":-1.3,"impedance":0.8}"#).as_bytes(),
        None,
    )
    .expect("loads");
    assert_eq!(
        scene.materials[0].metamaterial,
        Some(Metamaterial {
            refractive_index: -1.3,
            impedance: 0.8
        })
    );
    // Nothing about the extension is ignored (the document draws no triangles).
    assert!(
        !scene.warnings.iter().any(|w| w.contains("metamaterial")),
        "{:?}",
        scene.warnings
    );
    let matched =
        loader::load_slice(doc(r#"{"refractiveIndex":-1}"#).as_bytes(), None).expect("loads");
    assert_eq!(
        matched.materials[0].metamaterial.map(|m| m.impedance),
        Some(1.0)
    );
    for (bad, says) in [
        (r#"{"refractiveIndex":1.5}"#, "not a negative number"),
        (r#"{}"#, "not a negative number"),
        (
            r#"{"refractiveIndex":-1,"impedance":0}"#,
            "impedance 0 is not above 0",
        ),
    ] {
        let err = loader::load_slice(doc(bad).as_bytes(), None)
            .expect_err("refused")
            .to_string();
        assert!(err.contains(says), "{bad}: {err}");
    }
}

//! Lights at the extremes: emission from 1e-6 to 1e6, a tiny (1e-10 m²) and a huge (up to
//! 4e14 m²) area light, a point light on a surface, a spot of zero cone angle, 10,000 emissive
//! triangles and light arriving at grazing angles, each against its closed form.
//!
//! Most cases read the radiance of one surface point with a probe: an orthographic camera
//! 0.2 mm wide looking straight at the point, so every pixel sees practically that point.
//! Under direct light only (max depth 1) a white Lambertian surface of albedo ρ then shows
//! L = ρ E / π, with E the closed-form irradiance.

use std::f64::consts::PI;

use glam::{DMat4, DQuat, DVec3, Vec3, Vec4};
use tracer::camera::Projection;
use tracer::film::{SampleRange, TileRect};
use tracer::light::{Environment, PunctualLight};
use tracer::material::Material;
use tracer::render::{render_region, RenderSettings};
use tracer::scene::{CameraDef, Primitive, Scene, SceneBuilder};
use tracer::shapes::quad;

use crate::support::{assert_finite, mean, options, prepare, render, under_root};

/// Albedo of the receiving surfaces.
const RHO: f64 = 0.8;

/// Direct light only: the closed forms below are for one bounce.
const DIRECT: RenderSettings = RenderSettings {
    noise: None,
    max_depth: 1,
    seed: 0,
    ..RenderSettings::DEFAULT
};

/// A white Lambertian material of albedo [`RHO`] (no specular layer), visible from both
/// sides.
fn lambert(b: &mut SceneBuilder) -> u32 {
    b.material(Material {
        base_color: Vec3::splat(RHO as f32).extend(1.0),
        metallic: 0.0,
        roughness: 1.0,
        specular: 0.0,
        double_sided: true,
        ..Default::default()
    })
}

/// A black, one-sided emitter of radiance `radiance`: it reflects nothing, so only its
/// emission counts.
fn emitter(b: &mut SceneBuilder, radiance: f32) -> u32 {
    b.material(Material {
        base_color: Vec4::new(0.0, 0.0, 0.0, 1.0),
        metallic: 0.0,
        specular: 0.0,
        emissive: Vec3::splat(radiance),
        ..Default::default()
    })
}

/// The floor y = 0, |x|, |z| <= `half`, facing up.
fn floor(b: &mut SceneBuilder, half: f32) {
    let m = lambert(b);
    let s = half;
    let f = quad(
        [
            Vec3::new(-s, 0.0, s),
            Vec3::new(s, 0.0, s),
            Vec3::new(s, 0.0, -s),
            Vec3::new(-s, 0.0, -s),
        ],
        m,
    );
    b.mesh("floor", vec![f], DMat4::IDENTITY);
}

/// A horizontal square emitter at height `y`, |x|, |z| <= `half`, facing down.
fn ceiling_light(half: f32, y: f32, material: u32) -> Primitive {
    let s = half;
    quad(
        [
            Vec3::new(-s, y, -s),
            Vec3::new(s, y, -s),
            Vec3::new(s, y, s),
            Vec3::new(-s, y, s),
        ],
        material,
    )
}

/// An orthographic camera of half-height `ymag` at `eye` looking along `dir`.
fn ortho(b: &mut SceneBuilder, eye: DVec3, dir: DVec3, ymag: f32) {
    let camera = CameraDef {
        name: None,
        projection: Projection::Orthographic {
            xmag: ymag,
            ymag,
            znear: 0.0,
        },
    };
    let rotation = DQuat::from_rotation_arc(DVec3::NEG_Z, dir.normalize());
    b.camera(camera, DMat4::from_rotation_translation(rotation, eye));
}

/// A probe: a 0.2 mm wide orthographic camera 0.25 in front of `point`, looking along `dir`.
fn probe_camera(b: &mut SceneBuilder, point: DVec3, dir: DVec3) {
    ortho(b, point - dir.normalize() * 0.25, dir, 1e-4);
}

/// Mean radiance (RGB average) of an 8x8, `spp` render of `scene` (a probe), after checking
/// every layer is finite.
fn read_probe(case: &str, scene: Scene, settings: &RenderSettings, spp: u32) -> f64 {
    let frame = prepare(scene, &options(8, 8));
    let layers = render(&frame, settings, spp);
    assert_finite(case, &layers);
    mean(&layers)
}

/// Prints the row and asserts `measured` is within `tolerance` of `expected`, relative to
/// `expected` (absolute when `expected` is 0). Returns the error.
fn check(case: &str, measured: f64, expected: f64, tolerance: f64) -> f64 {
    let error = if expected == 0.0 {
        measured.abs()
    } else {
        (measured / expected - 1.0).abs()
    };
    let kind = if expected == 0.0 {
        "absolute"
    } else {
        "relative"
    };
    println!(
        "{case}: measured {measured:.6e} (expected {expected:.6e}, tolerance {tolerance} \
         {kind}; error {error:.2e})"
    );
    assert!(
        error <= tolerance,
        "{case}: measured {measured:e}, expected {expected:e} within {tolerance} {kind} \
         (error {error:e})"
    );
    error
}

/// Irradiance at `p` (surface normal `n`) from a uniform Lambertian polygon of radiance 1
/// wholly above `p`'s horizon: Lambert's formula E = ½ Σ Θᵢ (n · Γᵢ), with Θᵢ the angle
/// each edge subtends and Γᵢ the unit normal of the plane through `p` and that edge.
fn polygon_irradiance(p: DVec3, n: DVec3, polygon: &[DVec3]) -> f64 {
    let v: Vec<DVec3> = polygon.iter().map(|q| (*q - p).normalize()).collect();
    let mut sum = 0.0;
    for i in 0..v.len() {
        let (a, b) = (v[i], v[(i + 1) % v.len()]);
        let c = a.cross(b);
        let theta = c.length().atan2(a.dot(b));
        if c.length() > 0.0 {
            sum += theta * n.dot(c.normalize());
        }
    }
    (0.5 * sum).abs()
}

/// Mean over the pixels of a `width` x `height` orthographic view looking down at the
/// floor, centred at (`cx`, `cz`) with half-height `ymag`, of `f(x, z)` averaged over each
/// pixel by a `k` x `k` grid: what a box-filtered render converges to. Row-major like the
/// image.
// Not inlined: with the image size and `k` known at a call site, opt-level 3 unrolled the
// loops into a test binary that took 5 minutes to compile (5 s without).
#[inline(never)]
pub(crate) fn floor_view_expectation(
    width: u32,
    height: u32,
    ymag: f64,
    k: u32,
    f: impl Fn(f64, f64) -> f64,
) -> Vec<f64> {
    let aspect = width as f64 / height as f64;
    let mut out = Vec::with_capacity((width * height) as usize);
    for py in 0..height {
        for px in 0..width {
            let mut sum = 0.0;
            for j in 0..k {
                for i in 0..k {
                    let fx = (px as f64 + (i as f64 + 0.5) / k as f64) / width as f64;
                    let fy = (py as f64 + (j as f64 + 0.5) / k as f64) / height as f64;
                    // Camera +X is world +X and image up is world -Z (looking down -Y).
                    let x = (2.0 * fx - 1.0) * ymag * aspect;
                    let z = -(1.0 - 2.0 * fy) * ymag;
                    sum += f(x, z);
                }
            }
            out.push(sum / (k * k) as f64);
        }
    }
    out
}

/// Emission scaled by 1e-6 … 1e6: the image scales by the same factor. The light sampler
/// chooses by power ratios and Russian roulette by throughput, so every path is the same
/// and the images agree to float rounding.
#[test]
fn emission_from_1e_minus_6_to_1e6_scales_the_image_linearly() {
    let settings = RenderSettings::default();
    let scaled = |k: f32| {
        let mut scene = tracer::demo::cornell_box();
        for m in &mut scene.materials {
            m.emissive *= k;
        }
        let layers = render(&prepare(scene, &options(16, 16)), &settings, 4);
        assert_finite(&format!("emission x{k:e}"), &layers);
        layers
    };
    let unit = scaled(1.0);
    let unit_mean = mean(&unit);
    assert!(unit_mean > 0.01, "the Cornell box is lit: mean {unit_mean}");
    for k in [1e-6f32, 1e-3, 1e3, 1e6] {
        let layers = scaled(k);
        // Largest pixel difference from k x the unit image, relative to k x its mean.
        let worst = layers
            .beauty
            .iter()
            .zip(&unit.beauty)
            .map(|(a, b)| (a.truncate() - b.truncate() * k).abs().max_element() as f64)
            .fold(0.0, f64::max)
            / (k as f64 * unit_mean);
        let ratio = mean(&layers) / unit_mean;
        check(
            &format!("emission x{k:e}: image mean / unit mean"),
            ratio,
            k as f64,
            1e-5,
        );
        check(
            &format!("emission x{k:e}: worst pixel |I_k - k I_1| / (k mean I_1)"),
            worst,
            0.0,
            1e-4,
        );
    }
}

/// A 1e-5 x 1e-5 square light (area 1e-10) of radiance 1e10 at height 1 (intensity
/// I = L·A = 1 cd straight down): E = I cosθ_light cosθ / d² = I d_y² / d⁴ at floor points.
/// The light's corners are rounded to f32 in the camera-relative frame (1e-7 at 1 m, 1% of
/// its side), which shows here as up to 0.3% more light away from the camera's axis.
/// An emitter plane 2e5 or 2e7 m wide of radiance 1 at height 1 over a white floor: the
/// floor shows ρ·L, less the sliver of sky beyond the plane's edges (Lambert's formula).
#[test]
fn tiny_and_huge_area_lights_match_the_closed_form() {
    // Tiny: probe floor points at several distances from the light's foot.
    let (side, radiance, height) = (1e-5f32, 1e10f32, 1.0f64);
    let intensity = (radiance * side * side) as f64;
    for x in [0.0, 0.3, 1.0, 3.0] {
        let mut b = SceneBuilder::default();
        floor(&mut b, 10.0);
        let light = emitter(&mut b, radiance);
        b.mesh(
            "tiny light",
            vec![ceiling_light(side / 2.0, height as f32, light)],
            DMat4::IDENTITY,
        );
        b.environment(Environment::Black);
        probe_camera(&mut b, DVec3::new(x, 0.0, 0.4 * x), DVec3::NEG_Y);
        let d2 = height * height + x * x + 0.16 * x * x;
        let expected = RHO / PI * intensity * height * height / (d2 * d2);
        let got = read_probe("tiny light", b.finish(), &DIRECT, 4);
        check(
            &format!("tiny area light (1e-10), floor point at {x:.1} m from its foot"),
            got,
            expected,
            5e-3,
        );
    }

    // Huge: a 16x16 view of the floor under emitter planes 2e5 and 2e7 m wide.
    for half in [1e5f32, 1e7] {
        let mut b = SceneBuilder::default();
        floor(&mut b, half);
        let light = emitter(&mut b, 1.0);
        b.mesh(
            "huge light",
            vec![ceiling_light(half, 1.0, light)],
            DMat4::IDENTITY,
        );
        b.environment(Environment::Black);
        ortho(&mut b, DVec3::new(0.0, 0.5, 0.0), DVec3::NEG_Y, 0.5);
        let frame = prepare(b.finish(), &options(16, 16));
        let layers = render(&frame, &DIRECT, 4);
        let case = format!("huge area light ({:e} m square, radiance 1)", 2.0 * half);
        assert_finite(&case, &layers);
        let h = half as f64;
        let corners = [
            DVec3::new(-h, 1.0, -h),
            DVec3::new(h, 1.0, -h),
            DVec3::new(h, 1.0, h),
            DVec3::new(-h, 1.0, h),
        ];
        let expected = RHO / PI * polygon_irradiance(DVec3::ZERO, DVec3::Y, &corners);
        let worst = layers
            .beauty
            .iter()
            .map(|b| ((b.x + b.y + b.z) as f64 / 3.0 / expected - 1.0).abs())
            .fold(0.0, f64::max);
        check(
            &format!("{case}: mean floor radiance"),
            mean(&layers),
            expected,
            2e-3,
        );
        check(
            &format!("{case}: worst pixel relative error"),
            worst,
            0.0,
            0.02,
        );
    }
}

/// A point light exactly on the floor and 1 mm above it, with a wall at x = 1. On the
/// floor, E = I h / d³ (0 when the light lies in the floor's plane: light arrives at 90°);
/// on the wall, E = I / d³ (cosθ = 1/d). A whole view with indirect light stays finite.
#[test]
fn point_light_on_a_surface_and_just_above_it() {
    let intensity = 1.0f32;
    let scene = |light_height: f64, camera: &dyn Fn(&mut SceneBuilder)| {
        let mut b = SceneBuilder::default();
        floor(&mut b, 1.0);
        let m = lambert(&mut b);
        let wall = quad(
            [
                Vec3::new(1.0, 0.0, 1.0),
                Vec3::new(1.0, 0.0, -1.0),
                Vec3::new(1.0, 2.0, -1.0),
                Vec3::new(1.0, 2.0, 1.0),
            ],
            m,
        );
        b.mesh("wall", vec![wall], DMat4::IDENTITY);
        b.light(
            PunctualLight::Point {
                intensity: Vec3::splat(intensity),
                range: None,
            },
            DMat4::from_translation(DVec3::new(0.0, light_height, 0.0)),
        );
        b.environment(Environment::Black);
        camera(&mut b);
        b.finish()
    };
    let i = intensity as f64;
    for h in [0.0, 1e-3] {
        for r in [1e-2, 0.1, 1.0] {
            let p = DVec3::new(r * 0.6, 0.0, r * 0.8);
            let s = scene(h, &|b| probe_camera(b, p, DVec3::NEG_Y));
            let d2 = r * r + h * h;
            let expected = RHO / PI * i * h / (d2 * d2.sqrt());
            let got = read_probe("point light on a surface", s, &DIRECT, 4);
            // 0 exactly for a light in the floor's plane; else the closed form.
            let tolerance = if h == 0.0 { 0.0 } else { 5e-3 };
            check(
                &format!("point light {h} m above the floor: floor at {r} m"),
                got,
                expected,
                tolerance,
            );
        }
        for (y, z) in [(0.01, 0.0), (0.5, 0.3), (1.5, -0.8)] {
            let p = DVec3::new(1.0, y, z);
            let s = scene(h, &|b| probe_camera(b, p, DVec3::X));
            let d2 = 1.0 + (y - h) * (y - h) + z * z;
            let expected = RHO / PI * i / (d2 * d2.sqrt());
            let got = read_probe("point light on a surface", s, &DIRECT, 4);
            check(
                &format!("point light {h} m above the floor: wall at y {y}, z {z}"),
                got,
                expected,
                5e-3,
            );
        }
        let s = scene(h, &|b| {
            let camera = CameraDef {
                name: None,
                projection: Projection::Perspective {
                    yfov: 1.2,
                    aspect_ratio: None,
                    znear: 0.01,
                },
            };
            let eye = DVec3::new(-0.8, 0.6, 0.0);
            let look = DQuat::from_rotation_arc(
                DVec3::NEG_Z,
                (DVec3::new(1.0, 0.0, 0.0) - eye).normalize(),
            );
            b.camera(camera, DMat4::from_rotation_translation(look, eye));
        });
        let layers = render(&prepare(s, &options(16, 16)), &RenderSettings::default(), 4);
        assert_finite(&format!("point light {h} m above the floor: view"), &layers);
        println!(
            "point light {h} m above the floor: whole view finite, mean {:.4e}",
            mean(&layers)
        );
    }
}

/// A spot of zero cone angle (inner = outer = 0). KHR_lights_punctual requires
/// 0 <= inner < outer, so such a spot is invalid; its reference falloff
/// saturate((cos − cos outer) / max(0.001, cos inner − cos outer))² is 0 in every
/// direction, and a cone of zero solid angle carries no power. The tracer drops it: the
/// image is black, and adding it to a lit scene changes nothing, bit for bit.
#[test]
fn spot_with_zero_cone_angle_is_black() {
    let spot = |inner: f32, outer: f32| PunctualLight::Spot {
        intensity: Vec3::splat(1e6),
        range: None,
        inner_cone: inner,
        outer_cone: outer,
    };
    let down = DMat4::from_rotation_translation(
        DQuat::from_rotation_x(-std::f64::consts::FRAC_PI_2),
        DVec3::new(0.0, 1.0, 0.0),
    );
    let scene = |lights: &[PunctualLight]| {
        let mut b = SceneBuilder::default();
        floor(&mut b, 2.0);
        for l in lights {
            b.light(*l, down);
        }
        b.environment(Environment::Black);
        ortho(&mut b, DVec3::new(0.0, 0.5, 0.0), DVec3::NEG_Y, 0.5);
        b.finish()
    };
    let settings = RenderSettings::default();
    let image = |lights: &[PunctualLight]| {
        let frame = prepare(scene(lights), &options(16, 16));
        let rect = TileRect::new(0, 0, 16, 16);
        let tile = render_region(&frame, &settings, rect, SampleRange::new(0, 4), 16, &|_| {});
        assert_eq!(tile.dropped, 0, "no sample was NaN or infinite");
        tile.resolve()
    };
    for (inner, outer) in [(0.0, 0.0), (0.0, 1e-9), (f32::NAN, 0.0)] {
        let case = format!("spot cone inner {inner}, outer {outer}");
        let layers = image(&[spot(inner, outer)]);
        assert_finite(&case, &layers);
        let brightest = layers
            .beauty
            .iter()
            .map(|b| b.truncate().max_element() as f64)
            .fold(0.0, f64::max);
        check(&format!("{case}: brightest pixel"), brightest, 0.0, 0.0);
    }
    let point = PunctualLight::Point {
        intensity: Vec3::ONE,
        range: None,
    };
    let lit = image(&[point]);
    let with_spot = image(&[point, spot(0.0, 0.0)]);
    assert!(mean(&lit) > 0.0);
    assert!(
        with_spot == lit,
        "a zero-angle spot added to a point light changes the image"
    );
    println!(
        "spot cone 0 beside a point light: image bit-identical to the point light alone \
         (mean {:.4e})",
        mean(&lit)
    );
}

/// A 1 m² panel of radiance 1 at height 1 made of 10,000 emissive triangles, against the
/// same panel as one quad: both within noise of Lambert's formula at every floor point,
/// and every triangle is in the light sampler's table.
#[test]
fn ten_thousand_emissive_triangles_light_like_one_light_of_the_same_power() {
    let (cols, rows) = (100u32, 50u32);
    let panel = |split: bool| {
        let mut b = SceneBuilder::default();
        floor(&mut b, 4.0);
        let m = emitter(&mut b, 1.0);
        let prim = if split {
            let mut positions = Vec::new();
            for j in 0..=rows {
                for i in 0..=cols {
                    let x = -0.5 + i as f32 / cols as f32;
                    let z = -0.5 + j as f32 / rows as f32;
                    positions.push(Vec3::new(x, 1.0, z));
                }
            }
            let at = |i: u32, j: u32| j * (cols + 1) + i;
            let mut indices = Vec::new();
            for j in 0..rows {
                for i in 0..cols {
                    // Facing down: (x, z) counter-clockwise seen from below.
                    indices.push([at(i, j), at(i + 1, j), at(i + 1, j + 1)]);
                    indices.push([at(i, j), at(i + 1, j + 1), at(i, j + 1)]);
                }
            }
            Primitive {
                normals: vec![Vec3::NEG_Y; positions.len()],
                positions,
                indices,
                material: m,
                ..Default::default()
            }
        } else {
            ceiling_light(0.5, 1.0, m)
        };
        b.mesh("panel", vec![prim], DMat4::IDENTITY);
        b.environment(Environment::Black);
        ortho(&mut b, DVec3::new(0.0, 0.5, 0.0), DVec3::NEG_Y, 1.0);
        b.finish()
    };
    let corners = [
        DVec3::new(-0.5, 1.0, -0.5),
        DVec3::new(0.5, 1.0, -0.5),
        DVec3::new(0.5, 1.0, 0.5),
        DVec3::new(-0.5, 1.0, 0.5),
    ];
    let (w, spp) = (16u32, 64u32);
    let expected = floor_view_expectation(w, w, 1.0, 4, |x, z| {
        RHO / PI * polygon_irradiance(DVec3::new(x, 0.0, z), DVec3::Y, &corners)
    });
    let expected_mean = expected.iter().sum::<f64>() / expected.len() as f64;
    for (name, split) in [("10,000 triangles", true), ("one quad", false)] {
        let frame = prepare(panel(split), &options(w, w));
        let n_lights = frame.lights.len();
        assert_eq!(
            n_lights,
            if split { 10_000 } else { 2 },
            "{name}: every emissive triangle is a light"
        );
        let layers = render(&frame, &DIRECT, spp);
        assert_finite(name, &layers);
        check(
            &format!("{name} ({n_lights} lights): mean floor radiance"),
            mean(&layers),
            expected_mean,
            0.01,
        );
        // 4x4-pixel blocks (256 samples each) against the closed form.
        let mut worst = 0.0f64;
        for by in (0..w).step_by(4) {
            for bx in (0..w).step_by(4) {
                let (mut got, mut want) = (0.0, 0.0);
                for y in by..by + 4 {
                    for x in bx..bx + 4 {
                        let i = (y * w + x) as usize;
                        let b = layers.beauty[i];
                        got += (b.x + b.y + b.z) as f64 / 3.0;
                        want += expected[i];
                    }
                }
                worst = worst.max((got / want - 1.0).abs());
            }
        }
        check(
            &format!("{name}: worst 4x4 block relative error"),
            worst,
            0.0,
            0.03,
        );
    }
}

/// Light arriving nearly parallel to the receiver: a directional light 80° … 89.99° from
/// the floor's normal (E = E⊥ cosθ, also with the whole scene turned by an arbitrary
/// rotation, so the tessellated floor is not axis-aligned), a point light 1 cm and 1 mm
/// above the floor 1 m away (E = I h / d³), and a small area light standing on the
/// horizon (Lambert's formula).
#[test]
fn lights_at_grazing_angles_match_the_closed_form() {
    /// A 16x16-quad floor: shadow rays skim over many triangles.
    fn tessellated_floor(b: &mut SceneBuilder) {
        let m = lambert(b);
        let (n, s) = (16, 2.0f32);
        let mut prims = Vec::new();
        for j in 0..n {
            for i in 0..n {
                let x0 = -s + 2.0 * s * i as f32 / n as f32;
                let z0 = -s + 2.0 * s * j as f32 / n as f32;
                let d = 2.0 * s / n as f32;
                prims.push(quad(
                    [
                        Vec3::new(x0, 0.0, z0 + d),
                        Vec3::new(x0 + d, 0.0, z0 + d),
                        Vec3::new(x0 + d, 0.0, z0),
                        Vec3::new(x0, 0.0, z0),
                    ],
                    m,
                ));
            }
        }
        b.mesh("floor", prims, DMat4::IDENTITY);
    }
    let turned = DMat4::from_quat(DQuat::from_euler(glam::EulerRot::YXZ, 0.7, -0.4, 1.9));
    let point = DVec3::new(0.3, 0.0, -0.3);

    for degrees in [80.0f64, 89.0, 89.9, 89.99] {
        let theta = degrees.to_radians();
        let dir = DVec3::new(theta.sin(), -theta.cos(), 0.0);
        for (frame_name, root) in [("axis-aligned", None), ("turned", Some(turned))] {
            let mut b = SceneBuilder::default();
            tessellated_floor(&mut b);
            b.light(
                PunctualLight::Directional {
                    illuminance: Vec3::ONE,
                },
                DMat4::from_quat(DQuat::from_rotation_arc(DVec3::NEG_Z, dir)),
            );
            b.environment(Environment::Black);
            probe_camera(&mut b, point, DVec3::NEG_Y);
            let mut scene = b.finish();
            if let Some(root) = root {
                scene = under_root(scene, root);
            }
            let got = read_probe("grazing directional", scene, &DIRECT, 4);
            check(
                &format!("directional light {degrees}° from the normal, {frame_name} floor"),
                got,
                RHO / PI * theta.cos(),
                2e-3,
            );
        }
    }

    for h in [1e-2, 1e-3] {
        let mut b = SceneBuilder::default();
        tessellated_floor(&mut b);
        b.light(
            PunctualLight::Point {
                intensity: Vec3::ONE,
                range: None,
            },
            DMat4::from_translation(point + DVec3::new(-1.0, h, 0.0)),
        );
        b.environment(Environment::Black);
        probe_camera(&mut b, point, DVec3::NEG_Y);
        let got = read_probe("grazing point light", b.finish(), &DIRECT, 4);
        let d2: f64 = 1.0 + h * h;
        let expected = RHO / PI * h / (d2 * d2.sqrt());
        check(
            &format!(
                "point light {h} m high, 1 m away ({:.3}° from the normal)",
                (h / d2.sqrt()).acos().to_degrees()
            ),
            got,
            expected,
            5e-3,
        );
    }

    // A 10 cm square emitter standing 1 cm above the floor 1 m away, facing the point:
    // its light arrives between 84° and 89.4° from the normal.
    let (y0, s) = (0.01f64, 0.1f64);
    let corners = [
        DVec3::new(-1.0, y0, 0.05),
        DVec3::new(-1.0, y0, -0.05),
        DVec3::new(-1.0, y0 + s, -0.05),
        DVec3::new(-1.0, y0 + s, 0.05),
    ]
    .map(|c| c + DVec3::new(point.x, 0.0, point.z));
    let mut b = SceneBuilder::default();
    tessellated_floor(&mut b);
    let m = emitter(&mut b, 1.0);
    b.mesh(
        "standing light",
        vec![quad(corners.map(|c| c.as_vec3()), m)],
        DMat4::IDENTITY,
    );
    b.environment(Environment::Black);
    probe_camera(&mut b, point, DVec3::NEG_Y);
    let got = read_probe("grazing area light", b.finish(), &DIRECT, 64);
    let expected = RHO / PI * polygon_irradiance(point, DVec3::Y, &corners);
    check(
        "area light on the horizon (84°-89.4° from the normal)",
        got,
        expected,
        0.01,
    );
}

//! Scale and angles: the Cornell box scaled from 1e-4 to 1e6 and moved 1e6 units away,
//! huge (1e5) walls next to small objects, grazing camera rays along a floor and a wall,
//! and the camera inside closed objects.
//!
//! Scaling or moving a scene, camera included, changes no image: the sampler is keyed by
//! pixel and sample only, so the same paths are traced and the images agree far inside the
//! Monte Carlo noise; the tolerances below are set from that.

use std::f64::consts::FRAC_PI_2;

use glam::{DMat4, DQuat, DVec3, Vec3, Vec4};
use tracer::camera::Projection;
use tracer::film::Layers;
use tracer::light::{Environment, PunctualLight};
use tracer::material::Material;
use tracer::render::RenderSettings;
use tracer::scene::{CameraDef, Node, Primitive, Scene, SceneBuilder};
use tracer::shapes::{cube, quad, uv_sphere};

use super::support::{
    assert_finite, assert_same_image, mean, mean_rgb, options, prepare, render, under_root,
};

fn render_scene(scene: Scene, size: u32, settings: &RenderSettings, spp: u32) -> Layers {
    let frame = prepare(scene, &options(size, size));
    render(&frame, settings, spp)
}

/// The Cornell box as built in (its ceiling light's radiance needs no change at any scale).
fn cornell(_scale: f64) -> Scene {
    tracer::demo::cornell_box()
}

/// The Cornell box with a point light, a spot and a directional light added (intensities
/// multiplied by `scale²`, so that the image is that of the unscaled box once the whole
/// scene is scaled by `scale`: inverse-square falloff).
fn cornell_with_punctual(scale: f64) -> Scene {
    let mut scene = tracer::demo::cornell_box();
    let s2 = (scale * scale) as f32;
    let lights = [
        (
            PunctualLight::Point {
                intensity: Vec3::new(1.0, 0.8, 0.6) * s2,
                range: None,
            },
            DMat4::from_translation(DVec3::new(0.55, 1.5, 0.4)),
        ),
        (
            PunctualLight::Spot {
                intensity: Vec3::new(0.5, 1.0, 1.5) * s2,
                range: None,
                inner_cone: 0.3,
                outer_cone: 0.6,
            },
            // Shines down (-Z turned to -Y) on the floor in front of the tall block.
            DMat4::from_rotation_translation(
                DQuat::from_rotation_x(-FRAC_PI_2),
                DVec3::new(-0.4, 1.8, 0.5),
            ),
        ),
        (
            // In through the open front, onto the floor and the back wall.
            PunctualLight::Directional {
                illuminance: Vec3::splat(0.5),
            },
            DMat4::from_quat(DQuat::from_rotation_arc(
                DVec3::NEG_Z,
                DVec3::new(0.1, -0.5, -1.0).normalize(),
            )),
        ),
    ];
    for (light, local) in lights {
        scene.lights.push(light);
        scene.nodes.push(Node {
            local,
            light: Some(scene.lights.len() as u32 - 1),
            ..Default::default()
        });
        scene.roots.push(scene.nodes.len() as u32 - 1);
    }
    scene.features.punctual_lights = true;
    scene
}

/// Cornell box side in pixels and samples per pixel for the scale and move cases.
const BOX_SIZE: u32 = 32;
const BOX_SPP: u32 = 16;
/// Block size for image comparisons: 4x4 pixels of 16 samples each.
const BLOCK: u32 = 4;
/// Same paths, same noise: a scaled or moved scene may differ from the reference only by
/// the few paths that rounding sends another way. Allowed per 4x4 block, relative to the
/// image mean. Two renders with different seeds differ by 0.085 (the room) to 1.47 (the
/// Cornell box, at the lamp's edge) at these settings; the cases here measure 0.002 at
/// most.
const SAME_PATHS: f64 = 0.01;

#[test]
fn cornell_box_scaled_by_1e_minus_4_to_1e6_renders_the_same_image() {
    let settings = RenderSettings::default();
    for (name, build) in [
        ("ceiling light", cornell as fn(f64) -> Scene),
        ("punctual lights", cornell_with_punctual),
    ] {
        let reference = render_scene(build(1.0), BOX_SIZE, &settings, BOX_SPP);
        assert_finite(&format!("cornell ({name}) reference"), &reference);
        for scale in [1e-4, 1.0, 1e4, 1e6] {
            let case = format!("cornell ({name}) scaled by {scale:e}");
            let scene = under_root(build(scale), DMat4::from_scale(DVec3::splat(scale)));
            let got = render_scene(scene, BOX_SIZE, &settings, BOX_SPP);
            assert_finite(&case, &got);
            println!(
                "{case}: measured mean {:.4} (expected {:.4}, the unscaled box)",
                mean(&got),
                mean(&reference)
            );
            assert_same_image(&case, &got, &reference, BLOCK, SAME_PATHS);
        }
    }
}

#[test]
fn cornell_box_moved_1e4_and_1e6_from_the_origin_renders_the_same_image() {
    let settings = RenderSettings::default();
    // A direction along no axis, so that every coordinate is large.
    let away = DVec3::new(0.6, -0.48, 0.64);
    for (name, build) in [
        ("ceiling light", cornell as fn(f64) -> Scene),
        ("punctual lights", cornell_with_punctual),
    ] {
        let reference = render_scene(build(1.0), BOX_SIZE, &settings, BOX_SPP);
        assert_finite(&format!("cornell ({name}) at the origin"), &reference);
        for distance in [1e4, 1e6] {
            let case = format!("cornell ({name}) moved {distance:e}");
            let scene = under_root(build(1.0), DMat4::from_translation(away * distance));
            let got = render_scene(scene, BOX_SIZE, &settings, BOX_SPP);
            assert_finite(&case, &got);
            println!(
                "{case}: measured mean {:.4} (expected {:.4}, the box at the origin)",
                mean(&got),
                mean(&reference)
            );
            assert_same_image(&case, &got, &reference, BLOCK, SAME_PATHS);
        }
    }
}

fn diffuse(color: f32, emissive: f32) -> Material {
    Material {
        base_color: Vec4::new(color, color, color, 1.0),
        metallic: 0.0,
        roughness: 1.0,
        specular: 0.0,
        emissive: Vec3::splat(emissive),
        double_sided: true,
        ..Default::default()
    }
}

fn perspective(yfov: f32) -> CameraDef {
    CameraDef {
        name: None,
        projection: Projection::Perspective {
            yfov,
            aspect_ratio: None,
            znear: 1e-6,
        },
    }
}

/// How the six walls of the closed room are made.
#[derive(Clone, Copy, Debug)]
enum Walls {
    /// Quads the size of the room.
    Normal,
    /// Quads 2e5 across, their vertices 1e5 from the origin in the mesh itself.
    HugeQuads,
    /// Unit quads scaled to 2e5 across by their node.
    HugeScaledQuads,
    /// Unit cubes scaled to 2e5 and moved 1e5 away by their node, their inner faces on the
    /// room's walls (edupt's walls, spheres of radius 1e5, made of triangles).
    HugeCubes,
}

/// A closed room x, z in [-1, 1], y in [0, 2] with a lamp a millimetre below the ceiling
/// and small objects on the floor, some touching the walls or a millimetre from them; the
/// camera inside. Only the inner faces of the walls can be seen or reached, so every
/// `walls` gives the same image.
fn room(walls: Walls) -> Scene {
    const HUGE: f64 = 1e5;
    let mut b = SceneBuilder::default();
    let white = b.material(diffuse(0.75, 0.0));
    let grey = b.material(diffuse(0.4, 0.0));
    // Single-sided, facing down: the ceiling above it stays dark (no fireflies from rays
    // slipping into the gap between them).
    let light = b.material(Material {
        double_sided: false,
        ..diffuse(0.0, 20.0)
    });
    let v = |x: f32, y: f32, z: f32| Vec3::new(x, y, z);
    // (inward normal axis, its sign, plane position): floor, ceiling, left, right, back,
    // front.
    let planes = [
        (1, 1.0, 0.0),
        (1, -1.0, 2.0),
        (0, 1.0, -1.0),
        (0, -1.0, 1.0),
        (2, 1.0, -1.0),
        (2, -1.0, 1.0),
    ];
    for (i, &(axis, sign, at)) in planes.iter().enumerate() {
        let material = if i == 0 { grey } else { white };
        // The wall's centre on the room's axis (y = 1), and its plane.
        let mut centre = DVec3::new(0.0, 1.0, 0.0);
        centre[axis] = at;
        // A square facing into the room, half-size `half`, around `mid`.
        let square = |mid: DVec3, half: f64| {
            let (u, w) = ((axis + 1) % 3, (axis + 2) % 3);
            let corner = |su: f64, sw: f64| {
                let mut p = mid;
                p[u] += su * half;
                p[w] += sw * half;
                p.as_vec3()
            };
            let mut corners = [
                corner(-1.0, -1.0),
                corner(1.0, -1.0),
                corner(1.0, 1.0),
                corner(-1.0, 1.0),
            ];
            if sign < 0.0 {
                corners.reverse();
            }
            quad(corners, material)
        };
        let (prim, place) = match walls {
            Walls::Normal => (square(centre, 1.0), DMat4::IDENTITY),
            Walls::HugeQuads => (square(centre, HUGE), DMat4::IDENTITY),
            Walls::HugeScaledQuads => (
                square(DVec3::ZERO, 0.5),
                DMat4::from_scale_rotation_translation(
                    DVec3::splat(2.0 * HUGE),
                    DQuat::IDENTITY,
                    centre,
                ),
            ),
            Walls::HugeCubes => {
                centre[axis] -= sign * HUGE;
                (
                    cube(material),
                    DMat4::from_scale_rotation_translation(
                        DVec3::splat(2.0 * HUGE),
                        DQuat::IDENTITY,
                        centre,
                    ),
                )
            }
        };
        b.mesh("wall", vec![prim], place);
    }
    let (hx, y) = (0.2, 1.999);
    b.mesh(
        "light",
        vec![quad(
            [v(-hx, y, -hx), v(hx, y, -hx), v(hx, y, hx), v(-hx, y, hx)],
            light,
        )],
        DMat4::IDENTITY,
    );
    // A block on the floor against the back wall, a small cube in the left back corner, a
    // thin slab a millimetre off the right wall and a small sphere resting on the floor.
    let place =
        |size: DVec3, at: DVec3| DMat4::from_scale_rotation_translation(size, DQuat::IDENTITY, at);
    let objects = [
        (
            cube(white),
            place(DVec3::new(0.5, 0.6, 0.4), DVec3::new(0.2, 0.3, -0.8)),
        ),
        (
            cube(white),
            place(DVec3::splat(0.05), DVec3::new(-0.975, 0.025, -0.975)),
        ),
        (
            cube(white),
            place(DVec3::new(0.01, 0.8, 0.6), DVec3::new(0.994, 0.4, -0.2)),
        ),
        (
            uv_sphere(white, 16, 32),
            place(DVec3::splat(0.1), DVec3::new(-0.4, 0.1, -0.3)),
        ),
    ];
    for (prim, m) in objects {
        b.mesh("object", vec![prim], m);
    }
    b.camera(
        perspective(1.2),
        DMat4::from_translation(DVec3::new(0.0, 1.0, 0.95)),
    );
    b.environment(Environment::Black);
    b.finish()
}

#[test]
fn huge_walls_next_to_small_objects_match_normal_walls() {
    let settings = RenderSettings::default();
    let reference = render_scene(room(Walls::Normal), 32, &settings, 16);
    assert_finite("room of normal walls", &reference);
    for walls in [Walls::HugeQuads, Walls::HugeScaledQuads, Walls::HugeCubes] {
        let case = format!("room of {walls:?} walls");
        let got = render_scene(room(walls), 32, &settings, 16);
        assert_finite(&case, &got);
        println!(
            "{case}: measured mean {:.4} (expected {:.4}, the room of normal walls)",
            mean(&got),
            mean(&reference)
        );
        assert_same_image(&case, &got, &reference, BLOCK, SAME_PATHS);
    }
}

/// Which plane the grazing camera looks along.
#[derive(Clone, Copy, Debug)]
enum Along {
    /// A floor below the camera: the lower half of the image sees it.
    Floor,
    /// A wall left of the camera: the left half of the image sees it.
    Wall,
}

/// Albedo of the grazed plane.
const PLANE_ALBEDO: f32 = 0.5;

/// A plane 1e5 across, `gap` from the camera, which looks along it from `aside` off its
/// centre (sideways, in the plane); a uniform sky of radiance 1. The plane sees only sky
/// over its whole upper hemisphere, so its radiance is exactly its albedo, and the sky half
/// of the image is exactly 1.
fn grazing(along: Along, gap: f64, aside: f64) -> Scene {
    let mut b = SceneBuilder::default();
    let m = b.material(diffuse(PLANE_ALBEDO, 0.0));
    let h = 5e4f32;
    let floor = quad(
        [
            Vec3::new(-h, 0.0, h),
            Vec3::new(h, 0.0, h),
            Vec3::new(h, 0.0, -h),
            Vec3::new(-h, 0.0, -h),
        ],
        m,
    );
    let turn = match along {
        Along::Floor => DQuat::IDENTITY,
        // The floor turned up into the plane x = 0, facing +X.
        Along::Wall => DQuat::from_rotation_z(-FRAC_PI_2),
    };
    b.mesh("plane", vec![floor], DMat4::from_quat(turn));
    b.camera(
        perspective(0.8),
        DMat4::from_translation(turn * DVec3::new(aside, gap, 0.0)),
    );
    b.environment(Environment::Constant(Vec3::ONE));
    b.finish()
}

/// Means of the image's two halves: (plane side, sky side).
fn halves(layers: &Layers, along: Along) -> (f64, f64) {
    let (w, h) = (layers.rect.width as usize, layers.rect.height as usize);
    let (mut plane, mut sky) = (0.0, 0.0);
    for (i, b) in layers.beauty.iter().enumerate() {
        let (x, y) = (i % w, i / w);
        let on_plane = match along {
            Along::Floor => y >= h / 2,
            Along::Wall => x < w / 2,
        };
        let l = (b.x + b.y + b.z) as f64 / 3.0;
        if on_plane {
            plane += l;
        } else {
            sky += l;
        }
    }
    let n = (w * h / 2) as f64;
    (plane / n, sky / n)
}

#[test]
fn grazing_camera_rays_along_a_huge_floor_and_wall_see_the_analytic_radiance() {
    let settings = RenderSettings::default();
    let size = 32;
    let spp = 16;
    // The plane's radiance is estimated from light and BSDF samples: over half the image at
    // these settings it varies by ±0.0006 from seed to seed.
    let tolerance = 0.005;
    // As built; the whole scene turned (no plane along an axis); the camera 4e4 from the
    // plane's centre, far from the origin of the mesh's coordinates.
    let turn = DMat4::from_quat(DQuat::from_euler(glam::EulerRot::YXZ, 0.7, -0.4, 1.1));
    let placements = [
        ("", 0.0, None),
        (", turned", 0.0, Some(turn)),
        (", 4e4 aside", 4e4, None),
    ];
    for along in [Along::Floor, Along::Wall] {
        for gap in [1e-3, 1e-2] {
            for (placed, aside, root) in placements {
                let case = format!("grazing {along:?} seen from {gap:e}{placed}");
                let scene = grazing(along, gap, aside);
                let scene = match root {
                    Some(root) => under_root(scene, root),
                    None => scene,
                };
                let got = render_scene(scene, size, &settings, spp);
                assert_finite(&case, &got);
                let (plane, sky) = halves(&got, along);
                let want = PLANE_ALBEDO as f64;
                println!(
                    "{case}: measured plane {plane:.4} (expected {want}, tolerance {tolerance}), \
                     sky {sky:.6} (expected 1, tolerance 1e-6)"
                );
                assert!(
                    (plane - want).abs() <= tolerance,
                    "{case}: the plane's half of the image is {plane}, expected {want}"
                );
                assert!(
                    (sky - 1.0).abs() <= 1e-6,
                    "{case}: the sky's half of the image is {sky}, expected 1"
                );
            }
        }
    }
}

/// A camera inside a closed, double-sided Lambertian enclosure of albedo `a` emitting `l`:
/// whatever the shape, radiance is uniform and equals l·(1 + a + … + a^depth), the
/// geometric series cut at the path depth (l / (1 − a) without the cut).
fn enclosure_radiance(l: f64, a: f64, max_depth: u32) -> f64 {
    l * (0..=max_depth).map(|k| a.powi(k as i32)).sum::<f64>()
}

#[test]
fn camera_inside_closed_objects_sees_the_analytic_radiance() {
    let settings = RenderSettings {
        noise: None,
        max_depth: 12,
        ..Default::default()
    };
    // 16 spp varies by ±1.2% from seed to seed (albedo 0.8: long paths); 64 by a half.
    let (size, spp) = (16, 64);
    let tolerance = 0.01;
    let sphere: fn(u32) -> Primitive = |m| uv_sphere(m, 24, 48);
    let enclosures = [
        ("sphere", 0.5, 1.0, sphere, DMat4::IDENTITY),
        ("cube", 0.8, 0.5, cube, DMat4::from_scale(DVec3::splat(2.0))),
        (
            // The camera a hair's breadth (1e-4 of the size) inside one face.
            "cube, camera 1e-4 from a wall",
            0.8,
            0.5,
            cube,
            DMat4::from_translation(DVec3::new(0.0, 0.0, 0.4999)),
        ),
    ];
    for (name, albedo, emission, shape, place) in enclosures {
        let case = format!("camera inside an emissive {name} (albedo {albedo})");
        let mut b = SceneBuilder::default();
        let m = b.material(diffuse(albedo, emission));
        b.mesh(name, vec![shape(m)], place);
        b.camera(perspective(1.4), DMat4::IDENTITY);
        b.environment(Environment::Black);
        let got = render_scene(b.finish(), size, &settings, spp);
        assert_finite(&case, &got);
        let want = enclosure_radiance(emission as f64, albedo as f64, settings.max_depth);
        let measured = mean(&got);
        let rel = (measured - want).abs() / want;
        println!(
            "{case}: measured {measured:.4} (expected {want:.4}, tolerance {tolerance} relative)"
        );
        assert!(
            rel <= tolerance,
            "{case}: radiance {measured}, expected {want} (off by {rel:.4})"
        );
    }

    // A closed opaque cube in a bright sky: from inside, nothing leaks in. A single-sided
    // one is culled from behind (glTF), so the camera sees the sky through it.
    for (name, double_sided, want) in [("double-sided", true, 0.0), ("single-sided", false, 1.0)] {
        let case = format!("camera inside a closed {name} white cube in a sky of 1");
        let mut b = SceneBuilder::default();
        let m = b.material(Material {
            double_sided,
            ..diffuse(0.8, 0.0)
        });
        b.mesh("cube", vec![cube(m)], DMat4::IDENTITY);
        b.camera(
            perspective(1.4),
            DMat4::from_translation(DVec3::new(0.1, -0.2, 0.3)),
        );
        b.environment(Environment::Constant(Vec3::ONE));
        let got = render_scene(b.finish(), size, &settings, spp);
        assert_finite(&case, &got);
        let measured = mean_rgb(&got).max_element() as f64;
        println!("{case}: measured {measured:.6} (expected {want}, tolerance 1e-6)");
        assert!(
            (measured - want).abs() <= 1e-6,
            "{case}: radiance {measured}, expected {want}"
        );
    }
}

/// Half-sizes of the lamp in [`lamp_under_ceiling`] (the Cornell box's) and its gap below
/// the ceiling.
const LAMP: (f64, f64, f64) = (0.235, 0.19, 0.1);
/// The ceiling's albedo there.
const CEILING_ALBEDO: f64 = 0.73;

/// A white ceiling (y = 2, 4 across) with a double-sided lamp of radiance 1 hanging
/// [`LAMP`]'s gap below it, seen from below by a camera at y = 1 looking up: the ceiling
/// around the lamp is lit by the lamp's back.
fn lamp_under_ceiling() -> Scene {
    let (hx, hz, gap) = LAMP;
    let mut b = SceneBuilder::default();
    let white = b.material(diffuse(CEILING_ALBEDO as f32, 0.0));
    let lamp = b.material(diffuse(0.5, 1.0));
    let v = |x: f64, y: f64, z: f64| Vec3::new(x as f32, y as f32, z as f32);
    let rect = |hx: f64, y: f64, hz: f64, m: u32| {
        quad(
            [v(-hx, y, -hz), v(hx, y, -hz), v(hx, y, hz), v(-hx, y, hz)],
            m,
        )
    };
    b.mesh("ceiling", vec![rect(2.0, 2.0, 2.0, white)], DMat4::IDENTITY);
    b.mesh("lamp", vec![rect(hx, 2.0 - gap, hz, lamp)], DMat4::IDENTITY);
    b.camera(
        perspective(2.0),
        DMat4::from_rotation_translation(
            DQuat::from_rotation_x(FRAC_PI_2),
            DVec3::new(0.0, 1.0, 0.0),
        ),
    );
    b.environment(Environment::Black);
    b.finish()
}

/// Form factor from a point to a parallel rectangle of radiance 1 `[-hx, hx] x [-hz, hz]`
/// at distance `c`, the point's foot at (x, z): the rectangle's irradiance at the point
/// over π (Hottel's corner formula, combined over the four corners).
fn rectangle_form_factor(x: f64, z: f64, (hx, hz, c): (f64, f64, f64)) -> f64 {
    let corner = |a: f64, b: f64| {
        let (ra, rb) = ((a * a + c * c).sqrt(), (b * b + c * c).sqrt());
        (a / ra * (b / ra).atan() + b / rb * (a / rb).atan()) / std::f64::consts::TAU
    };
    corner(hx - x, hz - z) - corner(-hx - x, hz - z) - corner(hx - x, -hz - z)
        + corner(-hx - x, -hz - z)
}

#[test]
fn a_ceiling_lit_by_a_lamp_just_below_it_matches_the_form_factor() {
    // Direct light only: the ceiling's radiance is albedo x form factor, pixel by pixel.
    let settings = RenderSettings {
        noise: None,
        max_depth: 1,
        ..Default::default()
    };
    let (size, spp) = (32u32, 16);
    let (hx, hz, _) = LAMP;
    // Each pixel's expected value averaged over a 4x4 grid of points in it; pixels whose
    // ceiling point is near the lamp's silhouette (drawn 1/0.9 larger on the ceiling) are
    // left out.
    let tan = 1.0f64.tan();
    let ceiling_point = |fx: f64, fy: f64| {
        let d = DQuat::from_rotation_x(FRAC_PI_2)
            * DVec3::new((2.0 * fx - 1.0) * tan, (1.0 - 2.0 * fy) * tan, -1.0);
        (d.x / d.y, d.z / d.y)
    };
    let mut want = Vec::new();
    for py in 0..size {
        for px in 0..size {
            let (cx, cz) = ceiling_point(
                (px as f64 + 0.5) / size as f64,
                (py as f64 + 0.5) / size as f64,
            );
            if cx.abs() < hx / 0.9 + 0.1 && cz.abs() < hz / 0.9 + 0.1 {
                continue;
            }
            let mut f = 0.0;
            for s in 0..16 {
                let (sx, sy) = ((s % 4) as f64 + 0.5, (s / 4) as f64 + 0.5);
                let (x, z) = ceiling_point(
                    (px as f64 + sx / 4.0) / size as f64,
                    (py as f64 + sy / 4.0) / size as f64,
                );
                f += rectangle_form_factor(x, z, LAMP) / 16.0;
            }
            want.push(((py * size + px) as usize, CEILING_ALBEDO * f));
        }
    }
    let expected = want.iter().map(|(_, w)| w).sum::<f64>() / want.len() as f64;
    // Light and BSDF samples, 16 per pixel, over about 700 pixels: the mean varies by
    // ±1.2% from seed to seed.
    let tolerance = 0.03;
    for scale in [1e-4, 1.0, 1e4] {
        let case = format!("ceiling over a lamp {:e} below it", LAMP.2 * scale);
        let scene = under_root(lamp_under_ceiling(), DMat4::from_scale(DVec3::splat(scale)));
        let got = render_scene(scene, size, &settings, spp);
        assert_finite(&case, &got);
        let measured = want
            .iter()
            .map(|&(i, _)| got.beauty[i].x as f64)
            .sum::<f64>()
            / want.len() as f64;
        let rel = measured / expected - 1.0;
        println!(
            "{case}: measured {measured:.6} (expected {expected:.6}, off by {rel:+.4}, \
             tolerance {tolerance} relative)"
        );
        assert!(
            rel.abs() <= tolerance,
            "{case}: the ceiling's radiance is {measured}, expected {expected} ({rel:+.4})"
        );
    }
}

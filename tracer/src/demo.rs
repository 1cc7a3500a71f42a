//! The built-in demo scenes, authored in code: a Cornell box (after the published Cornell
//! measurements, scaled to a 2 m box) with an area light, a diffuse box, a metal sphere and
//! a glass sphere; still, or animated for the farm's demo. And the spectral showcase
//! ([`fluorescence_scene`]).

use glam::{DMat4, DVec3, Vec3, Vec4};

use crate::animation::{Animation, Channel, Interpolation, Target};
use crate::camera::Projection;
use crate::light::Environment;
use crate::material::Material;
use crate::math;
use crate::scene::{CameraDef, Scene, SceneBuilder, Trs};
use crate::shapes::{cube, quad, uv_sphere};

mod fluorescence;

pub use fluorescence::{fluorescence_scene, FLUORESCENCE_SECONDS, SWITCH_SECONDS};

/// Cornell box wall reflectances (approximations of the measured spectra).
const WHITE: Vec3 = Vec3::new(0.73, 0.73, 0.73);
const RED: Vec3 = Vec3::new(0.63, 0.065, 0.05);
const GREEN: Vec3 = Vec3::new(0.14, 0.45, 0.091);
/// The ceiling light's radiance in nits, the classic warm Cornell light.
const LIGHT: Vec3 = Vec3::new(17.0, 12.0, 4.0);

fn diffuse(name: &str, color: Vec3) -> Material {
    Material {
        name: Some(name.into()),
        base_color: color.extend(1.0),
        metallic: 0.0,
        roughness: 1.0,
        // A path tracer sees walls from inside the box; culling them buys nothing.
        double_sided: true,
        specular: 0.0,
        ..Default::default()
    }
}

/// The empty Cornell box: five white, red and green Lambertian walls, the ceiling light
/// and the camera of the published setup (39.3° vertical field of view). The box spans
/// x, z in [-1, 1] and y in [0, 2]; the camera looks down -Z from z = 3.75, where a square image just
/// sees the inside of the box.
fn cornell_shell(b: &mut SceneBuilder) {
    let white = b.material(diffuse("white", WHITE));
    let red = b.material(diffuse("red", RED));
    let green = b.material(diffuse("green", GREEN));
    // One-sided, as the measured box's lamp: it lights the room below it. Double-sided,
    // it also lit the 2 mm gap above it to about twice its own radiance (the ceiling and
    // the lamp's back reflecting each other), seen through a sliver at its near edge: a
    // light the real box has not, and most of a 16-spp render's squared error.
    let light = b.material(Material {
        emissive: LIGHT,
        double_sided: false,
        ..diffuse("light", Vec3::splat(0.78))
    });
    let v = |x: f32, y: f32, z: f32| Vec3::new(x, y, z);
    let walls = vec![
        quad(
            [
                v(-1., 0., 1.),
                v(1., 0., 1.),
                v(1., 0., -1.),
                v(-1., 0., -1.),
            ],
            white,
        ), // floor
        quad(
            [
                v(-1., 2., -1.),
                v(1., 2., -1.),
                v(1., 2., 1.),
                v(-1., 2., 1.),
            ],
            white,
        ), // ceiling
        quad(
            [
                v(-1., 0., -1.),
                v(1., 0., -1.),
                v(1., 2., -1.),
                v(-1., 2., -1.),
            ],
            white,
        ), // back
        quad(
            [
                v(-1., 0., 1.),
                v(-1., 0., -1.),
                v(-1., 2., -1.),
                v(-1., 2., 1.),
            ],
            red,
        ), // left
        quad(
            [v(1., 0., -1.), v(1., 0., 1.), v(1., 2., 1.), v(1., 2., -1.)],
            green,
        ), // right
    ];
    b.mesh("walls", walls, DMat4::IDENTITY);
    // The light sits just below the ceiling, its front face down; 0.47 × 0.38 m like the
    // original.
    let (hx, hz, y) = (0.235, 0.19, 1.998);
    let lamp = quad(
        [v(-hx, y, -hz), v(hx, y, -hz), v(hx, y, hz), v(-hx, y, hz)],
        light,
    );
    b.mesh("light", vec![lamp], DMat4::IDENTITY);

    let camera = CameraDef {
        name: Some("cornell".into()),
        projection: Projection::Perspective {
            yfov: 39.3f32.to_radians(),
            aspect_ratio: Some(1.0),
            znear: 0.01,
        },
    };
    b.camera(camera, DMat4::from_translation(DVec3::new(0.0, 1.0, 3.75)));
    // Closed but for the front: only the ceiling light lights it.
    b.environment(Environment::Black);
}

/// The measured Cornell box with its two diffuse blocks: the reference scene for
/// benchmarks against other renderers.
pub fn cornell_box() -> Scene {
    let mut b = SceneBuilder::default();
    cornell_shell(&mut b);
    let white = b.material(diffuse("block", WHITE));
    let tall = DMat4::from_scale_rotation_translation(
        DVec3::new(0.6, 1.2, 0.6),
        math::rotation_y_f64(0.29),
        DVec3::new(-0.33, 0.6, -0.3),
    );
    let short = DMat4::from_scale_rotation_translation(
        DVec3::new(0.6, 0.6, 0.6),
        math::rotation_y_f64(-0.3),
        DVec3::new(0.34, 0.3, 0.25),
    );
    b.mesh("tall block", vec![cube(white)], tall);
    b.mesh("short block", vec![cube(white)], short);
    b.finish()
}

/// The demo's objects: a diffuse box, a polished metal sphere and a glass sphere, each
/// placed by a [`Trs`] so that animations can drive them. Returns their nodes.
fn demo_objects(b: &mut SceneBuilder) -> [u32; 3] {
    let block = b.material(diffuse("block", Vec3::new(0.75, 0.7, 0.6)));
    let metal = b.material(Material {
        name: Some("metal".into()),
        base_color: Vec4::new(0.95, 0.93, 0.88, 1.0),
        metallic: 1.0,
        roughness: 0.15,
        double_sided: true,
        ..Default::default()
    });
    let glass = b.material(Material {
        name: Some("glass".into()),
        base_color: Vec4::ONE,
        metallic: 0.0,
        roughness: 0.0,
        transmission: 1.0,
        ior: 1.5,
        // A solid ball (KHR_materials_volume), not a soap bubble: the unit sphere's
        // diameter, in its mesh's units.
        thickness: 2.0,
        ..Default::default()
    });
    let boxy = Trs {
        translation: DVec3::new(-0.4, 0.55, -0.35),
        rotation: math::rotation_y_f64(0.35),
        scale: DVec3::new(0.55, 1.1, 0.55),
    };
    let sphere_at = |r: f64, x: f64, z: f64| Trs {
        translation: DVec3::new(x, r, z),
        scale: DVec3::splat(r),
        ..Trs::default()
    };
    [
        b.mesh_trs("box", vec![cube(block)], boxy),
        b.mesh_trs(
            "metal sphere",
            vec![uv_sphere(metal, 48, 96)],
            sphere_at(METAL_RADIUS, 0.45, -0.45),
        ),
        b.mesh_trs(
            "glass sphere",
            vec![uv_sphere(glass, 48, 96)],
            sphere_at(0.32, 0.15, 0.45),
        ),
    ]
}

const METAL_RADIUS: f64 = 0.35;

/// The demo: the Cornell box with a diffuse box, a polished metal sphere and a glass
/// sphere, standing still.
pub fn demo_scene() -> Scene {
    let mut b = SceneBuilder::default();
    cornell_shell(&mut b);
    demo_objects(&mut b);
    b.finish()
}

/// Seconds one loop of the animated demo lasts: 48 frames at 24 fps.
pub const ANIMATED_DEMO_SECONDS: f64 = 2.0;

/// The demo scene in motion, looping every [`ANIMATED_DEMO_SECONDS`]: the metal sphere
/// bounces twice (a cubic spline whose keys and tangents trace exact parabolas), the box
/// turns half a revolution (rotation keys, slerped), the glass sphere slides left and back
/// (linear keys). Rendered with an open shutter, all three blur.
pub fn animated_demo_scene() -> Scene {
    let mut b = SceneBuilder::default();
    cornell_shell(&mut b);
    let [boxy, metal, glass] = demo_objects(&mut b);

    // Bounce: y(s) = r + 4h·s(1 - s) over each one-second hop, so the speed leaving and
    // reaching the floor is 4h m/s and the top is reached with zero speed.
    let (r, h) = (METAL_RADIUS as f32, 0.6f32);
    let v = 4.0 * h;
    let key = |in_v: f32, y: f32, out_v: f32| [0.0, in_v, 0.0, 0.45, y, -0.45, 0.0, out_v, 0.0];
    let bounce: Vec<f32> = [
        key(-v, r, v),
        key(0.0, r + h, 0.0),
        key(-v, r, v),
        key(0.0, r + h, 0.0),
        key(-v, r, v),
    ]
    .concat();
    let turn: Vec<f32> = (0..=4)
        .flat_map(|k| {
            let angle = 0.35 + std::f32::consts::FRAC_PI_4 * k as f32;
            let q = math::rotation_y(angle);
            [q.x, q.y, q.z, q.w]
        })
        .collect();
    let slide = vec![0.15, 0.32, 0.45, -0.35, 0.32, 0.45, 0.15, 0.32, 0.45];
    b.animation(Animation {
        name: Some("demo".into()),
        properties: Vec::new(),
        channels: vec![
            Channel::new(
                metal,
                Target::Translation,
                Interpolation::CubicSpline,
                vec![0.0, 0.5, 1.0, 1.5, 2.0],
                bounce,
                3,
            ),
            Channel::new(
                boxy,
                Target::Rotation,
                Interpolation::Linear,
                vec![0.0, 0.5, 1.0, 1.5, 2.0],
                turn,
                4,
            ),
            Channel::new(
                glass,
                Target::Translation,
                Interpolation::Linear,
                vec![0.0, 1.0, 2.0],
                slide,
                3,
            ),
        ],
    });
    b.finish()
}

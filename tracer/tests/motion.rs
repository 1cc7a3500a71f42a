//! Motion blur against its analytic answer: an emissive box (a cube stretched to a slab)
//! moving at a known speed under an orthographic camera smears into a linear ramp exactly
//! as wide as it moves while the shutter is open; rigid motion, morphing, skinning and a moving camera all give that
//! same ramp, and a closed shutter gives a sharp edge on the static path.

use std::sync::Arc;

use glam::{DMat4, DVec3, Vec3, Vec4};

use tracer::animation::{Animation, Channel, Interpolation, Sampler, Target};
use tracer::camera::Projection;
use tracer::film::{Layers, SampleRange, TileRect};
use tracer::light::Environment;
use tracer::material::Material;
use tracer::motion::Shutter;
use tracer::render::{prepare_frame, render_region, FrameOptions, PreparedFrame, RenderSettings};
use tracer::scene::{CameraDef, JointSet, MorphTarget, Node, Scene, SceneBuilder, Skin, Trs};
use tracer::shapes::{cube, quad};

/// Image: 64 × 16 pixels of 1/16 world unit each, spanning x in [-2, 2].
const WIDTH: u32 = 64;
const HEIGHT: u32 = 16;
const PIXEL: f64 = 1.0 / 16.0;
/// Frames per second, and the slab's speed in world units per second: 0.5 units (8
/// pixels) per frame.
const FPS: f64 = 4.0;
const SPEED: f64 = 2.0;
/// Frame 2 is at t = 0.5 s, where every setup below puts the slab's centre at x = 0.
const FRAME: i32 = 2;

/// A 16-pixel-wide emissive box spanning the image's height: the unit cube stretched to
/// 1 × 2 × 1, centred on the origin.
fn slab(b: &mut SceneBuilder) -> Vec<tracer::scene::Primitive> {
    let glow = b.material(Material {
        base_color: Vec4::new(0.0, 0.0, 0.0, 1.0),
        emissive: Vec3::ONE,
        double_sided: true,
        ..Default::default()
    });
    let mut box_ = cube(glow);
    box_.positions.iter_mut().for_each(|p| p.y *= 2.0);
    vec![box_]
}

/// An orthographic camera at z = 5 seeing x in [-2, 2], y in [-0.5, 0.5].
fn camera(b: &mut SceneBuilder, local: DMat4) -> u32 {
    let camera = CameraDef {
        name: None,
        projection: Projection::Orthographic {
            xmag: 2.0,
            ymag: 0.5,
            znear: 0.01,
        },
    };
    b.camera(camera, DMat4::from_translation(DVec3::Z * 5.0) * local)
}

/// A LINEAR channel moving `node` along x from `x0` at t = 0 to `x0 + SPEED` at t = 1 s.
fn slide(node: u32, x0: f32, z: f32) -> Animation {
    Animation {
        name: Some("slide".into()),
        properties: Vec::new(),
        channels: vec![Channel {
            node,
            target: Target::Translation,
            sampler: Sampler {
                interpolation: Interpolation::Linear,
                times: vec![0.0, 1.0],
                values: vec![x0, 0.0, z, x0 + SPEED as f32, 0.0, z],
                width: 3,
            },
        }],
    }
}

fn finish(mut b: SceneBuilder) -> Scene {
    b.environment(Environment::Black);
    b.finish()
}

/// The slab's node moves.
fn rigid() -> Scene {
    let mut b = SceneBuilder::default();
    let prims = slab(&mut b);
    let node = b.mesh_trs("slab", prims, Trs::default());
    camera(&mut b, DMat4::IDENTITY);
    b.animation(slide(node, -1.0, 0.0));
    finish(b)
}

/// The slab stands still and the camera moves the other way.
fn moving_camera() -> Scene {
    let mut b = SceneBuilder::default();
    let prims = slab(&mut b);
    b.mesh("slab", prims, DMat4::IDENTITY);
    let cam = camera(&mut b, DMat4::IDENTITY);
    let mut scene = finish(b);
    // The camera node keeps z = 5 and slides from x = +1 to x = -1.
    scene.nodes[cam as usize].trs = Some(Trs {
        translation: DVec3::new(1.0, 0.0, 5.0),
        ..Trs::default()
    });
    scene.animations.push(Animation {
        name: None,
        properties: Vec::new(),
        channels: vec![Channel {
            node: cam,
            target: Target::Translation,
            sampler: Sampler {
                interpolation: Interpolation::Linear,
                times: vec![0.0, 1.0],
                values: vec![1.0, 0.0, 5.0, 1.0 - SPEED as f32, 0.0, 5.0],
                width: 3,
            },
        }],
    });
    scene
}

/// The slab's vertices move by a morph target whose weight rises from 0 to 1 over the
/// second (its node sits at x = -1, the target displaces by SPEED).
fn morphed() -> Scene {
    let mut b = SceneBuilder::default();
    let mut prims = slab(&mut b);
    let n = prims[0].positions.len();
    prims[0].targets = vec![MorphTarget {
        positions: vec![Vec3::new(SPEED as f32, 0.0, 0.0); n],
        ..Default::default()
    }];
    let node = b.mesh_trs(
        "slab",
        prims,
        Trs {
            translation: DVec3::new(-1.0, 0.0, 0.0),
            ..Trs::default()
        },
    );
    camera(&mut b, DMat4::IDENTITY);
    b.animation(Animation {
        name: None,
        properties: Vec::new(),
        channels: vec![Channel {
            node,
            target: Target::Weights,
            sampler: Sampler {
                interpolation: Interpolation::Linear,
                times: vec![0.0, 1.0],
                values: vec![0.0, 1.0],
                width: 1,
            },
        }],
    });
    let mut scene = finish(b);
    scene.meshes[0].weights = vec![0.0];
    scene
}

/// The slab is skinned to one joint, and the joint moves.
fn skinned() -> Scene {
    let mut b = SceneBuilder::default();
    let mut prims = slab(&mut b);
    let n = prims[0].positions.len();
    prims[0].joint_sets = vec![JointSet {
        joints: vec![[0; 4]; n],
        weights: vec![[1.0, 0.0, 0.0, 0.0]; n],
    }];
    // The mesh node's own transform must not apply to a skinned mesh (glTF).
    let mesh_node = b.mesh("slab", prims, DMat4::from_translation(DVec3::X * 100.0));
    camera(&mut b, DMat4::IDENTITY);
    let mut scene = finish(b);
    scene.nodes.push(Node {
        name: Some("joint".into()),
        trs: Some(Trs::default()),
        ..Default::default()
    });
    let joint = scene.nodes.len() as u32 - 1;
    scene.roots.push(joint);
    scene.nodes[mesh_node as usize].skin = Some(0);
    scene.skins.push(Skin {
        name: None,
        joints: vec![joint],
        inverse_bind: vec![DMat4::IDENTITY],
    });
    scene.animations.push(slide(joint, -1.0, 0.0));
    scene
}

fn prepare(scene: Scene, shutter: Shutter) -> PreparedFrame {
    let options = FrameOptions {
        frame: FRAME,
        fps: FPS,
        shutter,
        width: WIDTH,
        height: HEIGHT,
        ..Default::default()
    };
    prepare_frame(Arc::new(scene), &options).expect("scene prepares")
}

fn render(frame: &PreparedFrame, spp: u32) -> Layers {
    let settings = RenderSettings {
        noise: None,
        max_depth: 0,
        seed: 0,
        ..RenderSettings::DEFAULT
    };
    let rect = TileRect::new(0, 0, WIDTH, HEIGHT);
    render_region(
        frame,
        &settings,
        rect,
        SampleRange::new(0, spp),
        16,
        &|_| {},
    )
    .resolve()
}

/// Brightness per column, averaged over the rows.
fn profile(layers: &Layers) -> Vec<f64> {
    (0..WIDTH as usize)
        .map(|x| {
            (0..HEIGHT as usize)
                .map(|y| layers.beauty[y * WIDTH as usize + x].x as f64)
                .sum::<f64>()
                / HEIGHT as f64
        })
        .collect()
}

/// Where, in pixels, the falling right edge of the profile crosses `level` (linear
/// interpolation between pixel centres).
fn crossing(profile: &[f64], level: f64) -> f64 {
    let i = (1..profile.len())
        .rev()
        .find(|&i| profile[i - 1] >= level && profile[i] < level)
        .expect("the profile crosses the level");
    let (a, b) = (profile[i - 1], profile[i]);
    (i - 1) as f64 + 0.5 + (a - level) / (a - b)
}

const HALF_OPEN: Shutter = Shutter {
    open: -0.5,
    close: 0.5,
};

#[test]
fn an_open_shutter_smears_the_edge_over_the_distance_moved() {
    let frame = prepare(rigid(), HALF_OPEN);
    assert!(
        frame.motion && frame.motion_steps >= 2,
        "{}",
        frame.motion_steps
    );
    let p = profile(&render(&frame, 64));
    // The edge moves 0.5 units = 8 pixels while the shutter is open: a linear ramp whose
    // 90 % and 10 % points are 0.8 · 8 = 6.4 pixels apart.
    let moved = SPEED / FPS / PIXEL;
    let width = crossing(&p, 0.1) - crossing(&p, 0.9);
    assert!(
        (width - 0.8 * moved).abs() < 1.0,
        "ramp {width:.2} px, expected {:.2}: {p:?}",
        0.8 * moved
    );
    // The ramp is centred where the edge is at mid-shutter, x = 0.5 -> pixel 40.
    let centre = crossing(&p, 0.5);
    println!(
        "{} motion steps; ramp {width:.2} px (expected {:.2}), centre {centre:.2} px",
        frame.motion_steps,
        0.8 * moved
    );
    assert!((centre - 40.0).abs() < 0.5, "centre {centre:.2}");
    // Smearing moves light around but keeps it: the slab is 16 pixels wide.
    let total: f64 = p.iter().sum();
    assert!((total - 16.0).abs() < 0.25, "total {total:.3}");
}

#[test]
fn a_closed_shutter_takes_the_static_path_with_a_sharp_edge() {
    let frame = prepare(rigid(), Shutter::default());
    assert!(!frame.motion && frame.motion_steps == 1);
    assert!(!frame.bvh.has_motion() && !frame.camera.moves());
    let p = profile(&render(&frame, 16));
    let width = crossing(&p, 0.1) - crossing(&p, 0.9);
    assert!(width < 1.0, "edge spread over {width:.2} px: {p:?}");
    assert!((crossing(&p, 0.5) - 40.0).abs() < 0.5);
}

#[test]
fn a_still_scene_with_an_open_shutter_takes_the_static_path() {
    let mut scene = rigid();
    scene.animations.clear();
    let frame = prepare(scene, HALF_OPEN);
    assert!(!frame.motion && frame.motion_steps == 1);
}

#[test]
fn camera_motion_morphing_and_skinning_blur_like_rigid_motion() {
    let reference = profile(&render(&prepare(rigid(), HALF_OPEN), 64));
    for (name, scene) in [
        ("moving camera", moving_camera()),
        ("morph target", morphed()),
        ("skin", skinned()),
    ] {
        let frame = prepare(scene, HALF_OPEN);
        assert!(frame.motion, "{name}: nothing moves");
        let p = profile(&render(&frame, 64));
        let worst = p
            .iter()
            .zip(&reference)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        println!(
            "{name}: {} motion steps, largest difference {worst:.4}",
            frame.motion_steps
        );
        assert!(
            worst < 0.03,
            "{name}: differs by {worst:.3}\n{p:?}\n{reference:?}"
        );
    }
}

/// The mean motion vector over the pixels the slab covers for the whole shutter
/// (columns 28 to 35: it covers 20-35 at shutter open and 28-43 at close).
fn slab_motion(layers: &Layers) -> (f32, f32, f32) {
    let pixels: Vec<_> = (0..HEIGHT as usize)
        .flat_map(|y| (28..36).map(move |x| y * WIDTH as usize + x))
        .collect();
    let mean = pixels.iter().map(|&i| layers.motion[i]).sum::<glam::Vec2>() / pixels.len() as f32;
    let spread = pixels
        .iter()
        .map(|&i| (layers.motion[i] - mean).abs().max_element())
        .fold(0.0, f32::max);
    (mean.x, mean.y, spread)
}

#[test]
fn motion_vectors_give_the_pixels_moved_over_the_shutter() {
    // The slab moves 0.5 units = 8 pixels to the right while the shutter is open, however
    // it is made to move; the black environment behind an orthographic camera stays put.
    let moved = (SPEED / FPS / PIXEL) as f32;
    for (name, scene) in [
        ("rigid", rigid()),
        ("moving camera", moving_camera()),
        ("morph target", morphed()),
        ("skin", skinned()),
    ] {
        let layers = render(&prepare(scene, HALF_OPEN), 4);
        let (x, y, spread) = slab_motion(&layers);
        println!("{name}: motion ({x:.4}, {y:.4}) px, spread {spread:.2e}");
        assert!(
            (x - moved).abs() < 1e-3 && y.abs() < 1e-3 && spread < 1e-3,
            "{name}: ({x}, {y}) ± {spread}, expected ({moved}, 0)"
        );
        assert_eq!(
            layers.motion[0],
            glam::Vec2::ZERO,
            "{name}: the environment"
        );
    }
    // A closed shutter sees no motion.
    let still = render(&prepare(rigid(), Shutter::default()), 4);
    assert!(still.motion.iter().all(|m| *m == glam::Vec2::ZERO));
}

#[test]
fn explicit_motion_steps_are_used_and_checked() {
    let options = |steps| FrameOptions {
        frame: FRAME,
        fps: FPS,
        shutter: HALF_OPEN,
        motion_steps: Some(steps),
        width: WIDTH,
        height: HEIGHT,
        ..Default::default()
    };
    let scene = Arc::new(rigid());
    assert_eq!(
        prepare_frame(scene.clone(), &options(5))
            .unwrap()
            .motion_steps,
        5
    );
    for bad in [0, 65] {
        let err = prepare_frame(scene.clone(), &options(bad)).err().unwrap();
        assert!(err.to_string().contains("motion steps"), "{err}");
    }
}

/// A point light carried by an animated node lights the floor below where the animation
/// puts it at each frame: the bright spot follows the light, in closed form.
#[test]
fn an_animated_light_moves_with_its_node() {
    use tracer::light::PunctualLight;

    let mut b = SceneBuilder::default();
    let floor = b.material(Material {
        base_color: Vec4::new(0.8, 0.8, 0.8, 1.0),
        metallic: 0.0,
        roughness: 1.0,
        specular: 0.0,
        double_sided: true,
        ..Default::default()
    });
    let v = |x: f32, y: f32| Vec3::new(x, y, 0.0);
    b.mesh(
        "floor",
        vec![quad(
            [v(-2.0, -0.5), v(2.0, -0.5), v(2.0, 0.5), v(-2.0, 0.5)],
            floor,
        )],
        DMat4::IDENTITY,
    );
    camera(&mut b, DMat4::IDENTITY);
    let light = b.light(
        PunctualLight::Point {
            intensity: Vec3::ONE,
            range: None,
        },
        DMat4::IDENTITY,
    );
    let mut scene = finish(b);
    scene.nodes[light as usize].trs = Some(Trs::default());
    // The light hangs 0.5 above the floor and slides along x from -1 (t = 0) to +1 (t = 1).
    scene.animations.push(slide(light, -1.0, 0.5));
    let scene = Arc::new(scene);

    for (frame, x_light) in [(1, -0.5), (3, 0.5)] {
        let options = FrameOptions {
            frame,
            fps: FPS,
            width: WIDTH,
            height: HEIGHT,
            ..Default::default()
        };
        let prepared = prepare_frame(scene.clone(), &options).unwrap();
        assert!(!prepared.motion);
        let settings = RenderSettings {
            noise: None,
            max_depth: 1,
            seed: 0,
            ..RenderSettings::DEFAULT
        };
        let rect = TileRect::new(0, 0, WIDTH, HEIGHT);
        let lit = render_region(
            &prepared,
            &settings,
            rect,
            SampleRange::new(0, 16),
            16,
            &|_| {},
        )
        .resolve();
        // The two middle rows straddle y = 0, the line under the light.
        let w = WIDTH as usize;
        let p: Vec<f64> = (0..w)
            .map(|x| 0.5 * (lit.beauty[7 * w + x].x + lit.beauty[8 * w + x].x) as f64)
            .collect();
        let brightest = (0..p.len()).max_by(|&a, &b| p[a].total_cmp(&p[b])).unwrap();
        // World x maps to pixel column (x + 2) · 16; the light is over a column edge, so
        // the brightest column is one of the two beside it.
        let expected = (x_light + 2.0) * 16.0;
        assert!(
            (brightest as f64 + 0.5 - expected).abs() <= 1.0,
            "frame {frame}: brightest column {brightest}, light above x = {expected} px"
        );
        // The irradiance right under the light is I / h² = 4 lux: radiance 0.8 · 4 / π,
        // less the fall-off across a pixel (under 1 %).
        let peak = p[brightest];
        let expected_peak = 0.8 * 4.0 / std::f64::consts::PI;
        assert!(
            (peak / expected_peak - 1.0).abs() < 0.03,
            "peak {peak}, expected {expected_peak}"
        );
    }
}

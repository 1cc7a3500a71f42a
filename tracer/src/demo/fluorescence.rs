//! The spectral showcase: a ball painted with fluorescent paint rolls across a room,
//! hits a switch, and the light turns from white to ultraviolet: the room goes dark and
//! the ball glows green. While the white light is on, a flint-glass prism on a pedestal
//! shows a white tube on the back wall, seen through it, as a spectrum. Every
//! wavelength-dependent feature in one scene: TESSERA_materials_fluorescence,
//! TESSERA_lights_spectrum, KHR_materials_dispersion and KHR_animation_pointer.

use glam::{DMat4, DQuat, DVec3, DVec4, Vec3, Vec4};

use super::diffuse;
use crate::animation::{
    Animation, Channel, Interpolation, Property, PropertyChannel, Sampler, Target,
};
use crate::camera::Projection;
use crate::light::Environment;
use crate::material::Material;
use crate::math;
use crate::scene::{CameraDef, Scene, SceneBuilder, Trs};
use crate::shapes::{cube, prism, quad, uv_sphere};
use crate::spectrum::{FluorescenceDef, SpectrumShape};

/// Seconds the shot lasts: 48 frames at 24 fps.
pub const FLUORESCENCE_SECONDS: f64 = 2.0;
/// When the ball reaches the switch and the light turns ultraviolet.
pub const SWITCH_SECONDS: f32 = 1.0;

/// The ceiling panels' radiance in nits, white and ultraviolet alike (TESSERA_lights_spectrum
/// gives them the same power).
const PANEL: f32 = 10.0;
/// The white tube on the back wall.
const STRIP: f32 = 12.0;
const BALL_RADIUS: f64 = 0.2;

/// The showcase scene (see the module docs); the switch is at [`SWITCH_SECONDS`].
pub fn fluorescence_scene() -> Scene {
    let mut b = SceneBuilder::default();
    room(&mut b);
    let v = |x: f32, y: f32, z: f32| Vec3::new(x, y, z);

    // The lights: a white panel and an ultraviolet one (a 365 nm blacklight) on the
    // ceiling, and a white strip on the floor behind the prism.
    let white_panel = b.material(Material {
        emissive: Vec3::splat(PANEL),
        ..diffuse("white panel", Vec3::splat(0.8))
    });
    let uv_panel = b.material(Material {
        emissive: Vec3::splat(PANEL),
        emission_spectrum: Some(SpectrumShape::Gaussian {
            peak: 365.0,
            width: 12.0,
        }),
        ..diffuse("ultraviolet panel", Vec3::splat(0.8))
    });
    let strip = b.material(Material {
        emissive: Vec3::splat(STRIP),
        ..diffuse("strip", Vec3::splat(0.8))
    });
    let panel = |x: f32, m| {
        let (h, y) = (0.45, 2.49);
        quad(
            [
                v(x - h, y, h),
                v(x + h, y, h),
                v(x + h, y, -h),
                v(x - h, y, -h),
            ],
            m,
        )
    };
    b.mesh(
        "ceiling panels",
        vec![panel(-0.7, white_panel), panel(0.7, uv_panel)],
        DMat4::IDENTITY,
    );
    // The tube on the back wall that the camera sees through the prism.
    let (y, w) = (2.1, 0.015);
    b.mesh(
        "wall tube",
        vec![quad(
            [
                v(0.9, y - w, -1.499),
                v(2.0, y - w, -1.499),
                v(2.0, y + w, -1.499),
                v(0.9, y + w, -1.499),
            ],
            strip,
        )],
        DMat4::IDENTITY,
    );

    // The prism: flint glass (Abbe number 13) on a stand on a pedestal, its edge along
    // x, apex down and tilted so that the camera sees the tube on the back wall through
    // it, near its minimum deviation: each wavelength of the tube's light shows at its
    // own height.
    let flint = b.material(Material {
        name: Some("flint glass".into()),
        base_color: Vec4::ONE,
        metallic: 0.0,
        roughness: 0.0,
        transmission: 1.0,
        thickness: 0.3,
        ior: 1.6,
        dispersion: 1.5,
        ..Default::default()
    });
    let stone = b.material(diffuse("pedestal", Vec3::new(0.35, 0.33, 0.3)));
    let block = |size: DVec3, centre: DVec3| {
        DMat4::from_scale_rotation_translation(size, DQuat::IDENTITY, centre)
    };
    b.mesh(
        "pedestal",
        vec![cube(stone)],
        block(DVec3::new(0.5, 0.7, 0.3), DVec3::new(1.1, 0.35, -0.45)),
    );
    b.mesh(
        "stand",
        vec![cube(stone)],
        block(DVec3::new(0.03, 0.16, 0.03), DVec3::new(1.1, 0.78, -0.45)),
    );
    // Local x (the light's way through it) along −z, local z (its edge) along x; turned
    // about its centroid.
    let height = 0.26;
    let axes = DMat4::from_cols(
        DVec4::new(0.0, 0.0, -1.0, 0.0),
        DVec4::new(0.0, 1.0, 0.0, 0.0),
        DVec4::new(1.0, 0.0, 0.0, 0.0),
        DVec4::W,
    );
    let prism_at = DMat4::from_rotation_translation(
        math::rotation_x_f64(200f64.to_radians()),
        DVec3::new(1.1, 1.0, -0.45),
    ) * axes
        * DMat4::from_translation(DVec3::new(0.0, -height / 3.0, 0.0));
    b.mesh(
        "prism",
        vec![prism(
            flint,
            std::f32::consts::FRAC_PI_3,
            height as f32,
            0.5,
        )],
        prism_at,
    );

    // The ball, the switch it rolls into, and the shot's animation.
    let paint = b.material(Material {
        name: Some("fluorescent paint".into()),
        base_color: Vec4::new(0.75, 0.8, 0.35, 1.0),
        metallic: 0.0,
        specular: 0.0,
        fluorescence: Some(FluorescenceDef {
            excitation: SpectrumShape::Gaussian {
                peak: 400.0,
                width: 90.0,
            },
            emission: SpectrumShape::Gaussian {
                peak: 520.0,
                width: 40.0,
            },
            concentration: 0.9,
            quantum_yield: 0.9,
        }),
        ..Default::default()
    });
    let ball = b.mesh_trs(
        "ball",
        vec![uv_sphere(paint, 48, 96)],
        Trs {
            translation: DVec3::new(-1.4, BALL_RADIUS, 0.35),
            scale: DVec3::splat(BALL_RADIUS),
            ..Trs::default()
        },
    );
    let switch = b.material(diffuse("switch", Vec3::new(0.7, 0.08, 0.05)));
    b.mesh(
        "switch",
        vec![cube(switch)],
        DMat4::from_scale_rotation_translation(
            DVec3::new(0.15, 0.3, 0.3),
            glam::DQuat::IDENTITY,
            DVec3::new(0.375, 0.15, 0.35),
        ),
    );
    let (x0, x1) = (-1.4f32, 0.1f32);
    // Rolling without slipping: the angle is the distance over the radius.
    let turn = (x1 - x0) / BALL_RADIUS as f32;
    // Keys less than half a turn apart, so that each slerp turns the way the ball rolls.
    let roll: Vec<f32> = (0..=4)
        .flat_map(|k| math::rotation_z(-turn * k as f32 / 4.0).to_array())
        .collect();
    let step = |on: f32, off: f32| Sampler {
        interpolation: Interpolation::Step,
        times: vec![0.0, SWITCH_SECONDS],
        values: vec![on, on, on, off, off, off],
        width: 3,
    };
    b.animation(Animation {
        name: Some("switch".into()),
        channels: vec![
            Channel::new(
                ball,
                Target::Translation,
                Interpolation::Linear,
                vec![0.0, SWITCH_SECONDS],
                vec![x0, BALL_RADIUS as f32, 0.35, x1, BALL_RADIUS as f32, 0.35],
                3,
            ),
            Channel::new(
                ball,
                Target::Rotation,
                Interpolation::Linear,
                (0..=4).map(|k| SWITCH_SECONDS * k as f32 / 4.0).collect(),
                roll,
                4,
            ),
        ],
        properties: vec![
            PropertyChannel {
                property: Property::Emission(white_panel),
                sampler: step(PANEL, 0.0),
            },
            PropertyChannel {
                property: Property::Emission(strip),
                sampler: step(STRIP, 0.0),
            },
            PropertyChannel {
                property: Property::Emission(uv_panel),
                sampler: step(0.0, PANEL),
            },
        ],
    });

    let camera = CameraDef {
        name: Some("showcase".into()),
        projection: Projection::Perspective {
            yfov: 50f32.to_radians(),
            aspect_ratio: None,
            znear: 0.01,
        },
    };
    let eye = DVec3::new(0.0, 1.25, 3.3);
    let target = DVec3::new(0.1, 0.55, -0.3);
    b.camera(camera, DMat4::look_at_rh(eye, target, DVec3::Y).inverse());
    b.environment(Environment::Black);
    b.finish()
}

/// A room of grey walls, 4 m wide, 3 m deep and 2.5 m high, open at the front.
fn room(b: &mut SceneBuilder) {
    let wall = b.material(diffuse("wall", Vec3::splat(0.6)));
    let floor = b.material(diffuse("floor", Vec3::new(0.45, 0.42, 0.4)));
    let v = |x: f32, y: f32, z: f32| Vec3::new(x, y, z);
    let (x, y, z) = (2.0, 2.5, 1.5);
    b.mesh(
        "room",
        vec![
            quad(
                [v(-x, 0., z), v(x, 0., z), v(x, 0., -z), v(-x, 0., -z)],
                floor,
            ),
            quad([v(-x, y, -z), v(x, y, -z), v(x, y, z), v(-x, y, z)], wall),
            quad(
                [v(-x, 0., -z), v(x, 0., -z), v(x, y, -z), v(-x, y, -z)],
                wall,
            ),
            quad(
                [v(-x, 0., z), v(-x, 0., -z), v(-x, y, -z), v(-x, y, z)],
                wall,
            ),
            quad([v(x, 0., -z), v(x, 0., z), v(x, y, z), v(x, y, -z)], wall),
        ],
        DMat4::IDENTITY,
    );
}

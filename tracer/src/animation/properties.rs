//! What KHR_animation_pointer animates beyond node transforms: a light's colour and
//! intensity, a material's emission and factors. A frame takes their values at the middle
//! of its shutter (as it places punctual lights), so a light switches between frames, not
//! within one.

use glam::{Vec3, Vec4};

use super::Sampler;
use crate::light::PunctualLight;
use crate::material::Material;
use crate::scene::Scene;

/// A property of a light or a material that an animation drives.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Property {
    /// Light `i`'s colour × intensity (3 values per key): what
    /// [`PunctualLight`]'s intensity or illuminance holds.
    Light(u32),
    /// Material `i`'s emission, emissiveFactor × KHR_materials_emissive_strength (3 values).
    Emission(u32),
    /// Material `i`'s baseColorFactor (4 values).
    BaseColor(u32),
    /// Material `i`'s metallicFactor (1 value).
    Metallic(u32),
    /// Material `i`'s roughnessFactor (1 value).
    Roughness(u32),
}

impl Property {
    /// Values per key.
    pub fn width(self) -> usize {
        match self {
            Property::Light(_) | Property::Emission(_) => 3,
            Property::BaseColor(_) => 4,
            Property::Metallic(_) | Property::Roughness(_) => 1,
        }
    }

    /// The material it drives, if it drives one.
    pub fn material(self) -> Option<u32> {
        match self {
            Property::Light(_) => None,
            Property::Emission(m)
            | Property::BaseColor(m)
            | Property::Metallic(m)
            | Property::Roughness(m) => Some(m),
        }
    }
}

/// One channel driving a [`Property`].
#[derive(Clone, Debug)]
pub struct PropertyChannel {
    /// What it drives.
    pub property: Property,
    /// Keyframes (`property.width()` values each) and how to interpolate them.
    pub sampler: Sampler,
}

/// Whether an animation turns some material's emission on (a material can be dark in
/// the file and glow later).
pub fn animates_emission(scene: &Scene) -> bool {
    scene
        .animations
        .iter()
        .flat_map(|a| &a.properties)
        .any(|p| {
            matches!(p.property, Property::Emission(_)) && p.sampler.values.iter().any(|&v| v > 0.0)
        })
}

/// Each property channel of the chosen animations (indices into [`Scene::animations`]),
/// in order, with its value at `time` (seconds); a later channel driving the same
/// property wins when applied in this order.
fn values_at(scene: &Scene, animations: &[usize], time: f64) -> Vec<(Property, [f64; 4])> {
    let mut out = Vec::new();
    for &a in animations {
        let Some(anim) = scene.animations.get(a) else {
            continue;
        };
        for ch in &anim.properties {
            if ch.sampler.keys() == 0 || ch.sampler.width != ch.property.width() {
                continue;
            }
            let mut v = [0.0; 4];
            ch.sampler.sample(time, &mut v[..ch.sampler.width]);
            out.push((ch.property, v));
        }
    }
    out
}

/// The scene's punctual lights at `time` with `animations` playing. A negative value (a
/// cubic spline overshooting 0) is no light.
pub fn lights_at(scene: &Scene, animations: &[usize], time: f64) -> Vec<PunctualLight> {
    let mut lights = scene.lights.clone();
    for (property, v) in values_at(scene, animations, time) {
        let Property::Light(i) = property else {
            continue;
        };
        let Some(light) = lights.get_mut(i as usize) else {
            continue;
        };
        let value = Vec3::new(v[0] as f32, v[1] as f32, v[2] as f32).max(Vec3::ZERO);
        match light {
            PunctualLight::Point { intensity, .. } | PunctualLight::Spot { intensity, .. } => {
                *intensity = value
            }
            PunctualLight::Directional { illuminance } => *illuminance = value,
        }
    }
    lights
}

/// The scene's materials at `time` with `animations` playing, where they drive any
/// material; `None` where the scene's materials stand. Values are clamped to their
/// ranges (a cubic spline may overshoot them).
pub fn materials_at(scene: &Scene, animations: &[usize], time: f64) -> Option<Vec<Material>> {
    let values = values_at(scene, animations, time);
    if !values.iter().any(|(p, _)| p.material().is_some()) {
        return None;
    }
    let mut materials = scene.materials.clone();
    for (property, v) in values {
        let Some(m) = property
            .material()
            .and_then(|m| materials.get_mut(m as usize))
        else {
            continue;
        };
        let unit = |x: f64| (x as f32).clamp(0.0, 1.0);
        match property {
            Property::Light(_) => {}
            Property::Emission(_) => {
                m.emissive = Vec3::new(v[0] as f32, v[1] as f32, v[2] as f32).max(Vec3::ZERO)
            }
            Property::BaseColor(_) => {
                m.base_color = Vec4::new(unit(v[0]), unit(v[1]), unit(v[2]), unit(v[3]))
            }
            Property::Metallic(_) => m.metallic = unit(v[0]),
            Property::Roughness(_) => m.roughness = unit(v[0]),
        }
    }
    Some(materials)
}

//! The light set of one prepared frame and the sampler that picks a light for next-event
//! estimation.
//!
//! Lights are chosen with probability proportional to an estimate of their power, with an
//! alias table (O(1) per choice, O(n) to build):
//!
//! | light | power estimate |
//! |---|---|
//! | emissive triangle | area · π · luminance(emission), × 2 if double-sided |
//! | point | 4π · luminance(I) |
//! | spot | luminance(I) · ∫ attenuation dω (exact for the glTF falloff) |
//! | directional | π r² · luminance(E) |
//! | environment | π r² · ∫ luminance(L) dω (= 4π · π r² · L for a constant) |
//!
//! with r the radius of the scene's bounding sphere. Lights that cannot emit (zero area,
//! zero intensity, a spot cone of zero angle, a black environment) are left out, so they
//! are never chosen and their pdfs are 0.
//!
//! # What the integrator does with a sample
//! * `delta` samples (punctual lights): contribution = f · |cos θ| · L / pdf, with
//!   `L` = [`Emitter::Radiance`] (already I·attenuation/d² or E). No MIS: a BSDF-sampled
//!   ray never hits them.
//! * Triangle samples of uniform emission (no texture, no vertex colours): the sampler
//!   knows the radiance and the front face (static instances only are in the set), so it
//!   returns [`Emitter::Radiance`], or `None` towards a single-sided triangle's back.
//! * Other triangle samples: evaluate the emission at (b1, b2) of that instance's triangle and
//!   keep it only if the triangle emits towards the reference point: for a one-sided
//!   material the reference point must be on the front side, i.e.
//!   `dot(front_normal, -wi) > 0`, where `front_normal` is the `normal` of [`Emitter::Triangle`]
//!   (the unflipped cross(p1 − p0, p2 − p0)) negated when the instance mirrors (negative
//!   determinant: glTF's winding rule). The sampler does not cull back faces itself
//!   because it cannot know the instance's winding; checking before tracing the shadow ray
//!   saves it. MIS weight with the BSDF pdf as usual.
//! * When a BSDF-sampled ray hits an emissive triangle, its light pdf for MIS is
//!   [`LightSet::pdf_triangle`]; when it escapes, [`LightSet::pdf_environment`].

use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hasher};

use glam::{Affine3A, Vec2, Vec3};

use super::distribution::AliasTable;
use super::punctual::WorldPunctual;
use super::triangle::TriangleLight;
use super::{EmissiveTriangle, Environment, PunctualLight};
use crate::geometry::Aabb;
use crate::math;

/// A light sampled from a reference point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LightSample {
    /// Unit direction from the reference point towards the light.
    pub wi: Vec3,
    /// Distance to the sampled point; `f32::INFINITY` for directional lights and the
    /// environment.
    pub distance: f32,
    /// For area lights and the environment: the solid-angle density of `wi`, including the
    /// probability of having chosen this light. For delta lights (`delta == true`): that
    /// selection probability alone.
    pub pdf: f32,
    /// Whether the light is a delta light (punctual), which no BSDF-sampled ray can hit.
    pub delta: bool,
    /// What the light sends.
    pub emitter: Emitter,
    /// The spectrum the light's colour filters (TESSERA_lights_spectrum), as the light set
    /// was given it; `None` for light whose colour lifts to a spectrum like any other.
    pub spectrum: Option<u32>,
}

/// What a sampled light sends towards the reference point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Emitter {
    /// Known incident light: for punctual lights the value to use in place of radiance
    /// (I · spot attenuation / d², or the directional E), so that the contribution is
    /// f · |cos θ| · L / pdf; for the environment and a uniformly emitting triangle, the
    /// radiance from `wi`.
    Radiance(Vec3),
    /// A point on an emissive triangle; the integrator evaluates the (possibly textured)
    /// emission there and checks the side (see the [module docs](crate::light::sampler)).
    Triangle {
        /// Instance of the triangle.
        instance: u32,
        /// Triangle index within the instance's mesh.
        triangle: u32,
        /// Barycentric weight of the triangle's second vertex.
        b1: f32,
        /// Barycentric weight of the triangle's third vertex.
        b2: f32,
        /// Unit geometric normal cross(p1 − p0, p2 − p0), not flipped towards the
        /// reference point.
        normal: Vec3,
    },
}

/// One light of the set, in the order of the selection table.
#[derive(Clone, Debug)]
enum Light {
    /// A punctual light, and its spectrum if it has its own.
    Punctual(WorldPunctual, Option<u32>),
    Triangle(TriangleLight),
    Environment,
}

/// Hasher for the (instance, triangle) lookup: keys are already well-spread integers, so
/// one multiply (Fibonacci hashing) beats SipHash on every BSDF hit of an emitter.
#[derive(Clone, Copy, Debug, Default)]
struct KeyHasher(u64);

impl Hasher for KeyHasher {
    fn finish(&self) -> u64 {
        self.0
    }

    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.0 = (self.0.rotate_left(8) ^ b as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15);
        }
    }

    fn write_u64(&mut self, k: u64) {
        let h = (self.0 ^ k).wrapping_mul(0x9E37_79B9_7F4A_7C15);
        self.0 = h ^ (h >> 29);
    }
}

fn key(instance: u32, triangle: u32) -> u64 {
    (instance as u64) << 32 | triangle as u64
}

/// The lights of one prepared frame, in camera-relative world space, with the table that
/// chooses among them. Build it once per frame; it is shared read-only by all threads.
#[derive(Clone, Debug)]
pub struct LightSet {
    lights: Vec<Light>,
    /// `None` when no light can emit: sampling then returns `None`.
    table: Option<AliasTable>,
    /// (instance, triangle) → index in `lights`.
    triangle_index: HashMap<u64, u32, BuildHasherDefault<KeyHasher>>,
    /// Index of the environment in `lights`, if it emits.
    environment_index: Option<u32>,
    environment: Environment,
}

impl Default for LightSet {
    /// The empty set: no lights, black environment.
    fn default() -> Self {
        Self::new(Vec::new(), Vec::new(), Environment::Black, Aabb::EMPTY)
    }
}

impl LightSet {
    /// Builds the set in O(n).
    ///
    /// * `punctual`: each light with its node → world transform, and the spectrum its
    ///   light samples carry ([`LightSample::spectrum`]).
    /// * `triangles`: emissive triangles in world space. Degenerate ones (zero area,
    ///   non-finite vertices) and ones that emit nothing are skipped; a repeated
    ///   (instance, triangle) keeps its first entry.
    /// * `environment`: light from infinitely far away.
    /// * `bounds`: the scene's world bounds, for the power of directional lights and the
    ///   environment (an empty box counts as radius 1).
    pub fn new(
        punctual: Vec<(PunctualLight, Affine3A, Option<u32>)>,
        triangles: Vec<EmissiveTriangle>,
        environment: Environment,
        bounds: Aabb,
    ) -> Self {
        let radius = if bounds.is_empty() {
            0.0
        } else {
            0.5 * bounds.extent().length()
        };
        let radius = if radius > 0.0 && radius.is_finite() {
            radius
        } else {
            1.0
        };
        let pi_r2 = std::f64::consts::PI * (radius as f64) * (radius as f64);

        let mut lights = Vec::with_capacity(punctual.len() + triangles.len() + 1);
        let mut power = Vec::with_capacity(lights.capacity());
        for (light, to_world, spectrum) in &punctual {
            if let Some(l) = WorldPunctual::new(light, to_world) {
                let p = l.power(radius);
                if p > 0.0 && p.is_finite() {
                    lights.push(Light::Punctual(l, *spectrum));
                    power.push(p);
                }
            }
        }
        let mut triangle_index =
            HashMap::with_capacity_and_hasher(triangles.len(), BuildHasherDefault::default());
        for t in &triangles {
            let Some(l) = TriangleLight::new(t) else {
                continue;
            };
            let sides = if t.double_sided { 2.0 } else { 1.0 };
            let p =
                l.area as f64 * std::f64::consts::PI * super::luminance(t.emission) as f64 * sides;
            if !(p > 0.0 && p.is_finite()) {
                continue;
            }
            if let std::collections::hash_map::Entry::Vacant(e) =
                triangle_index.entry(key(t.instance, t.triangle))
            {
                e.insert(lights.len() as u32);
                lights.push(Light::Triangle(l));
                power.push(p);
            }
        }
        let mut environment_index = None;
        let env_power = pi_r2 * environment.luminance_integral() as f64;
        if env_power > 0.0 && env_power.is_finite() {
            environment_index = Some(lights.len() as u32);
            lights.push(Light::Environment);
            power.push(env_power);
        }
        let table = AliasTable::new(&power);
        Self {
            lights,
            table,
            triangle_index,
            environment_index,
            environment,
        }
    }

    /// Number of lights that can be chosen.
    pub fn len(&self) -> usize {
        self.lights.len()
    }

    /// Whether there is no light to sample.
    pub fn is_empty(&self) -> bool {
        self.table.is_none()
    }

    /// The environment (also when it is black and never sampled).
    pub fn environment(&self) -> &Environment {
        &self.environment
    }

    /// Index of the light for emissive triangle (instance, triangle), if it is in the set.
    pub fn triangle_light(&self, instance: u32, triangle: u32) -> Option<u32> {
        self.triangle_index.get(&key(instance, triangle)).copied()
    }

    /// Probability that [`Self::sample`] chooses light `index`.
    pub fn selection_probability(&self, index: u32) -> f32 {
        self.table
            .as_ref()
            .map_or(0.0, |t| t.probability(index as usize))
    }

    /// Chooses a light with `u_light` and a point or direction on it with `u`, as seen from
    /// the reference point `p`. `n` (the surface normal at `p`) is accepted for future use
    /// and ignored now, so that the pdfs do not depend on it. `None` when there is no light,
    /// or the chosen one sends nothing to `p` this time (outside a spot cone, `p` on the
    /// light itself): the estimate for this sample is then zero.
    pub fn sample(&self, p: Vec3, n: Option<Vec3>, u_light: f32, u: Vec2) -> Option<LightSample> {
        let _ = n;
        let (index, selection) = self.table.as_ref()?.sample(u_light);
        if selection <= 0.0 {
            return None;
        }
        match &self.lights[index] {
            Light::Punctual(l, spectrum) => {
                let s = l.sample(p)?;
                Some(LightSample {
                    wi: s.wi,
                    distance: s.distance,
                    pdf: selection,
                    delta: true,
                    emitter: Emitter::Radiance(s.value),
                    spectrum: *spectrum,
                })
            }
            Light::Triangle(t) => {
                // Refused below all the same (`emits_toward`), without the sampling's work.
                if t.radiance.is_some() && t.faces_away(p) {
                    return None;
                }
                let s = t.sample(p, u)?;
                let pdf = s.pdf * selection;
                if !math::positive_finite(pdf) {
                    return None;
                }
                let emitter = match t.radiance {
                    Some(l) if t.emits_toward(s.wi) => Emitter::Radiance(l),
                    Some(_) => return None,
                    None => Emitter::Triangle {
                        instance: t.instance,
                        triangle: t.triangle,
                        b1: s.b1,
                        b2: s.b2,
                        normal: t.normal,
                    },
                };
                Some(LightSample {
                    wi: s.wi,
                    distance: s.distance,
                    pdf,
                    delta: false,
                    emitter,
                    spectrum: t.spectrum,
                })
            }
            Light::Environment => {
                let (wi, radiance, pdf) = self.environment.sample(u)?;
                let pdf = pdf * selection;
                math::positive_finite(pdf).then_some(LightSample {
                    wi,
                    distance: f32::INFINITY,
                    pdf,
                    delta: false,
                    emitter: Emitter::Radiance(radiance),
                    spectrum: None,
                })
            }
        }
    }

    /// The solid-angle density (selection probability included) with which
    /// [`Self::sample`] from `p_ref` picks the point `p_light` of emissive triangle
    /// (instance, triangle); 0 when that triangle is not in the set. `n_light` is the
    /// geometric normal at `p_light`; the set uses its own copy of that triangle's normal so
    /// that the value matches `sample` exactly whatever the caller passes.
    pub fn pdf_triangle(
        &self,
        instance: u32,
        triangle: u32,
        p_ref: Vec3,
        p_light: Vec3,
        n_light: Vec3,
    ) -> f32 {
        let _ = n_light;
        let Some(index) = self.triangle_light(instance, triangle) else {
            return 0.0;
        };
        let Light::Triangle(t) = &self.lights[index as usize] else {
            return 0.0;
        };
        let pdf = self.selection_probability(index) * t.pdf(p_ref, p_light);
        if pdf.is_finite() {
            pdf
        } else {
            0.0
        }
    }

    /// The solid-angle density (selection probability included) with which
    /// [`Self::sample`] picks the environment direction `dir` (world, need not be unit).
    pub fn pdf_environment(&self, dir: Vec3) -> f32 {
        let Some(index) = self.environment_index else {
            return 0.0;
        };
        let pdf = self.selection_probability(index) * self.environment.pdf(dir);
        if pdf.is_finite() {
            pdf
        } else {
            0.0
        }
    }
}

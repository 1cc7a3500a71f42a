//! glTF animation: samplers (STEP, LINEAR, CUBICSPLINE) over node translation, rotation,
//! scale and morph weights, evaluated into a [`Pose`] at any time in seconds.
//!
//! [`AnimationChoice::resolve`] picks the animations that play, [`time_range`] says when
//! they have keys, [`pose`] evaluates every node at one time (in f64), and
//! [`world_transforms`] and [`morph_weights`] read a pose the way skinning and morphing
//! ([`crate::deform`]) need it. [`Sampler::sample`] and [`Sampler::sample_rotation`]
//! follow glTF 2.0 Appendix C: times outside the keys clamp to the first or last value,
//! LINEAR rotations slerp along the shorter arc, CUBICSPLINE rotations are normalised.

use glam::{DMat4, DQuat, DVec3};

use crate::math;
use crate::scene::{Node, Scene, Trs};

mod properties;

pub use properties::{animates_emission, lights_at, materials_at, Property, PropertyChannel};

/// One glTF animation.
#[derive(Clone, Debug, Default)]
pub struct Animation {
    /// The animation's name, if any.
    pub name: Option<String>,
    /// Its channels, each driving one property of one node.
    pub channels: Vec<Channel>,
    /// Its channels driving a light or a material (KHR_animation_pointer).
    pub properties: Vec<PropertyChannel>,
}

/// One channel: a sampler driving one property of one node.
#[derive(Clone, Debug)]
pub struct Channel {
    /// The node animated.
    pub node: u32,
    /// The property animated.
    pub target: Target,
    /// Keyframes and how to interpolate them.
    pub sampler: Sampler,
}

impl Channel {
    /// A channel driving `target` of `node`: keys at `times`, `values` with `width`
    /// floats per element (see [`Sampler`]), interpolated by `interpolation`.
    pub fn new(
        node: u32,
        target: Target,
        interpolation: Interpolation,
        times: Vec<f32>,
        values: Vec<f32>,
        width: usize,
    ) -> Self {
        Channel {
            node,
            target,
            sampler: Sampler {
                interpolation,
                times,
                values,
                width,
            },
        }
    }
}

/// The node property a channel drives.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Target {
    /// Translation (3 values per key).
    Translation,
    /// Rotation quaternion x, y, z, w (4 values per key).
    Rotation,
    /// Scale (3 values per key).
    Scale,
    /// Morph weights (one value per morph target per key).
    Weights,
}

/// glTF sampler interpolation.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Interpolation {
    /// The value of the last key at or before the time.
    Step,
    /// Linear, with spherical linear interpolation for rotations.
    Linear,
    /// Cubic Hermite spline with in- and out-tangents stored beside each value.
    CubicSpline,
}

/// Keyframes of one channel.
#[derive(Clone, Debug)]
pub struct Sampler {
    /// Interpolation between keys.
    pub interpolation: Interpolation,
    /// Key times in seconds, strictly increasing.
    pub times: Vec<f32>,
    /// Key values, `width` floats per element; CUBICSPLINE stores (in-tangent, value,
    /// out-tangent) per key, so three elements per key.
    pub values: Vec<f32>,
    /// Floats per element: 3 (translation, scale), 4 (rotation) or the number of morph
    /// targets (weights).
    pub width: usize,
}

/// Every node's local transform and morph weights at one time.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Pose {
    /// Local transform per node (the node's own when no channel drives it).
    pub local: Vec<DMat4>,
    /// Morph weights per node when a channel drives them, else `None` (the node's or the
    /// mesh's own weights apply).
    pub weights: Vec<Option<Vec<f32>>>,
}

/// Which animations play.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub enum AnimationChoice {
    /// Every animation of the scene, together.
    #[default]
    All,
    /// One animation by index.
    Index(usize),
    /// One animation by name.
    Name(String),
}

// ---------------------------------------------------------------------------------------
// Sampler evaluation

/// Where a time falls among a sampler's keys.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Span {
    /// Exactly one key applies: before the first key, after the last, or a single key.
    Key(usize),
    /// Between key `k` and key `k + 1`: `u` in [0, 1) is the fraction of the interval,
    /// `dt` its length in seconds.
    Between { k: usize, u: f64, dt: f64 },
}

impl Sampler {
    /// Number of keyframes.
    pub fn keys(&self) -> usize {
        self.times.len()
    }

    /// Element `e` of [`Sampler::values`] (`width` floats; fewer when the values are short,
    /// which only a hand-built sampler can be).
    fn element(&self, e: usize) -> &[f32] {
        let start = (e * self.width).min(self.values.len());
        let end = (start + self.width).min(self.values.len());
        &self.values[start..end]
    }

    /// The value of key `k` (for CUBICSPLINE the spline vertex, not a tangent).
    fn value(&self, k: usize) -> &[f32] {
        match self.interpolation {
            Interpolation::CubicSpline => self.element(3 * k + 1),
            _ => self.element(k),
        }
    }

    /// Where `time` falls. Times before the first key (and NaN) clamp to the first key,
    /// times at or after the last key to the last one; `None` without keys.
    fn span(&self, time: f64) -> Option<Span> {
        let last = self.times.len().checked_sub(1)?;
        if !(time > self.times[0] as f64) {
            return Some(Span::Key(0));
        }
        if time >= self.times[last] as f64 {
            return Some(Span::Key(last));
        }
        // times[k] <= time < times[k + 1], with k < last by the two tests above.
        let k = self.times.partition_point(|&t| t as f64 <= time) - 1;
        let (t0, t1) = (self.times[k] as f64, self.times[k + 1] as f64);
        let dt = t1 - t0;
        Some(Span::Between {
            k,
            u: (time - t0) / dt,
            dt,
        })
    }

    /// Writes the value at `time` (seconds) into `out`, component by component: STEP takes
    /// the last key at or before `time`, LINEAR interpolates linearly, CUBICSPLINE
    /// evaluates the Hermite spline of glTF 2.0 Appendix C,
    /// `p(u) = (2u³-3u²+1)p₀ + (u³-2u²+u)m₀ + (-2u³+3u²)p₁ + (u³-u²)m₁` with
    /// `m₀ = (t₁-t₀)·outTangent₀` and `m₁ = (t₁-t₀)·inTangent₁`. Times outside the keys
    /// clamp to the first or last value.
    ///
    /// Writes `min(out.len(), width)` components and leaves the rest of `out` alone; leaves
    /// `out` untouched when the sampler has no keys. Rotations need
    /// [`Sampler::sample_rotation`] instead, which slerps and normalises.
    pub fn sample(&self, time: f64, out: &mut [f64]) {
        let Some(span) = self.span(time) else {
            return;
        };
        let copy = |out: &mut [f64], v: &[f32]| {
            for (o, &v) in out.iter_mut().zip(v) {
                *o = v as f64;
            }
        };
        match (span, self.interpolation) {
            (Span::Key(k), _) | (Span::Between { k, .. }, Interpolation::Step) => {
                copy(out, self.value(k));
            }
            (Span::Between { k, u, .. }, Interpolation::Linear) => {
                let (a, b) = (self.value(k), self.value(k + 1));
                for (o, (&a, &b)) in out.iter_mut().zip(a.iter().zip(b)) {
                    *o = a as f64 + (b as f64 - a as f64) * u;
                }
            }
            (Span::Between { k, u, dt }, Interpolation::CubicSpline) => {
                let (u2, u3) = (u * u, u * u * u);
                let h00 = 2.0 * u3 - 3.0 * u2 + 1.0;
                let h10 = u3 - 2.0 * u2 + u;
                let h01 = -2.0 * u3 + 3.0 * u2;
                let h11 = u3 - u2;
                let p0 = self.element(3 * k + 1);
                let out0 = self.element(3 * k + 2);
                let in1 = self.element(3 * (k + 1));
                let p1 = self.element(3 * (k + 1) + 1);
                for (c, o) in out.iter_mut().enumerate().take(self.width) {
                    let get = |s: &[f32]| s.get(c).map_or(0.0, |&v| v as f64);
                    *o = h00 * get(p0) + h10 * dt * get(out0) + h01 * get(p1) + h11 * dt * get(in1);
                }
            }
        }
    }

    /// The rotation at `time` from a sampler of quaternions (x, y, z, w): STEP takes the
    /// previous key, LINEAR slerps along the shorter arc, CUBICSPLINE evaluates the spline
    /// on the four components and normalises the result, as glTF 2.0 Appendix C says. The
    /// result is a unit quaternion in f64; identity without keys, and a degenerate
    /// (zero or non-finite) value falls back to the nearest earlier key, then identity.
    pub fn sample_rotation(&self, time: f64) -> DQuat {
        let quat = |v: &[f32]| {
            let mut q = [0.0f64, 0.0, 0.0, 1.0];
            for (o, &v) in q.iter_mut().zip(v) {
                *o = v as f64;
            }
            DQuat::from_array(q)
        };
        let Some(span) = self.span(time) else {
            return DQuat::IDENTITY;
        };
        let (k, q) = match (span, self.interpolation) {
            (Span::Key(k), _) | (Span::Between { k, .. }, Interpolation::Step) => {
                (k, quat(self.value(k)))
            }
            (Span::Between { k, u, .. }, Interpolation::Linear) => {
                (k, slerp(quat(self.value(k)), quat(self.value(k + 1)), u))
            }
            (Span::Between { k, .. }, Interpolation::CubicSpline) => {
                let mut q = [0.0, 0.0, 0.0, 1.0];
                self.sample(time, &mut q);
                (k, DQuat::from_array(q))
            }
        };
        unit_quat(q)
            .or_else(|| unit_quat(quat(self.value(k))))
            .unwrap_or(DQuat::IDENTITY)
    }
}

/// `q` scaled to unit length, or `None` when it has no usable length.
fn unit_quat(q: DQuat) -> Option<DQuat> {
    let len = q.length();
    (len.is_finite() && len > 1e-300).then(|| q / len)
}

/// Spherical linear interpolation from `a` to `b` along the shorter arc (glTF 2.0
/// Appendix C: `b` is negated when `a · b < 0`). Inputs need not be normalised; nearly
/// equal rotations fall back to a normalised linear blend, where slerp's `sin θ` divisor
/// would lose precision.
fn slerp(a: DQuat, b: DQuat, u: f64) -> DQuat {
    let (Some(a), Some(mut b)) = (unit_quat(a), unit_quat(b)) else {
        return if u < 0.5 { a } else { b };
    };
    let mut d = a.dot(b);
    if d < 0.0 {
        b = -b;
        d = -d;
    }
    if d > 1.0 - 1e-10 {
        return a * (1.0 - u) + b * u;
    }
    let theta = math::acos_f64(d.min(1.0));
    let s = math::sin_f64(theta);
    a * (math::sin_f64((1.0 - u) * theta) / s) + b * (math::sin_f64(u * theta) / s)
}

// ---------------------------------------------------------------------------------------
// Animations, choices and poses

impl Animation {
    /// First and last key time over all its channels (node and property ones), in
    /// seconds; `None` when no channel has keys.
    pub fn time_range(&self) -> Option<(f64, f64)> {
        let mut range: Option<(f64, f64)> = None;
        let samplers = self.channels.iter().map(|c| &c.sampler);
        for sampler in samplers.chain(self.properties.iter().map(|p| &p.sampler)) {
            let (Some(&first), Some(&last)) = (sampler.times.first(), sampler.times.last()) else {
                continue;
            };
            let (a, b) = (first as f64, last as f64);
            range = Some(match range {
                None => (a, b),
                Some((lo, hi)) => (lo.min(a), hi.max(b)),
            });
        }
        range
    }

    /// How errors and listings name it: `0 'Walk'` or `1 (unnamed)`.
    fn label(&self, index: usize) -> String {
        match &self.name {
            Some(n) => format!("{index} '{n}'"),
            None => format!("{index} (unnamed)"),
        }
    }
}

impl AnimationChoice {
    /// The indices into [`Scene::animations`] this choice plays. `All` gives every
    /// animation (none for a scene without any); an index out of range or a name no
    /// animation has is an error listing the animations the scene has. When several
    /// animations share a name, `Name` picks the first.
    pub fn resolve(&self, scene: &Scene) -> Result<Vec<usize>, String> {
        let n = scene.animations.len();
        let listing = || {
            if n == 0 {
                "the scene has no animations".to_string()
            } else {
                let all: Vec<String> = scene
                    .animations
                    .iter()
                    .enumerate()
                    .map(|(i, a)| a.label(i))
                    .collect();
                format!("the scene has {n}: {}", all.join(", "))
            }
        };
        match self {
            AnimationChoice::All => Ok((0..n).collect()),
            AnimationChoice::Index(i) if *i < n => Ok(vec![*i]),
            AnimationChoice::Index(i) => Err(format!(
                "animation index {i} is out of range; {}",
                listing()
            )),
            AnimationChoice::Name(name) => scene
                .animations
                .iter()
                .position(|a| a.name.as_deref() == Some(name.as_str()))
                .map(|i| vec![i])
                .ok_or_else(|| format!("no animation is named '{name}'; {}", listing())),
        }
    }
}

/// First and last key time over the chosen animations (indices into
/// [`Scene::animations`]; out-of-range ones are ignored), in seconds; `None` when they have
/// no keys.
pub fn time_range(scene: &Scene, animations: &[usize]) -> Option<(f64, f64)> {
    animations
        .iter()
        .filter_map(|&a| scene.animations.get(a)?.time_range())
        .reduce(|(a0, a1), (b0, b1)| (a0.min(b0), a1.max(b1)))
}

/// Every node's local transform and morph weights at `time` (seconds) with the chosen
/// animations playing (indices into [`Scene::animations`]; out-of-range ones are ignored).
///
/// A node no chosen channel drives keeps [`Node::local`]. An animated node starts from
/// [`Node::trs`] (a hand-built node without one: its `local` decomposed), has its animated
/// components replaced, and gets [`Trs::matrix`] of the result, with the rotation
/// renormalised in f64. When two channels drive the same property, the later one (in the
/// order of `animations`, then of channels) wins. A weights channel sets
/// [`Pose::weights`] for its node; see [`morph_weights`]. Everything is evaluated in f64.
pub fn pose(scene: &Scene, animations: &[usize], time: f64) -> Pose {
    let n = scene.nodes.len();
    let mut trs: Vec<Option<Trs>> = vec![None; n];
    let mut weights: Vec<Option<Vec<f32>>> = vec![None; n];
    for &a in animations {
        let Some(anim) = scene.animations.get(a) else {
            continue;
        };
        for ch in &anim.channels {
            let i = ch.node as usize;
            let Some(node) = scene.nodes.get(i) else {
                continue;
            };
            if ch.sampler.keys() == 0 {
                continue;
            }
            match ch.target {
                Target::Translation => {
                    let t = animated(&mut trs[i], node);
                    let mut v = t.translation.to_array();
                    ch.sampler.sample(time, &mut v);
                    t.translation = DVec3::from_array(v);
                }
                Target::Scale => {
                    let t = animated(&mut trs[i], node);
                    let mut v = t.scale.to_array();
                    ch.sampler.sample(time, &mut v);
                    t.scale = DVec3::from_array(v);
                }
                Target::Rotation => {
                    animated(&mut trs[i], node).rotation = ch.sampler.sample_rotation(time)
                }
                Target::Weights => {
                    let mut w = vec![0.0; ch.sampler.width];
                    ch.sampler.sample(time, &mut w);
                    weights[i] = Some(w.iter().map(|&w| w as f32).collect());
                }
            }
        }
    }
    let local = scene
        .nodes
        .iter()
        .zip(trs)
        .map(|(node, t)| match t {
            Some(mut t) => {
                t.rotation = unit_quat(t.rotation).unwrap_or(DQuat::IDENTITY);
                t.matrix()
            }
            None => node.local,
        })
        .collect();
    Pose { local, weights }
}

/// The animated transform of `node` in `slot`, starting from its own the first time a
/// channel drives it.
fn animated<'a>(slot: &'a mut Option<Trs>, node: &Node) -> &'a mut Trs {
    slot.get_or_insert_with(|| node_trs(node))
}

/// The node's decomposed transform: [`Node::trs`], else its matrix decomposed (only a
/// hand-built scene animates a node without one; the loader refuses that).
fn node_trs(node: &Node) -> Trs {
    node.trs.unwrap_or_else(|| {
        let (scale, rotation, translation) = node.local.to_scale_rotation_translation();
        Trs {
            translation,
            rotation,
            scale,
        }
    })
}

/// The morph weights that apply to `node` in `pose`: the animated ones, else the node's
/// own ([`Node::weights`]), else its mesh's defaults ([`crate::scene::Mesh::weights`]);
/// empty for a node without a mesh.
pub fn morph_weights<'a>(scene: &'a Scene, pose: &'a Pose, node: u32) -> &'a [f32] {
    let i = node as usize;
    if let Some(Some(w)) = pose.weights.get(i) {
        return w;
    }
    let Some(n) = scene.nodes.get(i) else {
        return &[];
    };
    if let Some(w) = &n.weights {
        return w;
    }
    n.mesh
        .and_then(|m| scene.meshes.get(m as usize))
        .map_or(&[], |m| &m.weights)
}

/// Every node's local-to-world transform in `pose`, for the first instance of each node
/// reachable from [`Scene::roots`] (see [`Scene::for_each_node_instance_with`]); `None` for
/// a node the default scene does not reach. A pose shorter than the node list (such as
/// `Pose::default()`) falls back to [`Node::local`]. Joint matrices for skinning are built
/// from these ([`crate::deform::joint_matrices`]).
pub fn world_transforms(scene: &Scene, pose: &Pose) -> Vec<Option<DMat4>> {
    let mut world = vec![None; scene.nodes.len()];
    scene.for_each_node_instance_with(
        |i| {
            pose.local
                .get(i as usize)
                .copied()
                .unwrap_or(scene.nodes[i as usize].local)
        },
        |i, m| {
            let w = &mut world[i as usize];
            if w.is_none() {
                *w = Some(*m);
            }
        },
    );
    world
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec4;

    fn sampler(
        interpolation: Interpolation,
        times: &[f32],
        values: &[f32],
        width: usize,
    ) -> Sampler {
        Sampler {
            interpolation,
            times: times.to_vec(),
            values: values.to_vec(),
            width,
        }
    }

    fn at(s: &Sampler, t: f64) -> Vec<f64> {
        let mut out = vec![f64::NAN; s.width];
        s.sample(t, &mut out);
        out
    }

    fn close(a: &[f64], b: &[f64]) -> bool {
        a.len() == b.len() && a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-12)
    }

    #[test]
    fn step_holds_the_previous_key_and_clamps() {
        let s = sampler(
            Interpolation::Step,
            &[1.0, 2.0, 4.0],
            &[10.0, 20.0, 40.0],
            1,
        );
        for (t, want) in [
            (-5.0, 10.0),
            (1.0, 10.0),
            (1.999, 10.0),
            (2.0, 20.0),
            (3.5, 20.0),
            (4.0, 40.0),
            (9.0, 40.0),
            (f64::NAN, 10.0),
        ] {
            assert_eq!(at(&s, t), vec![want], "t = {t}");
        }
    }

    #[test]
    fn linear_interpolates_each_component() {
        let s = sampler(
            Interpolation::Linear,
            &[0.0, 2.0, 3.0],
            &[0.0, 10.0, 4.0, 0.0, 6.0, 1.0],
            2,
        );
        assert!(close(&at(&s, -1.0), &[0.0, 10.0]));
        assert!(close(&at(&s, 0.5), &[1.0, 7.5]));
        assert!(close(&at(&s, 2.0), &[4.0, 0.0]));
        assert!(close(&at(&s, 2.25), &[4.5, 0.25]));
        assert!(close(&at(&s, 7.0), &[6.0, 1.0]));
    }

    #[test]
    fn cubic_spline_follows_the_hermite_formula() {
        // Keys at t = 1 and t = 3 (dt = 2): p0 = 1, outTangent0 = 3, inTangent1 = -1,
        // p1 = 2. The first in-tangent and the last out-tangent are never used.
        let s = sampler(
            Interpolation::CubicSpline,
            &[1.0, 3.0],
            &[99.0, 1.0, 3.0, -1.0, 2.0, 99.0],
            1,
        );
        // u = 0.5: h = (0.5, 0.125, 0.5, -0.125); m0 = 6, m1 = -2:
        // 0.5·1 + 0.125·6 + 0.5·2 + (-0.125)(-2) = 2.5.
        assert!(close(&at(&s, 2.0), &[2.5]));
        // u = 0.25: h = (0.84375, 0.140625, 0.15625, -0.046875):
        // 0.84375 + 0.84375 + 0.3125 + 0.09375 = 2.09375.
        assert!(close(&at(&s, 1.5), &[2.09375]));
        assert!(close(&at(&s, 1.0), &[1.0]));
        assert!(close(&at(&s, 3.0), &[2.0]));
        assert!(close(&at(&s, 0.0), &[1.0]));
        assert!(close(&at(&s, 5.0), &[2.0]));
    }

    #[test]
    fn a_single_key_is_constant_and_no_key_writes_nothing() {
        let s = sampler(Interpolation::CubicSpline, &[2.0], &[5.0, 7.0, 9.0], 1);
        assert_eq!(at(&s, 0.0), vec![7.0]);
        assert_eq!(at(&s, 3.0), vec![7.0]);
        let empty = sampler(Interpolation::Linear, &[], &[], 3);
        let mut out = [1.0, 2.0, 3.0];
        empty.sample(0.5, &mut out);
        assert_eq!(out, [1.0, 2.0, 3.0]);
        assert_eq!(empty.sample_rotation(0.5), DQuat::IDENTITY);
    }

    fn y_rotation(deg: f64) -> [f32; 4] {
        let h = deg.to_radians() / 2.0;
        [0.0, h.sin() as f32, 0.0, h.cos() as f32]
    }

    #[test]
    fn linear_rotation_slerps_along_the_shorter_arc() {
        let q90 = y_rotation(90.0);
        let s = sampler(
            Interpolation::Linear,
            &[0.0, 1.0],
            &[[0.0, 0.0, 0.0, 1.0], q90].concat(),
            4,
        );
        // Halfway: 45° about Y, (0, sin 22.5°, 0, cos 22.5°).
        let want = DVec4::new(0.0, 0.38268343236508984, 0.0, 0.9238795325112867);
        let got = DVec4::from(s.sample_rotation(0.5));
        assert!(got.abs_diff_eq(want, 1e-7), "{got}");
        // A quarter: 22.5°, not the 25% linear blend of the components.
        let got = DVec4::from(s.sample_rotation(0.25));
        let want = DVec4::new(0.0, 0.19509032201612825, 0.0, 0.9807852804032304);
        assert!(got.abs_diff_eq(want, 1e-7), "{got}");
        // The same end rotation written as -q: still the short way, 45° at the middle.
        let neg = q90.map(|c| -c);
        let s = sampler(
            Interpolation::Linear,
            &[0.0, 1.0],
            &[[0.0, 0.0, 0.0, 1.0], neg].concat(),
            4,
        );
        let got = s.sample_rotation(0.5);
        let want = DQuat::from_rotation_y(45f64.to_radians());
        assert!(got.dot(want).abs() > 1.0 - 1e-12, "{got}");
    }

    #[test]
    fn cubic_rotation_is_normalised() {
        // Zero tangents: the spline passes through (identity + 90° about Y)/2-ish
        // components, which are not unit length until normalised.
        let q90 = y_rotation(90.0);
        let zero = [0.0f32; 4];
        let values = [zero, [0.0, 0.0, 0.0, 1.0], zero, zero, q90, zero].concat();
        let s = sampler(Interpolation::CubicSpline, &[0.0, 1.0], &values, 4);
        let q = s.sample_rotation(0.5);
        assert!((q.length() - 1.0).abs() < 1e-12);
        // By symmetry the halfway point is 45° about Y.
        let want = DQuat::from_rotation_y(45f64.to_radians());
        assert!(q.abs_diff_eq(want, 1e-7), "{q}");
    }

    #[test]
    fn a_degenerate_rotation_falls_back_to_a_key() {
        let s = sampler(
            Interpolation::CubicSpline,
            &[0.0, 1.0],
            &[
                [0.0; 4],
                [0.0, 0.0, 0.0, 2.0],
                [0.0; 4],
                [0.0; 4],
                [0.0; 4],
                [0.0; 4],
            ]
            .concat(),
            4,
        );
        // The last key is all zeros: identity, never NaN.
        assert_eq!(s.sample_rotation(5.0), DQuat::IDENTITY);
        assert!(s.sample_rotation(0.9).is_finite());
    }

    fn scene_with(animations: Vec<Animation>) -> Scene {
        let mut scene = Scene::default();
        for _ in 0..2 {
            scene.nodes.push(Node {
                trs: Some(Trs {
                    scale: DVec3::splat(2.0),
                    ..Default::default()
                }),
                local: DMat4::from_scale(DVec3::splat(2.0)),
                ..Default::default()
            });
        }
        scene.roots = vec![0];
        scene.nodes[0].children = vec![1];
        scene.animations = animations;
        scene
    }

    fn channel(node: u32, target: Target, times: &[f32], values: &[f32], width: usize) -> Channel {
        Channel {
            node,
            target,
            sampler: sampler(Interpolation::Linear, times, values, width),
        }
    }

    #[test]
    fn pose_replaces_only_the_animated_components() {
        let walk = Animation {
            name: Some("walk".into()),
            properties: Vec::new(),
            channels: vec![channel(
                1,
                Target::Translation,
                &[1.0, 3.0],
                &[0.0, 0.0, 0.0, 4.0, 0.0, 0.0],
                3,
            )],
        };
        let scene = scene_with(vec![walk]);
        let pose = pose(&scene, &[0], 2.0);
        assert_eq!(pose.local[0], scene.nodes[0].local);
        // Translation (2, 0, 0) with the node's own scale 2 kept.
        let want = DMat4::from_scale_rotation_translation(
            DVec3::splat(2.0),
            DQuat::IDENTITY,
            DVec3::new(2.0, 0.0, 0.0),
        );
        assert_eq!(pose.local[1], want);
        assert_eq!(pose.weights, vec![None, None]);
        // Not playing the animation: the rest pose.
        assert_eq!(super::pose(&scene, &[], 2.0).local[1], scene.nodes[1].local);
        let world = world_transforms(&scene, &pose);
        assert_eq!(world[1], Some(scene.nodes[0].local * want));
    }

    #[test]
    fn time_ranges_and_choices() {
        let a = Animation {
            name: Some("walk".into()),
            properties: Vec::new(),
            channels: vec![
                channel(0, Target::Scale, &[0.5, 2.0], &[1.0; 6], 3),
                channel(1, Target::Scale, &[1.0, 3.0], &[1.0; 6], 3),
            ],
        };
        let b = Animation {
            name: None,
            properties: Vec::new(),
            channels: vec![channel(0, Target::Scale, &[-1.0, 0.0], &[1.0; 6], 3)],
        };
        let scene = scene_with(vec![a, b, Animation::default()]);
        assert_eq!(scene.animations[0].time_range(), Some((0.5, 3.0)));
        assert_eq!(scene.animations[2].time_range(), None);
        assert_eq!(time_range(&scene, &[0, 1]), Some((-1.0, 3.0)));
        assert_eq!(time_range(&scene, &[2]), None);
        assert_eq!(AnimationChoice::All.resolve(&scene), Ok(vec![0, 1, 2]));
        assert_eq!(AnimationChoice::Index(1).resolve(&scene), Ok(vec![1]));
        assert_eq!(
            AnimationChoice::Name("walk".into()).resolve(&scene),
            Ok(vec![0])
        );
        let err = AnimationChoice::Name("run".into())
            .resolve(&scene)
            .unwrap_err();
        assert_eq!(
            err,
            "no animation is named 'run'; the scene has 3: 0 'walk', 1 (unnamed), 2 (unnamed)"
        );
        let err = AnimationChoice::Index(3).resolve(&scene).unwrap_err();
        assert!(
            err.starts_with("animation index 3 is out of range; the scene has 3"),
            "{err}"
        );
        let empty = Scene::default();
        assert_eq!(AnimationChoice::All.resolve(&empty), Ok(vec![]));
        assert_eq!(
            AnimationChoice::Index(0).resolve(&empty).unwrap_err(),
            "animation index 0 is out of range; the scene has no animations"
        );
    }
}

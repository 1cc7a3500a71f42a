//! Emissive triangles: sampling a point on one as seen from a reference point, and the
//! solid-angle density of that choice.
//!
//! Seen from a point near the triangle, where it covers a moderate solid angle Ω,
//! directions are drawn uniformly inside the spherical triangle (Arvo 1995, in the form of pbrt-v4's
//! `SampleSphericalTriangle`), with density exactly 1/Ω. Where Ω is tiny (single precision
//! cannot resolve the spherical construction), nearly a hemisphere (the construction
//! degenerates), or the point is far from the triangle for its size (area sampling is
//! then nearly as good, and cheaper: [`AREA_SAMPLING_RADII`]), the point is drawn
//! uniformly by area instead, with density
//! d² / (|cos θ_light| · area). So is a triangle two of whose vertices lie in nearly
//! opposite directions (the point sits close to that edge, as under a huge emitter): the
//! great circle through two nearly antipodal directions is ill-defined in single precision,
//! and the spherical construction then crowds its samples towards the horizon (a floor
//! 0.5 m under an emitter plane 2e5 m wide came out 8% too dark). Both
//! [`TriangleLight::sample`] and [`TriangleLight::pdf`] decide between the two from the
//! same quantities computed the same way, so they always agree.

use glam::{Vec2, Vec3};

use super::EmissiveTriangle;
use crate::math;

/// Below this solid angle (sr), sample by area (pbrt-v4's `MinSphericalSampleArea`).
const MIN_SPHERICAL_SOLID_ANGLE: f32 = 3e-4;
/// Above this solid angle (sr), sample by area (pbrt-v4's `MaxSphericalSampleArea`; a
/// hemisphere is 2π ≈ 6.283).
const MAX_SPHERICAL_SOLID_ANGLE: f32 = 6.22;
/// Beyond this many bounding radii (the largest distance from the vertices' centre to a
/// vertex) from the centre, sample by area without computing the solid angle. Every point
/// of the triangle is then between 2 and 4 radii away, so 1/d² varies by at most 4x over
/// it and the area density stays close to the spherical one; the solid angle is at most
/// 0.36 sr. On the measured Cornell box, where most points see the light from afar, this
/// is 15% more paths per second for 0.1% more MSE at 16 spp.
const AREA_SAMPLING_RADII: f32 = 3.0;
/// Below this cosine between two vertex directions (more than about 176° apart), sample
/// by area: the spherical construction's error grows like 1e-7 / sin of that angle, from
/// about 1e-4 of the irradiance here to tens of percent within 0.01° of 180°.
const MIN_SPHERICAL_VERTEX_COSINE: f32 = -0.998;
/// How far, relative to its distance from the triangle and to the size of the triangle's
/// coordinates, a point must lie behind a one-sided light for
/// [`TriangleLight::faces_away`]: a thousand times the rounding of a point sampled on the
/// light and of the direction to it (about 1e-7 of those), so no such direction can come
/// out facing the light's front.
const BEHIND_MARGIN: f32 = 1e-4;

/// An emissive triangle ready for sampling: its vertices, unit geometric normal
/// (cross(p1 − p0, p2 − p0), not flipped) and area.
#[derive(Clone, Debug)]
pub(crate) struct TriangleLight {
    pub(crate) p: [Vec3; 3],
    pub(crate) normal: Vec3,
    pub(crate) area: f32,
    /// Centre of the vertices, and the squared distance from it within which the
    /// triangle may be sampled on the sphere (see [`AREA_SAMPLING_RADII`]).
    centroid: Vec3,
    spherical_within2: f32,
    /// The squared distance from the centre to the farthest vertex.
    radius2: f32,
    /// The largest squared distance of a vertex from the origin: a point sampled on the
    /// triangle rounds relative to it.
    magnitude2: f32,
    /// The radiance at every point, where it is the same everywhere.
    pub(crate) radiance: Option<Vec3>,
    /// The front face's normal, and whether the back face emits too.
    front: Vec3,
    double_sided: bool,
    pub(crate) instance: u32,
    pub(crate) triangle: u32,
    pub(crate) spectrum: Option<u32>,
}

/// A point sampled on a triangle light.
pub(crate) struct TriangleSample {
    pub(crate) wi: Vec3,
    pub(crate) distance: f32,
    /// Solid-angle density (not including the light's selection probability).
    pub(crate) pdf: f32,
    pub(crate) b1: f32,
    pub(crate) b2: f32,
}

impl TriangleLight {
    /// Prepares `t`, or `None` when it cannot emit: zero or non-finite area, vertices not
    /// finite, or emission without a positive finite component.
    pub(crate) fn new(t: &EmissiveTriangle) -> Option<Self> {
        let [p0, p1, p2] = t.p;
        if !(p0.is_finite() && p1.is_finite() && p2.is_finite()) {
            return None;
        }
        let c = (p1 - p0).cross(p2 - p0);
        let len = c.length();
        let area = 0.5 * len;
        let emits = t.emission.is_finite() && t.emission.max_element() > 0.0;
        let centroid = (p0 + p1 + p2) / 3.0;
        let r2 =
            t.p.map(|v| v.distance_squared(centroid))
                .into_iter()
                .fold(0.0, f32::max);
        let normal = c / len;
        (area > 0.0 && area.is_finite() && emits).then(|| Self {
            p: t.p,
            normal,
            area,
            centroid,
            spherical_within2: AREA_SAMPLING_RADII * AREA_SAMPLING_RADII * r2,
            radius2: r2,
            magnitude2: t
                .p
                .map(Vec3::length_squared)
                .into_iter()
                .fold(0.0, f32::max),
            radiance: t.uniform.then_some(t.emission),
            front: if t.mirrored { -normal } else { normal },
            double_sided: t.double_sided,
            instance: t.instance,
            triangle: t.triangle,
            spectrum: t.spectrum,
        })
    }

    /// Whether the triangle emits towards a point that sees it in direction `wi`.
    pub(crate) fn emits_toward(&self, wi: Vec3) -> bool {
        self.double_sided || self.front.dot(wi) < 0.0
    }

    /// Whether `p` lies behind the plane of a one-sided triangle by [`BEHIND_MARGIN`] of
    /// its distance from every vertex plus the vertices' size: [`Self::emits_toward`] then
    /// refuses every direction sampled from `p`, so a light sample may be refused without
    /// drawing one (the ceiling around a lamp that lights the room below).
    pub(crate) fn faces_away(&self, p: Vec3) -> bool {
        if self.double_sided {
            return false;
        }
        // Behind by `h` (the vertices agree on it far within the margin). Every vertex is
        // within `|p - centre| + radius`; with the vertices' size, the square of the sum
        // is at most three times the sum of the squares.
        let h = self.front.dot(self.p[0] - p);
        let reach2 = 3.0 * (p.distance_squared(self.centroid) + self.radius2 + self.magnitude2);
        h > 0.0 && h * h > BEHIND_MARGIN * BEHIND_MARGIN * reach2
    }

    /// Unit directions from `p` to the vertices (zero where `p` is a vertex).
    fn directions(&self, p: Vec3) -> [Vec3; 3] {
        self.p.map(|v| math::normalize_or(v - p, Vec3::ZERO))
    }

    /// Solid angle of the triangle seen along the vertex directions `[a, b, c]` (Van
    /// Oosterom & Strackee 1983).
    fn solid_angle([a, b, c]: [Vec3; 3]) -> f32 {
        let num = a.dot(b.cross(c)).abs();
        let den = 1.0 + a.dot(b) + a.dot(c) + b.dot(c);
        let omega = 2.0 * atan2_upper(num, den);
        if omega.is_finite() {
            omega
        } else {
            0.0
        }
    }

    /// Whether a solid angle `omega` is one the spherical construction resolves.
    fn spherical(omega: f32) -> bool {
        (MIN_SPHERICAL_SOLID_ANGLE..=MAX_SPHERICAL_SOLID_ANGLE).contains(&omega)
    }

    /// Whether, seen along the vertex directions `[a, b, c]` with solid angle `omega`,
    /// directions are sampled on the sphere (else by area): `omega` is resolvable and no
    /// two vertices are seen in nearly opposite directions.
    fn spherical_from([a, b, c]: [Vec3; 3], omega: f32) -> bool {
        if !Self::spherical(omega) {
            return false;
        }
        a.dot(b).min(b.dot(c)).min(c.dot(a)) > MIN_SPHERICAL_VERTEX_COSINE
    }

    /// Where directions from `p` are sampled on the sphere: the vertex directions and the
    /// solid angle; `None` where the point is drawn by area instead.
    fn spherical_view(&self, p: Vec3) -> Option<([Vec3; 3], f32)> {
        if p.distance_squared(self.centroid) > self.spherical_within2 {
            return None;
        }
        let dirs = self.directions(p);
        let omega = Self::solid_angle(dirs);
        Self::spherical_from(dirs, omega).then_some((dirs, omega))
    }

    /// Area-sampling density converted to solid angle for the point `q` seen from `p`;
    /// 0 where it is undefined (grazing, or `p` on the light).
    fn area_pdf_to_solid_angle(&self, p: Vec3, q: Vec3) -> f32 {
        let d = q - p;
        let dist2 = d.length_squared();
        if !math::positive_finite(dist2) {
            return 0.0;
        }
        let cos = self.normal.dot(d).abs() / dist2.sqrt();
        let pdf = dist2 / (cos * self.area);
        if pdf.is_finite() && cos > 0.0 {
            pdf
        } else {
            0.0
        }
    }

    /// Samples a point of the triangle as seen from `p`; `None` when no direction can be
    /// sampled (`p` in the triangle's plane, or a numerically degenerate configuration).
    pub(crate) fn sample(&self, p: Vec3, u: Vec2) -> Option<TriangleSample> {
        let (b1, b2, pdf) = if let Some((dirs, omega)) = self.spherical_view(p) {
            let (b1, b2) = self.sample_spherical(p, dirs, omega, u)?;
            (b1, b2, 1.0 / omega)
        } else {
            let (b1, b2) = sample_uniform_triangle(u);
            let q = self.point(b1, b2);
            (b1, b2, self.area_pdf_to_solid_angle(p, q))
        };
        let q = self.point(b1, b2);
        let d = q - p;
        let distance = d.length();
        if !(math::positive_finite(pdf) && math::positive_finite(distance)) {
            return None;
        }
        Some(TriangleSample {
            wi: d / distance,
            distance,
            pdf,
            b1,
            b2,
        })
    }

    /// Solid-angle density with which [`Self::sample`] from `p` picks the point `q` of
    /// this triangle.
    pub(crate) fn pdf(&self, p: Vec3, q: Vec3) -> f32 {
        if let Some((_, omega)) = self.spherical_view(p) {
            1.0 / omega
        } else {
            self.area_pdf_to_solid_angle(p, q)
        }
    }

    fn point(&self, b1: f32, b2: f32) -> Vec3 {
        crate::geometry::barycentric(self.p[0], self.p[1], self.p[2], b1, b2)
    }

    /// Arvo's uniform spherical-triangle sampling from `p`, whose vertex directions are
    /// `[a, b, c]` and solid angle `omega`; returns the barycentrics (b1, b2) of the point
    /// the sampled direction hits.
    fn sample_spherical(
        &self,
        p: Vec3,
        [a, b, c]: [Vec3; 3],
        omega: f32,
        u: Vec2,
    ) -> Option<(f32, f32)> {
        // Normals of the great-circle arcs from a.
        let n_ab = math::try_normalize(a.cross(b))?;
        let n_ca = math::try_normalize(c.cross(a))?;
        // The angle at a, as its cosine and sine (pbrt-v4 takes the angles at all three
        // vertices for the area α + β + γ − π, which is the solid angle already known).
        let cos_alpha = -n_ab.dot(n_ca);
        let sin_alpha = n_ab.cross(n_ca).length();

        // Uniformly choose the area A' of the sub-triangle (a, b, c').
        let ap_pi = std::f32::consts::PI + u.x * omega;
        let (sin_ap, cos_ap) = crate::math::sin_cos(ap_pi);
        let sin_phi = sin_ap * cos_alpha - cos_ap * sin_alpha;
        let cos_phi = cos_ap * cos_alpha + sin_ap * sin_alpha;
        let k1 = cos_phi + cos_alpha;
        let k2 = sin_phi - sin_alpha * a.dot(b);
        let cos_bp = (k2 + (k2 * cos_phi - k1 * sin_phi) * cos_alpha)
            / ((k2 * sin_phi + k1 * cos_phi) * sin_alpha);
        if !cos_bp.is_finite() {
            return None;
        }
        let cos_bp = cos_bp.clamp(-1.0, 1.0);
        // c' on the arc from a to c.
        let sin_bp = (1.0 - cos_bp * cos_bp).max(0.0).sqrt();
        let cp = cos_bp * a + sin_bp * math::try_normalize(gram_schmidt(c, a))?;
        // Direction on the arc from b to c', uniform in the sub-triangle's area.
        let cos_theta = 1.0 - u.y * (1.0 - cp.dot(b));
        let sin_theta = (1.0 - cos_theta * cos_theta).max(0.0).sqrt();
        let w = cos_theta * b + sin_theta * math::try_normalize(gram_schmidt(cp, b))?;

        // Barycentrics where the ray p + t·w meets the triangle's plane (Möller–Trumbore).
        let e1 = self.p[1] - self.p[0];
        let e2 = self.p[2] - self.p[0];
        let s1 = w.cross(e2);
        let divisor = s1.dot(e1);
        if !math::positive_finite(divisor.abs()) {
            return None;
        }
        let s = p - self.p[0];
        let mut b1 = (s.dot(s1) / divisor).clamp(0.0, 1.0);
        let mut b2 = (w.dot(s.cross(e1)) / divisor).clamp(0.0, 1.0);
        if b1 + b2 > 1.0 {
            let sum = b1 + b2;
            b1 /= sum;
            b2 /= sum;
        }
        (b1.is_finite() && b2.is_finite()).then_some((b1, b2))
    }
}

/// Uniform barycentrics (b1, b2) over a triangle (pbrt-v4's `SampleUniformTriangle`, which
/// maps the square to the triangle without folding, keeping strata intact).
fn sample_uniform_triangle(u: Vec2) -> (f32, f32) {
    let (b0, b1) = if u.x < u.y {
        let b0 = u.x / 2.0;
        (b0, u.y - b0)
    } else {
        let b1 = u.y / 2.0;
        (u.x - b1, b1)
    };
    (b1, (1.0 - b0 - b1).max(0.0))
}

/// `atan2(y, x)` for `y ≥ 0`, in [0, π] (NaN where both are 0): Cephes' `atanf` after
/// reducing the ratio to at most tan(π/8), within a few 1e-7 relative of the exact value,
/// in a fifth of the instructions of the C library's (it runs at every light sample).
fn atan2_upper(y: f32, x: f32) -> f32 {
    use std::f32::consts::{FRAC_PI_2, FRAC_PI_4, PI};
    // tan(3π/8) and tan(π/8).
    const TAN_3PI_8: f32 = 2.414_213_6;
    const TAN_PI_8: f32 = 0.414_213_57;
    let r = y / x.abs();
    let (base, z) = if r > TAN_3PI_8 {
        (FRAC_PI_2, -1.0 / r)
    } else if r > TAN_PI_8 {
        (FRAC_PI_4, (r - 1.0) / (r + 1.0))
    } else {
        (0.0, r)
    };
    let z2 = z * z;
    let atan_z = (((8.053_744_5e-2 * z2 - 1.387_768_6e-1) * z2 + 1.997_771_1e-1) * z2
        - 3.333_295e-1)
        * z2
        * z
        + z;
    let angle = base + atan_z;
    if x < 0.0 {
        PI - angle
    } else {
        angle
    }
}

/// The component of `v` orthogonal to the unit vector `w`.
fn gram_schmidt(v: Vec3, w: Vec3) -> Vec3 {
    v - v.dot(w) * w
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::test_rng::Rng;

    #[test]
    fn atan2_upper_matches_the_library_to_a_few_ulps() {
        let mut worst = 0.0f64;
        for i in 0..=2000 {
            for j in -1000..=1000 {
                let (y, x) = (i as f32 * 1e-3, j as f32 * 1.7e-3);
                let exact = f64::from(y).atan2(f64::from(x));
                let got = f64::from(atan2_upper(y, x));
                if y == 0.0 && x == 0.0 {
                    assert!(got.is_nan());
                    continue;
                }
                worst = worst.max((got - exact).abs() / exact.abs().max(1e-30));
            }
        }
        assert!(worst < 4e-7, "worst relative error {worst:e}");
        // Tiny and huge ratios, and a zero x of either sign.
        for (y, x) in [
            (1e-30, 1.0),
            (1.0, 1e-30),
            (1.0, -1e-30),
            (1.0, 0.0),
            (1.0, -0.0),
        ] {
            let exact = f64::from(y).atan2(f64::from(x));
            let got = f64::from(atan2_upper(y, x));
            assert!(
                (got - exact).abs() <= 4e-7 * exact,
                "{y} {x}: {got} {exact}"
            );
        }
    }

    fn light(p: [Vec3; 3]) -> TriangleLight {
        TriangleLight::new(&EmissiveTriangle {
            p,
            emission: Vec3::ONE,
            double_sided: false,
            uniform: true,
            mirrored: false,
            instance: 0,
            triangle: 0,
            spectrum: None,
        })
        .unwrap()
    }

    /// ∫ h(ω) dω over the triangle by a fine midpoint rule in area (independent of the
    /// sampler): ∫ h(ω(x)) |cos θ_x| / d² dA.
    fn area_quadrature(t: &TriangleLight, p: Vec3, h: impl Fn(Vec3) -> f64) -> f64 {
        let n = 600;
        let mut sum = 0.0f64;
        for i in 0..n {
            for j in 0..n - i {
                // Two sub-triangles per cell; use the upright one's centroid and, where it
                // exists, the inverted one's.
                let c = [(i as f64 + 1.0 / 3.0, j as f64 + 1.0 / 3.0)];
                let inv = (i + j + 1 < n).then_some((i as f64 + 2.0 / 3.0, j as f64 + 2.0 / 3.0));
                for (x, y) in c.into_iter().chain(inv) {
                    let (b1, b2) = ((x / n as f64) as f32, (y / n as f64) as f32);
                    let q = t.point(b1, b2);
                    let d = q - p;
                    let d2 = d.length_squared() as f64;
                    let w = d.normalize();
                    let cos = t.normal.dot(w).abs() as f64;
                    sum += h(w) * cos / d2 * (t.area as f64 / (n * n) as f64);
                }
            }
        }
        sum
    }

    #[test]
    fn points_said_to_face_away_get_no_direction_the_light_emits_toward() {
        // Tilted triangles at several scales, seen from points beside, above and below
        // them at heights from 1e-9 of their size up, where the rounding of the normal and
        // of sampled points decides the side.
        let mut rng = Rng(5);
        let (mut away, mut in_front) = (0, 0);
        for trial in 0..300 {
            let scale = [1e-4f32, 1.0, 1e5][trial % 3];
            // Near the origin, or 1e3 and 1e5 of its size away from it, where its
            // coordinates round coarser than the point's height above it.
            let offset = Vec3::splat([0.0, 1e3, 1e5][(trial / 3) % 3] * scale);
            let t = light(
                [rng.vec3(), rng.vec3(), rng.vec3()].map(|v| (v * 2.0 - 1.0) * scale + offset),
            );
            let [v0, v1, v2] = t.p;
            for j in 0..300 {
                let (a, b) = (rng.next_f32() * 5.0 - 2.0, rng.next_f32() * 5.0 - 2.0);
                let h = 10f32.powi(-(j % 10)) * scale * (rng.next_f32() - 0.5);
                let p = v0 + (v1 - v0) * a + (v2 - v0) * b - t.front * h;
                if !t.faces_away(p) {
                    in_front += usize::from(h < 0.0);
                    continue;
                }
                away += 1;
                assert!(h > 0.0, "{p} is in front of the light");
                for _ in 0..8 {
                    if let Some(s) = t.sample(p, rng.vec2()) {
                        assert!(!t.emits_toward(s.wi), "{p} {}", s.wi);
                    }
                }
            }
        }
        // Points well behind are refused up front (a tenth of those behind: heights down
        // to 1e-9 of the size are not), and none in front.
        assert!(away > 3_000, "{away}");
        assert!(in_front > 40_000, "{in_front}");
        let mut two_sided = light([Vec3::ZERO, Vec3::X, Vec3::Z]);
        two_sided.double_sided = true;
        assert!(!two_sided.faces_away(Vec3::new(0.2, -1.0, 0.2)));
        assert!(!two_sided.faces_away(Vec3::new(0.2, 1.0, 0.2)));
    }

    #[test]
    fn spherical_samples_are_uniform_in_solid_angle() {
        // A triangle covering about 0.8 sr: the spherical branch.
        let t = light([
            Vec3::new(-1.0, -0.5, -1.0),
            Vec3::new(1.0, -0.7, -1.2),
            Vec3::new(0.2, 1.0, -0.9),
        ]);
        let p = Vec3::new(0.1, 0.0, 0.3);
        let omega = TriangleLight::solid_angle(t.directions(p));
        assert!(TriangleLight::spherical(omega), "{omega}");
        let h = |w: Vec3| ((w.x + 2.0) as f64).powi(3) * ((w.y + 1.5) as f64);
        let reference = area_quadrature(&t, p, h);
        let omega_q = area_quadrature(&t, p, |_| 1.0);
        assert!(
            (omega_q - omega as f64).abs() < 1e-3 * omega as f64,
            "{omega_q} vs {omega}"
        );
        let mut rng = Rng(11);
        let n = 400_000;
        let mut est = 0.0f64;
        for _ in 0..n {
            let s = t.sample(p, rng.vec2()).unwrap();
            assert!((s.pdf - t.pdf(p, p + s.wi * s.distance)).abs() <= 1e-6 * s.pdf);
            est += h(s.wi) / s.pdf as f64;
        }
        est /= n as f64;
        assert!(
            (est - reference).abs() < 0.01 * reference,
            "{est} vs {reference}"
        );
    }

    #[test]
    fn far_points_sample_by_area_and_stay_unbiased() {
        // Seen from about 3.4 bounding radii: a solid angle the spherical construction
        // resolves, sampled by area all the same.
        let t = light([
            Vec3::new(-0.5, -0.3, -2.0),
            Vec3::new(0.5, -0.4, -2.2),
            Vec3::new(0.1, 0.5, -1.9),
        ]);
        let p = Vec3::new(0.3, 0.2, 0.0);
        assert!(p.distance_squared(t.centroid) > t.spherical_within2);
        assert!(TriangleLight::spherical(TriangleLight::solid_angle(
            t.directions(p)
        )));
        let h = |w: Vec3| ((w.x + 2.0) as f64).powi(3) * ((w.y + 1.5) as f64);
        let reference = area_quadrature(&t, p, h);
        let mut rng = Rng(5);
        let n = 400_000;
        let mut est = 0.0f64;
        for _ in 0..n {
            let s = t.sample(p, rng.vec2()).unwrap();
            let q = p + s.wi * s.distance;
            assert!((s.pdf - t.pdf(p, q)).abs() <= 1e-6 * s.pdf);
            assert_eq!(t.pdf(p, q), t.area_pdf_to_solid_angle(p, q));
            est += h(s.wi) / s.pdf as f64;
        }
        est /= n as f64;
        assert!(
            (est - reference).abs() < 0.01 * reference,
            "{est} vs {reference}"
        );
    }

    #[test]
    fn area_branch_for_tiny_and_huge_solid_angles() {
        let t = light([
            Vec3::new(0.0, 0.0, -100.0),
            Vec3::new(0.1, 0.0, -100.0),
            Vec3::new(0.0, 0.1, -100.0),
        ]);
        assert!(!TriangleLight::spherical(TriangleLight::solid_angle(
            t.directions(Vec3::ZERO)
        )));
        let s = t.sample(Vec3::ZERO, Vec2::new(0.3, 0.6)).unwrap();
        let expected = 100.0f32.powi(2) / (0.005 * s.wi.z.abs());
        assert!(
            (s.pdf - expected).abs() < 1e-2 * expected,
            "{} vs {expected}",
            s.pdf
        );
        let big = light([
            Vec3::new(-1e3, -1e3, -1e-3),
            Vec3::new(1e3, -1e3, -1e-3),
            Vec3::new(0.0, 1e3, -1e-3),
        ]);
        assert!(TriangleLight::solid_angle(big.directions(Vec3::ZERO)) > MAX_SPHERICAL_SOLID_ANGLE);
        let s = big.sample(Vec3::ZERO, Vec2::new(0.5, 0.5)).unwrap();
        assert!(s.pdf.is_finite() && s.pdf > 0.0);
    }

    #[test]
    fn reference_point_on_the_light_gives_no_sample_and_zero_pdf() {
        let t = light([Vec3::ZERO, Vec3::X, Vec3::Y]);
        let p = Vec3::new(0.25, 0.25, 0.0);
        for u in [Vec2::ZERO, Vec2::new(0.3, 0.9), Vec2::splat(0.999)] {
            assert!(t.sample(p, u).is_none());
        }
        assert_eq!(t.pdf(p, Vec3::new(0.5, 0.1, 0.0)), 0.0);
        // A point in the plane but outside the triangle as well.
        assert!(t
            .sample(Vec3::new(3.0, 3.0, 0.0), Vec2::splat(0.5))
            .is_none());
    }
}

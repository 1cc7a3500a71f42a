//! The watertight ray/triangle test of Woop, Benthin and Wald, "Watertight Ray/Triangle
//! Intersection", JCGT 2(1), 2013, with the conservative `t > 0` bound of Pharr, Jakob and
//! Humphreys, "Physically Based Rendering" (3rd and 4th ed., section 6.8.4 / 6.5.3).
//!
//! The ray is turned into the +Z axis by a permutation and a shear that depend only on the
//! ray ([`RayPrecomputed`]); each triangle is then tested in 2D with three edge functions.
//! Two triangles sharing an edge see the same transformed vertices bit for bit, so the edge
//! function has the same value (with opposite sign) for both: a ray through the edge can
//! never slip between them. Where an edge function rounds to exactly zero the test
//! recomputes the three in double precision, so that zero only means "exactly on the edge".

use std::ops::{Add, Mul, Sub};

use glam::{DVec2, Mat3A, Vec3, Vec3A, Vec4};

use crate::geometry::Ray;

mod lanes;
mod rows;

pub use lanes::{BlockHits, LaneHit, RayLanes};
pub use rows::{Block, TriangleRows, BLOCK};

/// `gamma(n)` of Higham / pbrt: the bound `n·u / (1 - n·u)` on the relative error of `n`
/// successive rounded f32 operations, with `u` the unit roundoff.
pub(crate) const fn gamma(n: i32) -> f32 {
    const U: f32 = f32::EPSILON * 0.5;
    let nu = n as f32 * U;
    nu / (1.0 - nu)
}

/// The watertight test's frame for a ray direction: the axis along which the direction is
/// largest (`kz`), the two others in winding-preserving order, and the shear that maps the
/// direction onto +Z. All the lane test ([`RayLanes`]) needs of a ray besides its origin.
#[derive(Clone, Copy, Debug)]
pub(crate) struct RayShear {
    /// `kx`, `ky`, `kz`, each below 3.
    pub axes: [usize; 3],
    /// (Sx, Sy, Sz) of the paper.
    pub shear: Vec3,
}

impl RayShear {
    /// The frame of `dir`. A direction that is zero or not finite gets NaN shear constants,
    /// and no test then reports a hit.
    #[inline(always)]
    pub fn new(dir: Vec3) -> Self {
        // Arithmetic and array indexing rather than branches and `Vec3`'s indexing (a
        // `match`): a ray's axes are a coin toss to the branch predictor, which mispredicted
        // here about once per incoherent ray.
        let d = dir.to_array();
        let a = dir.abs();
        // The dimension where the direction is largest, so that the shear is at most 1.
        let x_largest = a.x >= a.y && a.x >= a.z;
        let kz = usize::from(!x_largest) * (2 - usize::from(a.y >= a.z));
        let (kx, ky) = ([1, 2, 0][kz], [2, 0, 1][kz]);
        // Swapping kx and ky for a negative direction keeps the triangles' winding, so the
        // sign of the determinant still tells front from back.
        let (kx, ky) = if d[kz] < 0.0 { (ky, kx) } else { (kx, ky) };
        Self {
            axes: [kx, ky, kz],
            shear: Vec3::new(d[kx] / d[kz], d[ky] / d[kz], 1.0 / d[kz]),
        }
    }
}

/// What the whole test ([`intersect_triangle`]) needs from a ray, computed once per ray:
/// its `RayShear`, and the permutation and shear as one matrix.
#[derive(Clone, Copy, Debug)]
pub struct RayPrecomputed {
    origin: Vec3,
    /// The direction, for the double-precision recomputation of [`precise_hit`].
    dir: Vec3,
    frame: RayShear,
    /// The permutation and the x-y shear as one matrix, applied in SIMD lanes: row 0 is
    /// `e_kx − Sx·e_kz`, row 1 `e_ky − Sy·e_kz`, row 2 `e_kz`. Each row has one 1, at most
    /// one shear constant and a 0, so `M·a` rounds as `a[kx] − Sx·a[kz]` does (adding the
    /// zero product is exact): the same numbers, without indexing by `kx` per vertex.
    permute_shear: Mat3A,
    /// `origin` in SIMD lanes, for `permute_shear`.
    origin_a: Vec3A,
}

impl RayPrecomputed {
    /// Precomputes the permutation and shear for `ray`. A ray whose direction is zero or not
    /// finite gets NaN shear constants, and [`intersect_triangle`] then never reports a hit.
    // Inlined into each query: called out of line, the closest-hit queries of `tessera bench
    // rays` counted 5 to 9% more instructions (its fields went through memory).
    #[inline(always)]
    pub fn new(ray: &Ray) -> Self {
        let frame = RayShear::new(ray.dir);
        let ([kx, ky, kz], shear) = (frame.axes, frame.shear);
        let e = |k: usize| Vec3A::AXES[k];
        let rows = [e(kx) - shear.x * e(kz), e(ky) - shear.y * e(kz), e(kz)];
        Self {
            origin: ray.origin,
            dir: ray.dir,
            frame,
            permute_shear: Mat3A::from_cols(rows[0], rows[1], rows[2]).transpose(),
            origin_a: ray.origin.into(),
        }
    }
}

/// Intersects the ray behind `ray` with triangle (`v0`, `v1`, `v2`), from either side.
///
/// Returns `(t, b1, b2)` for a hit with `0 < t < t_max`, `b1` and `b2` being the barycentric
/// weights of `v1` and `v2`. A hit is reported only when `t` is provably positive given the
/// rounding errors of the test (pbrt's conservative bound), so that a ray leaving a surface
/// whose origin was offset does not find that surface again at `t ≈ 0`. Where single
/// precision cannot prove it, or places the hit only roughly (a triangle far larger than
/// its distance from the origin), `t` and the barycentrics are recomputed in double
/// precision. Degenerate (zero-area) triangles and rays in the triangle's plane never hit.
#[inline]
pub fn intersect_triangle(
    ray: &RayPrecomputed,
    v0: Vec3,
    v1: Vec3,
    v2: Vec3,
    t_max: f32,
) -> Option<(f32, f32, f32)> {
    let sz = ray.frame.shear.z;

    // Vertices relative to the ray origin, then permuted and sheared so that the ray is the
    // +Z axis (z not yet scaled by Sz).
    let [a, b, c] = [v0, v1, v2].map(|v| ray.permute_shear * (Vec3A::from(v) - ray.origin_a));
    let (ax, ay) = (a.x, a.y);
    let (bx, by) = (b.x, b.y);
    let (cx, cy) = (c.x, c.y);

    // Scaled barycentric coordinates: the edge functions of the edges opposite each vertex.
    let mut u = cx * by - cy * bx;
    let mut v = ax * cy - ay * cx;
    let mut w = bx * ay - by * ax;

    // An edge function that rounded to zero may really be slightly positive or negative:
    // products of f32 are exact in f64, so one rounding there gives the correct sign.
    if u == 0.0 || v == 0.0 || w == 0.0 {
        let (a2, b2, c2) = (
            DVec2::new(ax as f64, ay as f64),
            DVec2::new(bx as f64, by as f64),
            DVec2::new(cx as f64, cy as f64),
        );
        u = (c2.x * b2.y - c2.y * b2.x) as f32;
        v = (a2.x * c2.y - a2.y * c2.x) as f32;
        w = (b2.x * a2.y - b2.y * a2.x) as f32;
    }

    // Both-faced edge test: all three on the same side (zero counts as either side).
    if (u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0) {
        return None;
    }
    let det = u + v + w;
    if det == 0.0 {
        return None;
    }

    // Scaled hit distance (the paper's), and bounds on its error (see `Placement`).
    let hit = Placement::new([ax, bx, cx], [ay, by, cy], [a.z, b.z, c.z], sz, [u, v, w]);
    let t = hit.t;
    let placed = t > hit.t_error(hit.spread) * IMPRECISE;
    match single_precision_decides(t, placed, || hit.t_error(hit.max_zt), t_max) {
        Some(true) => Some((t, v * hit.inv_det, w * hit.inv_det)),
        Some(false) => None,
        // The bounds grow with the triangle's size and its distance from the origin, not
        // with t: on a huge triangle seen from close by (a 1e5 floor under a camera 1e-3
        // above it) single precision can neither place the hit nor prove it in front.
        // Double precision can.
        None => precise_hit(ray, v0, v1, v2, t_max),
    }
}

/// The whole test's decision past its edge test from single precision's numbers, for the
/// scalar test and the lanes alike: whether the triangle is hit below `t_max`, or `None`
/// where double precision must decide. `placed`: whether `t` lies past [`IMPRECISE`] times
/// the extent's error bound; `delta_t`: the depth's bound ([`Placement::t_error`] of
/// `max_zt`), asked only for a hit not placed.
#[inline(always)]
pub(crate) fn single_precision_decides(
    t: f32,
    placed: bool,
    delta_t: impl FnOnce() -> f32,
    t_max: f32,
) -> Option<bool> {
    if placed {
        return Some(t < t_max);
    }
    // Provably behind the origin (the surface a ray leaves) or beyond t_max (and NaN).
    let delta_t = delta_t();
    if !(t + delta_t > 0.0 && t - delta_t < t_max) {
        return Some(false);
    }
    None
}

/// When the single-precision bound on the error of `t` and of the hit's position exceeds
/// this fraction of `t`, the hit is recomputed in double precision.
pub(crate) const IMPRECISE: f32 = 1024.0;

/// The bounds' `gamma`s, named so that they are folded at compile time.
const G2: f32 = gamma(2);
const G3: f32 = gamma(3);
const G5: f32 = gamma(5);

/// One number, or four in SIMD lanes: what [`Placement`] computes in, so that the lane
/// test ([`RayLanes::test`]) places a hit with the very bits the whole test would.
pub(crate) trait Lanes:
    Copy + Add<Output = Self> + Sub<Output = Self> + Mul<Output = Self> + Mul<f32, Output = Self>
{
    /// Division, for the reciprocal of the determinant.
    fn recip(self) -> Self;
    fn abs(self) -> Self;
    /// The larger; NaN in either makes it either (no NaN reaches a kept hit: see
    /// [`Placement`]).
    fn max(self, other: Self) -> Self;
}

impl Lanes for f32 {
    #[inline(always)]
    fn recip(self) -> f32 {
        1.0 / self
    }
    #[inline(always)]
    fn abs(self) -> f32 {
        f32::abs(self)
    }
    #[inline(always)]
    fn max(self, other: f32) -> f32 {
        f32::max(self, other)
    }
}

impl Lanes for Vec4 {
    #[inline(always)]
    fn recip(self) -> Vec4 {
        Vec4::ONE / self
    }
    #[inline(always)]
    fn abs(self) -> Vec4 {
        Vec4::abs(self)
    }
    #[inline(always)]
    fn max(self, other: Vec4) -> Vec4 {
        Vec4::max(self, other)
    }
}

/// The watertight test's hit distance from the sheared vertices and the edge functions,
/// with bounds on its error from every rounding before it (pbrt-v4, "Ensure that computed
/// triangle t is conservatively greater than zero"), for one triangle or four in lanes:
/// one definition, the same operations in the same order either way (the grouping of each
/// sum and product is the bits: operands may swap, which IEEE keeps exact, but not
/// regroup). Any NaN among the
/// inputs makes `t` NaN, which no comparison keeps, so the lanes' `max` (SSE's, which may
/// pass a NaN by) and `f32::max` (which drops it) never decide a hit differently.
pub(crate) struct Placement<T> {
    /// The hit distance, in the ray direction's units.
    pub t: T,
    /// 1 / (u + v + w): the barycentrics are `v · inv_det` and `w · inv_det`.
    pub inv_det: T,
    /// The vertices' largest depth, scaled to `t`'s units.
    pub max_zt: T,
    /// The triangle's extent, in `t`'s units: at most |b − a| + |c − a| along each axis.
    pub spread: T,
    /// Parts of [`Self::t_error`].
    max_e: T,
    delta_e: T,
    delta_z: T,
}

impl<T: Lanes> Placement<T> {
    /// From the vertices' sheared `x`, `y` and unscaled `z` (relative to the ray's origin),
    /// the shear's `sz` and the edge functions `[u, v, w]`.
    #[inline(always)]
    pub fn new(x: [T; 3], y: [T; 3], z: [T; 3], sz: T, [u, v, w]: [T; 3]) -> Self {
        let scaled = z.map(|z| sz * z);
        let t_scaled = u * scaled[0] + v * scaled[1] + w * scaled[2];
        let inv_det = (u + v + w).recip();
        let largest = |c: [T; 3]| c[0].abs().max(c[1].abs()).max(c[2].abs());
        let max_zt = largest(scaled);
        let (max_xt, max_yt) = (largest(x), largest(y));
        // x' = x - Sx·z rounds relative to |x| + |z| (|Sx| <= 1), with z in the vertices'
        // units. pbrt takes the scaled z (in t's units), which is the same only for a unit
        // direction: an instance scaled by 1e6 has object-space directions of length 1e-6,
        // and its bound would come out a million times too large (every hit refused).
        let max_z = largest(z);
        let delta_x = (max_xt + max_z) * G5;
        let delta_y = (max_yt + max_z) * G5;
        let delta_e = (max_xt * G2 * max_yt + delta_y * max_xt + delta_x * max_yt) * 2.0;
        let extent = |c: [T; 3]| (c[1] - c[0]).abs() + (c[2] - c[0]).abs();
        Placement {
            t: t_scaled * inv_det,
            inv_det,
            max_zt,
            spread: (extent(x) + extent(y) + extent(z)) * sz.abs(),
            max_e: largest([u, v, w]),
            delta_e,
            delta_z: max_zt * G3,
        }
    }

    /// pbrt's bound on t's error, with the edge functions' errors times `depth`: the
    /// vertices' depth ([`Self::max_zt`]) for pbrt's delta_t, which rules out hits behind
    /// the origin; the triangle's extent ([`Self::spread`]) for whether single precision
    /// places the hit well enough to keep it. t is the mean of the depths weighted by the
    /// edge functions, and moves with each by (z_i − t)/det: at most the triangle's extent
    /// in depth over det, and the hit's barycentric point likewise. On a small triangle far
    /// away (any dense mesh seen whole) the extent is a thousandth of the depth, where the
    /// depth-based bound sent nearly every hit to double precision; a huge triangle seen
    /// from close by still goes there. A t past [`IMPRECISE`] times the extent's bound is
    /// placed, and proven positive.
    #[inline(always)]
    pub fn t_error(&self, depth: T) -> T {
        (self.max_e * G3 * self.max_zt + self.delta_e * depth + self.delta_z * self.max_e)
            * 3.0
            * self.inv_det.abs()
    }
}

/// [`intersect_triangle`] for a ray the single-precision test found inside the triangle
/// but could not place: `t`, `b1` and `b2` recomputed in double precision from the same
/// single-precision inputs (exact in double), `t` kept only if provably positive by the
/// same error bound with double's unit roundoff. Which triangle the ray is in stays the
/// single-precision test's decision, so that shared edges stay watertight.
#[cold]
#[inline(never)]
fn precise_hit(
    ray: &RayPrecomputed,
    v0: Vec3,
    v1: Vec3,
    v2: Vec3,
    t_max: f32,
) -> Option<(f32, f32, f32)> {
    #[cfg(test)]
    tests::PRECISE_HITS.with(|n| n.set(n.get() + 1));
    const fn gamma64(n: i32) -> f64 {
        const U: f64 = f64::EPSILON * 0.5;
        let nu = n as f64 * U;
        nu / (1.0 - nu)
    }
    let [kx, ky, kz] = ray.frame.axes;
    // Arrays, not `DVec3`, so that indexing by axis is a load rather than a `match`.
    let d = ray.dir.as_dvec3().to_array();
    let (sx, sy, sz) = (d[kx] / d[kz], d[ky] / d[kz], 1.0 / d[kz]);
    let o = ray.origin.as_dvec3();
    let [a, b, c] = [v0, v1, v2].map(|v| (v.as_dvec3() - o).to_array());
    let (ax, ay) = (a[kx] - sx * a[kz], a[ky] - sy * a[kz]);
    let (bx, by) = (b[kx] - sx * b[kz], b[ky] - sy * b[kz]);
    let (cx, cy) = (c[kx] - sx * c[kz], c[ky] - sy * c[kz]);
    let u = cx * by - cy * bx;
    let v = ax * cy - ay * cx;
    let w = bx * ay - by * ax;
    let det = u + v + w;
    if det == 0.0 || !det.is_finite() {
        return None;
    }
    let (az, bz, cz) = (sz * a[kz], sz * b[kz], sz * c[kz]);
    let t = (u * az + v * bz + w * cz) / det;

    // The bound of intersect_triangle, in double precision (one more rounding each for the
    // subtractions from the origin and the shear constants, which are not exact here).
    let max_zt = az.abs().max(bz.abs()).max(cz.abs());
    let max_xt = ax.abs().max(bx.abs()).max(cx.abs());
    let max_yt = ay.abs().max(by.abs()).max(cy.abs());
    let max_z = a[kz].abs().max(b[kz].abs()).max(c[kz].abs());
    let delta_z = gamma64(4) * max_zt;
    let delta_x = gamma64(6) * (max_xt + max_z);
    let delta_y = gamma64(6) * (max_yt + max_z);
    let delta_e = 2.0 * (gamma64(2) * max_xt * max_yt + delta_y * max_xt + delta_x * max_yt);
    let max_e = u.abs().max(v.abs()).max(w.abs());
    let delta_t =
        3.0 * (gamma64(3) * max_e * max_zt + delta_e * max_zt + delta_z * max_e) / det.abs();
    let t32 = t as f32;
    if !(t > delta_t && t32 > 0.0 && t32 < t_max) {
        return None;
    }
    // Inside by the single-precision test: keep the barycentrics inside too.
    let (b1, b2) = ((v / det).clamp(0.0, 1.0), (w / det).clamp(0.0, 1.0));
    let sum = b1 + b2;
    let (b1, b2) = if sum > 1.0 {
        (b1 / sum, b2 / sum)
    } else {
        (b1, b2)
    };
    Some((t32, b1 as f32, b2 as f32))
}

#[cfg(test)]
mod tests {
    use std::cell::Cell;

    use super::*;
    use crate::test_rng::Rng;

    thread_local! {
        /// Calls of [`precise_hit`] on this thread.
        pub(super) static PRECISE_HITS: Cell<u32> = const { Cell::new(0) };
    }

    fn hit(o: Vec3, d: Vec3, tri: [Vec3; 3], t_max: f32) -> Option<(f32, f32, f32)> {
        intersect_triangle(
            &RayPrecomputed::new(&Ray::new(o, d)),
            tri[0],
            tri[1],
            tri[2],
            t_max,
        )
    }

    const TRI: [Vec3; 3] = [
        Vec3::new(0.0, 0.0, 0.0),
        Vec3::new(1.0, 0.0, 0.0),
        Vec3::new(0.0, 1.0, 0.0),
    ];

    #[test]
    fn hits_inside_with_barycentrics_of_v1_and_v2() {
        let (t, b1, b2) = hit(
            Vec3::new(0.25, 0.5, 2.0),
            Vec3::new(0.0, 0.0, -1.0),
            TRI,
            f32::INFINITY,
        )
        .unwrap();
        assert!((t - 2.0).abs() < 1e-6);
        assert!((b1 - 0.25).abs() < 1e-6 && (b2 - 0.5).abs() < 1e-6);
        // A non-unit direction scales t, not the point.
        let (t, ..) = hit(
            Vec3::new(0.25, 0.5, 2.0),
            Vec3::new(0.0, 0.0, -4.0),
            TRI,
            f32::INFINITY,
        )
        .unwrap();
        assert!((t - 0.5).abs() < 1e-6);
    }

    #[test]
    fn both_faces_and_both_windings_hit() {
        let o = Vec3::new(0.2, 0.2, 1.0);
        let flipped = [TRI[0], TRI[2], TRI[1]];
        for tri in [TRI, flipped] {
            assert!(hit(o, -Vec3::Z, tri, 10.0).is_some());
            assert!(hit(o * Vec3::new(1.0, 1.0, -1.0), Vec3::Z, tri, 10.0).is_some());
        }
        // Barycentrics follow the vertex order, whatever the winding.
        let (_, b1, b2) = hit(Vec3::new(0.1, 0.3, 1.0), -Vec3::Z, flipped, 10.0).unwrap();
        assert!((b1 - 0.3).abs() < 1e-6 && (b2 - 0.1).abs() < 1e-6);
    }

    #[test]
    fn misses_outside_behind_and_beyond_t_max() {
        assert!(hit(Vec3::new(0.8, 0.8, 1.0), -Vec3::Z, TRI, 10.0).is_none());
        assert!(hit(Vec3::new(0.2, 0.2, 1.0), Vec3::Z, TRI, 10.0).is_none());
        assert!(hit(Vec3::new(0.2, 0.2, 1.0), -Vec3::Z, TRI, 1.0).is_none());
        assert!(hit(Vec3::new(0.2, 0.2, 1.0), -Vec3::Z, TRI, 1.0001).is_some());
    }

    #[test]
    fn degenerate_cases_never_hit() {
        // In the triangle's plane.
        assert!(hit(Vec3::new(-1.0, 0.2, 0.0), Vec3::X, TRI, 10.0).is_none());
        // Zero-area triangles: a point and a segment.
        let p = Vec3::splat(0.5);
        assert!(hit(Vec3::new(0.5, 0.5, 2.0), -Vec3::Z, [p, p, p], 10.0).is_none());
        let seg = [
            Vec3::ZERO,
            Vec3::new(1.0, 1.0, 0.0),
            Vec3::new(0.5, 0.5, 0.0),
        ];
        assert!(hit(Vec3::new(0.5, 0.5, 2.0), -Vec3::Z, seg, 10.0).is_none());
        // Zero or NaN directions, NaN vertices, NaN t_max.
        assert!(hit(Vec3::new(0.2, 0.2, 1.0), Vec3::ZERO, TRI, 10.0).is_none());
        assert!(hit(Vec3::new(0.2, 0.2, 1.0), Vec3::NAN, TRI, 10.0).is_none());
        let nan_tri = [TRI[0], Vec3::new(f32::NAN, 0.0, 0.0), TRI[2]];
        assert!(hit(Vec3::new(0.2, 0.2, 1.0), -Vec3::Z, nan_tri, 10.0).is_none());
        assert!(hit(Vec3::new(0.2, 0.2, 1.0), -Vec3::Z, TRI, f32::NAN).is_none());
    }

    #[test]
    fn ray_through_a_vertex_hits_with_that_vertex_weight() {
        let (t, b1, b2) = hit(Vec3::new(1.0, 0.0, 3.0), -Vec3::Z, TRI, 10.0).unwrap();
        assert_eq!((t, b1, b2), (3.0, 1.0, 0.0));
    }

    #[test]
    fn double_precision_fallback_decides_the_edge() {
        // Ray along +Z from the origin, so the 2D coordinates are the vertices' x and y.
        // With e = 2^-23, edge (v1, v2) gives Cx·By - Cy·Bx = -(1+e)² + (1+2e) = -e², which
        // rounds to exactly 0 in f32: without the f64 fallback the origin would count as on
        // the edge and both triangles below would be hit.
        let e = f32::EPSILON;
        let b = Vec3::new(-1.0, -(1.0 + e), 1.0);
        let c = Vec3::new(1.0 + e, 1.0 + 2.0 * e, 1.0);
        assert_eq!(c.x * b.y - c.y * b.x, 0.0);
        let inside = [Vec3::new(-1.0, 1.0, 1.0), b, c];
        let outside = [Vec3::new(1.0, -1.0, 1.0), b, c];
        assert!(hit(Vec3::ZERO, Vec3::Z, inside, 10.0).is_some());
        assert!(hit(Vec3::ZERO, Vec3::Z, outside, 10.0).is_none());
    }

    #[test]
    fn rays_through_a_shared_vertex_or_edge_hit_a_fan_of_triangles() {
        // A closed fan of 7 triangles around a centre vertex, slightly non-planar.
        let mut rng = Rng(0x9e3779b97f4a7c15);
        let centre = Vec3::new(0.1, -0.2, 0.05);
        let rim: Vec<Vec3> = (0..7)
            .map(|i| {
                let a = i as f32 * std::f32::consts::TAU / 7.0;
                Vec3::new(a.cos(), a.sin(), 0.3 * (rng.next_f32() - 0.5))
            })
            .collect();
        let tris: Vec<[Vec3; 3]> = (0..7).map(|i| [centre, rim[i], rim[(i + 1) % 7]]).collect();
        for _ in 0..20_000 {
            let o = (rng.vec3() - Vec3::new(0.5, 0.5, -1.0)) * 4.0;
            let i = (rng.next_f32() * 7.0) as usize % 7;
            let f = rng.next_f32();
            // Exactly at the centre, or at a point rounded onto a spoke edge.
            let target = if f < 0.2 {
                centre
            } else {
                centre + (rim[i] - centre) * f
            };
            let pre = RayPrecomputed::new(&Ray::new(o, target - o));
            let hits = tris
                .iter()
                .filter(|t| intersect_triangle(&pre, t[0], t[1], t[2], f32::INFINITY).is_some())
                .count();
            assert!(
                hits >= 1,
                "ray from {o} to {target} slipped through the fan"
            );
        }
    }

    /// A uniformly random point of `tri`.
    fn random_point(tri: &[Vec3; 3], rng: &mut Rng) -> Vec3 {
        let (r1, r2) = (rng.next_f32(), rng.next_f32());
        let (b1, b2) = if r1 + r2 > 1.0 {
            (1.0 - r1, 1.0 - r2)
        } else {
            (r1, r2)
        };
        tri[0] + (tri[1] - tri[0]) * b1 + (tri[2] - tri[0]) * b2
    }

    /// Hits of `tris` by rays from `eye` through random points of them, and how many of
    /// those hits went to double precision.
    fn hits_and_precise(eye: Vec3, tris: &[[Vec3; 3]], rng: &mut Rng) -> (u32, u32) {
        let before = PRECISE_HITS.get();
        let mut hits = 0;
        for tri in tris {
            let target = random_point(tri, rng);
            let pre = RayPrecomputed::new(&Ray::new(eye, target - eye));
            hits += u32::from(intersect_triangle(&pre, tri[0], tri[1], tri[2], 2.0).is_some());
        }
        (hits, PRECISE_HITS.get() - before)
    }

    #[test]
    fn a_dense_mesh_seen_whole_is_placed_in_single_precision() {
        // Triangles 1/1000 of their distance across (a million-triangle mesh filling the
        // view), at scales from 1e-4 to 1e5, head-on and tilted up to one radian: single
        // precision places each hit to far better than t/1024. The depth-based bound sent
        // all but a few of these to double precision.
        let mut rng = Rng(5);
        for scale in [1e-4, 1.0, 1e5] {
            for tilt in [0.0f32, 0.5, 1.0] {
                let eye = Vec3::new(0.0, 0.0, scale);
                let tris: Vec<[Vec3; 3]> = (0..2000)
                    .map(|_| {
                        let c = (rng.vec3() - 0.5) * Vec3::new(scale, scale, 0.0);
                        let size = scale * 1e-3;
                        let [x, y] = [
                            Vec3::X * size,
                            Vec3::new(0.0, tilt.cos(), tilt.sin()) * size,
                        ];
                        [c, c + x, c + y]
                    })
                    .collect();
                let (hits, precise) = hits_and_precise(eye, &tris, &mut rng);
                assert!(hits > 1900, "{hits} of 2000 at scale {scale}");
                assert_eq!(precise, 0, "scale {scale}, tilt {tilt}");
            }
        }
    }

    #[test]
    fn a_huge_triangle_seen_from_close_by_goes_to_double_precision() {
        // A floor 1e5 across under an eye 1e-3 above it: single precision can place the
        // hit only to centimetres along the floor, ten times the distance.
        let floor = [
            Vec3::new(-1e5, -1e5, 0.0),
            Vec3::new(1e5, -1e5, 0.0),
            Vec3::new(0.0, 1e5, 0.0),
        ];
        let eye = Vec3::new(3.0, 7.0, 1e-3);
        let (hits, precise) = hits_and_precise(eye, &[floor; 100], &mut Rng(9));
        assert_eq!((hits, precise), (100, 100));
    }

    #[test]
    fn hits_kept_in_single_precision_are_placed_to_a_thousandth_of_t() {
        // Random triangles from 1e-4 to 1e5 across, at distances from 1e-3 to 1e6 times
        // that, at any angle: where single precision keeps a hit, its t and its point (from
        // the barycentrics) are within t/1024 of the double-precision ones.
        let mut rng = Rng(21);
        let (mut single, mut double) = (0, 0);
        for _ in 0..20_000 {
            let size = 10f32.powf(rng.next_f32() * 9.0 - 4.0);
            let distance = size * 10f32.powf(rng.next_f32() * 9.0 - 3.0);
            let centre = (rng.vec3() - 0.5) * distance;
            let tri = [0, 1, 2].map(|_| centre + (rng.vec3() - 0.5) * size);
            let target = random_point(&tri, &mut rng);
            let eye = target + (rng.vec3() - 0.5).normalize() * distance;
            let pre = RayPrecomputed::new(&Ray::new(eye, target - eye));
            let before = PRECISE_HITS.get();
            let Some((t, b1, b2)) = intersect_triangle(&pre, tri[0], tri[1], tri[2], 2.0) else {
                continue;
            };
            if PRECISE_HITS.get() > before {
                double += 1;
                continue;
            }
            single += 1;
            let (t_ref, r1, r2) = precise_hit(&pre, tri[0], tri[1], tri[2], 2.0).unwrap();
            assert!((t - t_ref).abs() <= t / 1024.0, "t {t} against {t_ref}");
            let point = |b1: f32, b2: f32| {
                let [a, b, c] = tri.map(|v| v.as_dvec3());
                a + (b - a) * b1 as f64 + (c - a) * b2 as f64
            };
            let off = point(b1, b2).distance(point(r1, r2));
            let t_length = t as f64 * (target - eye).length() as f64;
            assert!(off <= t_length / 1024.0, "point {off} off at t {t_length}");
        }
        assert!(
            single > 10_000 && double > 100,
            "{single} single, {double} double"
        );
    }
}

//! The watertight test for four triangles at once, in SIMD lanes. A leaf's triangles go
//! through it four at a time, read from their block's rows (`triangle/rows.rs`). The three
//! edge functions decide most misses; for the triangles they keep, the lanes go on to the
//! hit distance and its error bounds ([`Placement`]), and where those place the hit, or
//! prove it behind the origin (the surface a ray leaves) or past `t_max`, the lanes'
//! answer is the whole test's. The rest (an edge function of zero, a hit single precision
//! cannot place) go through the whole test
//! ([`intersect_triangle`](super::intersect_triangle)). A leaf takes its candidates in
//! order either way, so it finds the same hits, with the same bits, as testing each
//! triangle alone. (Before the lanes placed hits, every candidate took the whole test out of
//! line, about 210 instructions each.)
//!
//! A triangle is ruled out only where its three edge functions are all non-zero and not all
//! of one sign, which is exactly where the whole test refuses it at its edge test. That
//! test transforms each vertex with a matrix (`permute_shear`) whose rows each hold a 1, a
//! shear constant and a 0; here the zero product is left out (`x − Sx·z` instead of
//! `1·x + (−Sx)·z + 0·y`). Adding a zero product is exact except for the sign of a zero
//! sum, so every coordinate, and so every edge function, is the same number here as there
//! but for the sign of a zero; and a zero edge function never rules a triangle out. Where
//! all three are non-zero, a coordinate's zero sign changes none of them, and none of the
//! hit distance's terms but a zero one, whose sum, if zero, places nothing. (Where a
//! coordinate overflows, the whole test's `0·inf` is NaN and refuses the triangle; here it
//! is an infinity, which rules the triangle out or leaves `t` NaN, placed nowhere.) The
//! same IEEE operations on every CPU: glam's SSE2 lanes on x86_64, its NEON or scalar
//! lanes elsewhere.

use glam::{BVec4A, Vec4};

use super::rows::Block;
use super::{single_precision_decides, Placement, RayShear, IMPRECISE};
use crate::geometry::Ray;

/// A ray's side of the lane test: its origin and shear constants in every lane, and which
/// vertex coordinates become the 2D x, y and the depth (`kx`, `ky`, `kz`).
#[derive(Clone, Copy, Debug)]
pub struct RayLanes {
    /// Origin components `kx`, `ky`, `kz`.
    origin: [Vec4; 3],
    /// Sx, Sy, Sz.
    shear: [Vec4; 3],
    /// `kx`, `ky`, `kz`, each below 3.
    axes: [usize; 3],
}

/// What the lane test found in a block: the triangles the ray may hit, and for those whose
/// edge functions are all non-zero, the whole test's numbers past its edge test.
#[derive(Clone, Copy, Debug)]
pub struct BlockHits {
    /// Bit `i` for each triangle `i` the ray may hit; it surely misses the others.
    pub candidates: u32,
    /// Bit `i` for each candidate whose numbers below are the whole test's.
    exact: u32,
    /// Bit `i` for each of those whose hit single precision places.
    placed: u32,
    // Arrays, not lanes: a lane picked by index is a load from them, where from a `Vec4`
    // the compiler shuffled every lane out first.
    t: [f32; 4],
    /// The bound on `t`'s error that decides whether the hit can be in front of the origin
    /// and before `t_max` at all.
    delta_t: [f32; 4],
    b1: [f32; 4],
    b2: [f32; 4],
}

/// The lane test's answer for one candidate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum LaneHit {
    /// A hit `(t, b1, b2)`, bit for bit the whole test's.
    Hit(f32, f32, f32),
    /// No hit, as the whole test would find.
    Miss,
    /// Only the whole test can tell (an edge function of zero, to recompute in double
    /// precision; a hit single precision cannot place).
    WholeTest,
}

impl BlockHits {
    /// What candidate `i` of the block is to a search that has found nothing closer than
    /// `t_max`: the whole test's decisions in its order, on the same numbers.
    #[inline(always)]
    pub fn decide(&self, i: usize, t_max: f32) -> LaneHit {
        if self.exact & (1 << i) == 0 {
            return LaneHit::WholeTest;
        }
        let t = self.t[i];
        let placed = self.placed & (1 << i) != 0;
        match single_precision_decides(t, placed, || self.delta_t[i], t_max) {
            Some(true) => LaneHit::Hit(t, self.b1[i], self.b2[i]),
            Some(false) => LaneHit::Miss,
            None => LaneHit::WholeTest,
        }
    }
}

impl RayLanes {
    /// The lanes of `ray`, once per ray. Only the shear constants: the whole test's matrix
    /// ([`RayPrecomputed`](super::RayPrecomputed)) is built where a candidate needs that
    /// test, a few times in a thousand queries (built per query, it cost about 80
    /// instructions each).
    // Inlined into each query, as `RayPrecomputed::new` is.
    #[inline(always)]
    pub fn new(ray: &Ray) -> Self {
        let RayShear { axes, shear } = RayShear::new(ray.dir);
        Self {
            origin: axes.map(|k| Vec4::splat(ray.origin.to_array()[k])),
            shear: shear.to_array().map(Vec4::splat),
            axes,
        }
    }

    /// The lane test of `block`'s triangles (bit or lane `i` for its triangle `i`).
    #[inline(always)]
    pub fn test(&self, block: &Block) -> BlockHits {
        let n = block.count();
        let [kx, ky, kz] = self.axes.map(|k| block.axis(k));
        // The last row's lanes past `n` read ids, whose bits may be subnormal floats, which
        // some CPUs compute with slowly: the last vertex's lanes past `n` are zeroed.
        let live = Vec4::new(0.0, 1.0, 2.0, 3.0).cmplt(Vec4::splat(n as f32));
        // One vertex of the four triangles, relative to the origin, in the ray's 2D frame,
        // and its depth (unscaled).
        let project = |j: usize| {
            let coord = |at: usize| match j {
                2 => Vec4::select(live, block.row(j, at), Vec4::ZERO),
                _ => block.row(j, at),
            };
            let z = coord(kz) - self.origin[2];
            (
                (coord(kx) - self.origin[0]) - self.shear[0] * z,
                (coord(ky) - self.origin[1]) - self.shear[1] * z,
                z,
            )
        };
        let ((ax, ay, az), (bx, by, bz), (cx, cy, cz)) = (project(0), project(1), project(2));
        let u = cx * by - cy * bx;
        let v = ax * cy - ay * cx;
        let w = bx * ay - by * ax;
        let any = |m: [BVec4A; 3]| m[0] | m[1] | m[2];
        let zero = any([u, v, w].map(|e| e.cmpeq(Vec4::ZERO)));
        let negative = any([u, v, w].map(|e| e.cmplt(Vec4::ZERO)));
        let positive = any([u, v, w].map(|e| e.cmpgt(Vec4::ZERO)));
        let ruled_out = !zero & negative & positive;
        let candidates = !ruled_out.bitmask() & ((1 << n) - 1);
        let mut hits = BlockHits {
            candidates,
            exact: 0,
            placed: 0,
            t: [0.0; 4],
            delta_t: [0.0; 4],
            b1: [0.0; 4],
            b2: [0.0; 4],
        };
        if candidates == 0 {
            return hits;
        }
        // The whole test's steps past its edge test, for triangles whose edge functions
        // are all non-zero (the others it recomputes in double precision first).
        let hit = Placement::new(
            [ax, bx, cx],
            [ay, by, cy],
            [az, bz, cz],
            self.shear[2],
            [u, v, w],
        );
        hits.exact = candidates & !zero.bitmask();
        hits.placed = hits.exact & hit.t.cmpgt(hit.t_error(hit.spread) * IMPRECISE).bitmask();
        hits.t = hit.t.to_array();
        hits.delta_t = hit.t_error(hit.max_zt).to_array();
        hits.b1 = (v * hit.inv_det).to_array();
        hits.b2 = (w * hit.inv_det).to_array();
        hits
    }
}

#[cfg(test)]
mod tests {
    use glam::Vec3;

    use super::super::{intersect_triangle, RayPrecomputed, TriangleRows, BLOCK};
    use super::*;
    use crate::geometry::Ray;
    use crate::test_rng::Rng;

    /// What [`check`] counted.
    #[derive(Default)]
    struct Counts {
        /// Triangles the whole test misses, of those the ones ruled out here, and the
        /// candidates the lanes decided were misses.
        missed: usize,
        ruled_out: usize,
        decided_misses: usize,
        /// Triangles the whole test hits, and of those the ones the lanes placed.
        hit: usize,
        placed: usize,
    }

    /// Checks the lane test against the whole test on `tris`, four at a time, for a search
    /// that has found nothing closer than `t_max`: a triangle it rules out is one the whole
    /// test misses, and a candidate it decides is decided as the whole test does, a hit
    /// bit for bit.
    fn check(ray: &Ray, tris: &[[Vec3; 3]], t_max: f32) -> Counts {
        let pre = RayPrecomputed::new(ray);
        let lanes = RayLanes::new(ray);
        // All in one leaf, in blocks of four from the first.
        let n = tris.len() as u32;
        let rows = TriangleRows::new(tris.iter().copied().zip(0..n), &[(0, n)]);
        let mut counts = Counts::default();
        for (block, chunk) in rows.leaf(0, tris.len()).zip(tris.chunks(BLOCK)) {
            let hits = lanes.test(&block);
            let may = hits.candidates;
            assert_eq!(may >> chunk.len(), 0, "a bit past the block's triangles");
            for (i, t) in chunk.iter().enumerate() {
                let hit = intersect_triangle(&pre, t[0], t[1], t[2], t_max);
                let kept = may & (1 << i) != 0;
                assert!(
                    kept || hit.is_none(),
                    "ray {ray:?} hits {t:?} ({hit:?}) but the lane test ruled it out"
                );
                let decided = match kept.then(|| hits.decide(i, t_max)) {
                    Some(LaneHit::Hit(t, b1, b2)) => Some(Some((t, b1, b2))),
                    Some(LaneHit::Miss) => Some(None),
                    _ => None,
                };
                if let Some(lanes_hit) = decided {
                    let bits = |h: (f32, f32, f32)| [h.0, h.1, h.2].map(f32::to_bits);
                    assert_eq!(
                        lanes_hit.map(bits),
                        hit.map(bits),
                        "ray {ray:?}, triangle {t:?}: lanes {lanes_hit:?}, whole test {hit:?}"
                    );
                }
                counts.missed += usize::from(hit.is_none());
                counts.ruled_out += usize::from(!kept);
                counts.decided_misses += usize::from(decided == Some(None));
                counts.hit += usize::from(hit.is_some());
                counts.placed += usize::from(hit.is_some() && decided.is_some());
            }
        }
        counts
    }

    #[test]
    fn rules_out_only_misses_and_places_hits_as_the_whole_test() {
        let mut rng = Rng(11);
        let mut counts = Counts::default();
        for n in 0..6000 {
            let scale = [1e-4, 1.0, 1e5][n % 3];
            let tris: Vec<[Vec3; 3]> = (0..1 + n % 7)
                .map(|_| {
                    let c = (rng.vec3() - 0.5) * scale;
                    [0, 1, 2].map(|_| c + (rng.vec3() - 0.5) * scale * 0.3)
                })
                .collect();
            // At random, or (every other ray) aimed inside one of the triangles.
            let origin = (rng.vec3() - 0.5) * scale * 2.0;
            let [a, b, c] = tris[n % tris.len()];
            let (u, v) = rng.vec2().into();
            let (u, v) = if u + v > 1.0 {
                (1.0 - u, 1.0 - v)
            } else {
                (u, v)
            };
            let aimed = a + (b - a) * u + (c - a) * v - origin;
            let dir = [aimed, rng.vec3() - 0.5][n % 2];
            let ray = Ray::new(origin, dir);
            // Unbounded, or ending where an aimed ray meets its triangle (as after a closer
            // hit found before).
            let t_max = [f32::INFINITY, 1.0][n / 2 % 2];
            let c = check(&ray, &tris, t_max);
            counts.missed += c.missed;
            counts.ruled_out += c.ruled_out;
            counts.hit += c.hit;
            counts.placed += c.placed;
            counts.decided_misses += c.decided_misses;
        }
        // Most misses fail the edge test; the rest are behind the origin (the whole test's
        // later checks). Half the random rays start behind their triangles.
        let Counts {
            missed,
            ruled_out,
            decided_misses,
            hit,
            placed,
        } = counts;
        assert!(missed > 5000, "{missed}");
        assert!(decided_misses > 500, "{decided_misses}");
        assert!(
            ruled_out * 10 > missed * 5,
            "{ruled_out} of {missed} misses ruled out"
        );
        // Nearly every hit is placed in the lanes: the whole test is for the rare rest.
        assert!(
            hit > 1000 && placed * 100 > hit * 95,
            "{placed} of {hit} hits placed"
        );
    }

    #[test]
    fn leaves_to_the_whole_test_the_hits_it_cannot_place() {
        // Huge triangles seen from close by, where single precision can neither place the
        // hit nor prove it in front (the whole test goes to double precision), and tiny
        // ones far away; every placed hit checked against the whole test.
        let mut rng = Rng(5);
        let mut counts = Counts::default();
        for n in 0..3000 {
            let (size, distance) = [(1e5, 1e-3), (1e-3, 1e4), (1e6, 1.0)][n % 3];
            let tris: Vec<[Vec3; 3]> = (0..1 + n % 5)
                .map(|_| {
                    let c = (rng.vec3() - 0.5) * size * 0.1;
                    [0, 1, 2].map(|_| c + (rng.vec3() - 0.5) * size)
                })
                .collect();
            let [a, b, c] = tris[n % tris.len()];
            let target = a * 0.2 + b * 0.3 + c * 0.5;
            let origin = target + (rng.vec3() - 0.5).normalize_or(Vec3::Z) * distance;
            let c = check(&Ray::new(origin, target - origin), &tris, f32::INFINITY);
            counts.hit += c.hit;
            counts.placed += c.placed;
        }
        let Counts { hit, placed, .. } = counts;
        assert!(hit > 1000, "{hit}");
        assert!(
            placed < hit,
            "{placed} of {hit}: every hit placed, none left over"
        );
    }

    #[test]
    fn decides_in_lanes_that_a_ray_misses_the_surface_it_leaves() {
        // Every bounce and shadow ray starts on the triangle it leaves, whose edge test it
        // passes at t ≈ 0: the lanes refuse it as the whole test does, without it.
        let mut rng = Rng(7);
        let (mut left, mut decided) = (0, 0);
        for n in 0..2000 {
            let scale = [1e-4, 1.0, 1e5][n % 3];
            let tris: Vec<[Vec3; 3]> = (0..1 + n % 4)
                .map(|_| [0, 1, 2].map(|_| (rng.vec3() - 0.5) * scale))
                .collect();
            let [a, b, c] = tris[0];
            let normal = (b - a).cross(c - a).normalize_or_zero();
            // Offset off the surface by the integrator's ulp steps.
            let on = a * 0.25 + b * 0.25 + c * 0.5;
            let origin = crate::geometry::offset_ray_origin_bounded(on, normal, Vec3::ZERO);
            let away = (rng.vec3() - 0.5) + normal;
            let dir = if away.dot(normal) > 0.0 { away } else { -away };
            let counts = check(&Ray::new(origin, dir), &tris, f32::INFINITY);
            left += 1;
            decided += counts.decided_misses.min(1);
        }
        // (The rest start too close for single precision to prove the surface behind: the
        // integrator offsets by the point's error bound too, which this leaves out.)
        assert!(decided * 4 > left * 3, "{decided} of {left} decided");
    }

    #[test]
    fn keeps_triangles_whose_edges_or_vertices_the_ray_meets() {
        // A grid of unit squares in z = 0, each two triangles, and rays from above and from
        // grid-aligned origins through vertices, edge points and along axes: edge functions
        // of zero, and zero coordinates whose sign the two formulas may round differently.
        let mut tris = Vec::new();
        for i in -2..2 {
            for j in -2..2 {
                let (x, y) = (i as f32, j as f32);
                let p = |dx: f32, dy: f32| Vec3::new(x + dx, y + dy, 0.0);
                tris.push([p(0.0, 0.0), p(1.0, 0.0), p(1.0, 1.0)]);
                tris.push([p(0.0, 0.0), p(1.0, 1.0), p(0.0, 1.0)]);
            }
        }
        let targets = [
            Vec3::ZERO,
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(0.5, 0.5, 0.0),
            Vec3::new(0.5, 0.0, 0.0),
            Vec3::new(-1.0, 0.25, 0.0),
            Vec3::new(0.3, 0.3, 0.0),
        ];
        let origins = [
            Vec3::new(0.0, 0.0, 1.0),
            Vec3::new(0.0, 0.0, -3.0),
            Vec3::new(2.0, 0.0, 1.0),
            Vec3::new(0.5, 0.5, 2.0),
            Vec3::new(-0.0, 1.0, 1.0),
        ];
        let mut hits = 0;
        for o in origins {
            for t in targets {
                let ray = Ray::new(o, t - o);
                check(&ray, &tris, f32::INFINITY);
                let pre = RayPrecomputed::new(&ray);
                hits +=
                    usize::from(tris.iter().any(|t| {
                        intersect_triangle(&pre, t[0], t[1], t[2], f32::INFINITY).is_some()
                    }));
            }
        }
        // Every ray aims at a point of the grid: none slips through.
        assert_eq!(hits, origins.len() * targets.len());
    }
}

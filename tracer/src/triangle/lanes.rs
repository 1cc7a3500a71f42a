//! The first half of the watertight test for four triangles at once, in SIMD lanes: the
//! three edge functions, which decide most misses. A leaf's triangles go through it four
//! at a time, read from their block's rows (`triangle/rows.rs`), and only those it cannot
//! rule out go through the whole test
//! ([`intersect_triangle`](super::intersect_triangle)), one by one and in order, so a leaf
//! finds the same hits, with the same bits, as testing each triangle alone.
//!
//! A triangle is ruled out only where its three edge functions are all non-zero and not all
//! of one sign, which is exactly where the whole test refuses it at its edge test. That
//! test transforms each vertex with a matrix (`permute_shear`) whose rows each hold a 1, a
//! shear constant and a 0; here the zero product is left out (`x − Sx·z` instead of
//! `1·x + (−Sx)·z + 0·y`). Adding a zero product is exact except for the sign of a zero
//! sum, so every coordinate, and so every edge function, is the same number here as there
//! but for the sign of a zero; and a zero edge function never rules a triangle out. (Where
//! a coordinate overflows, the whole test's `0·inf` is NaN and refuses the triangle
//! anyway.) The same IEEE operations on every CPU: glam's SSE2 lanes on x86_64, its NEON or
//! scalar lanes elsewhere.

use glam::{BVec4A, Vec4};

use super::rows::Block;
use super::RayPrecomputed;

/// A ray's side of the lane test: its origin and shear constants in every lane, and which
/// vertex coordinates become the 2D x, y and the depth (`kx`, `ky`, `kz`).
#[derive(Clone, Copy, Debug)]
pub struct RayLanes {
    /// Origin components `kx`, `ky`, `kz`.
    origin: [Vec4; 3],
    /// Sx, Sy.
    shear: [Vec4; 2],
    /// `kx`, `ky`, `kz`, each below 3.
    axes: [usize; 3],
}

impl RayLanes {
    /// The lanes of `ray`, once per ray.
    // Inlined into each query, as `RayPrecomputed::new` is.
    #[inline(always)]
    pub fn new(ray: &RayPrecomputed) -> Self {
        let axes = [ray.kx, ray.ky, ray.kz];
        Self {
            origin: axes.map(|k| Vec4::splat(ray.origin.to_array()[k])),
            shear: [Vec4::splat(ray.shear.x), Vec4::splat(ray.shear.y)],
            axes,
        }
    }

    /// A bit per triangle of `block` (bit `i` for its triangle `i`) that the ray may hit:
    /// the others it surely misses.
    #[inline(always)]
    pub fn may_hit(&self, block: &Block) -> u32 {
        let n = block.count();
        let [kx, ky, kz] = self.axes.map(|k| block.axis(k));
        // The last row's lanes past `n` read ids, whose bits may be subnormal floats, which
        // some CPUs compute with slowly: the last vertex's lanes past `n` are zeroed.
        let live = Vec4::new(0.0, 1.0, 2.0, 3.0).cmplt(Vec4::splat(n as f32));
        // One vertex of the four triangles, relative to the origin, in the ray's 2D frame.
        let project = |j: usize| {
            let coord = |at: usize| match j {
                2 => Vec4::select(live, block.row(j, at), Vec4::ZERO),
                _ => block.row(j, at),
            };
            let z = coord(kz) - self.origin[2];
            (
                (coord(kx) - self.origin[0]) - self.shear[0] * z,
                (coord(ky) - self.origin[1]) - self.shear[1] * z,
            )
        };
        let ((ax, ay), (bx, by), (cx, cy)) = (project(0), project(1), project(2));
        let u = cx * by - cy * bx;
        let v = ax * cy - ay * cx;
        let w = bx * ay - by * ax;
        let any = |m: [BVec4A; 3]| m[0] | m[1] | m[2];
        let zero = any([u, v, w].map(|e| e.cmpeq(Vec4::ZERO)));
        let negative = any([u, v, w].map(|e| e.cmplt(Vec4::ZERO)));
        let positive = any([u, v, w].map(|e| e.cmpgt(Vec4::ZERO)));
        let ruled_out = !zero & negative & positive;
        !ruled_out.bitmask() & ((1 << n) - 1)
    }
}

#[cfg(test)]
mod tests {
    use glam::Vec3;

    use super::super::{intersect_triangle, TriangleRows, BLOCK};
    use super::*;
    use crate::geometry::Ray;
    use crate::test_rng::Rng;

    /// Checks the lane test against the whole test on `tris`, four at a time: a triangle
    /// it rules out is one the whole test misses. Returns (triangles missed by the whole
    /// test, of those ruled out here).
    fn check(ray: &Ray, tris: &[[Vec3; 3]]) -> (usize, usize) {
        let pre = RayPrecomputed::new(ray);
        let lanes = RayLanes::new(&pre);
        // All in one leaf, in blocks of four from the first.
        let n = tris.len() as u32;
        let rows = TriangleRows::new(tris.iter().copied().zip(0..n), &[(0, n)]);
        let (mut missed, mut ruled_out) = (0, 0);
        for (block, chunk) in rows.leaf(0, tris.len()).zip(tris.chunks(BLOCK)) {
            let may = lanes.may_hit(&block);
            assert_eq!(may >> chunk.len(), 0, "a bit past the block's triangles");
            for (i, t) in chunk.iter().enumerate() {
                let hit = intersect_triangle(&pre, t[0], t[1], t[2], f32::INFINITY);
                let kept = may & (1 << i) != 0;
                assert!(
                    kept || hit.is_none(),
                    "ray {ray:?} hits {t:?} ({hit:?}) but the lane test ruled it out"
                );
                missed += usize::from(hit.is_none());
                ruled_out += usize::from(!kept);
            }
        }
        (missed, ruled_out)
    }

    #[test]
    fn rules_out_only_misses_and_most_of_them() {
        let mut rng = Rng(11);
        let (mut missed, mut ruled_out) = (0, 0);
        for n in 0..4000 {
            let scale = [1e-4, 1.0, 1e5][n % 3];
            let tris: Vec<[Vec3; 3]> = (0..1 + n % 7)
                .map(|_| {
                    let c = (rng.vec3() - 0.5) * scale;
                    [0, 1, 2].map(|_| c + (rng.vec3() - 0.5) * scale * 0.3)
                })
                .collect();
            let ray = Ray::new((rng.vec3() - 0.5) * scale * 2.0, rng.vec3() - 0.5);
            let (m, r) = check(&ray, &tris);
            missed += m;
            ruled_out += r;
        }
        // Most misses fail the edge test; the rest are behind the origin (the whole test's
        // later checks). Half the random rays start behind their triangles.
        assert!(missed > 5000, "{missed}");
        assert!(
            ruled_out * 10 > missed * 5,
            "{ruled_out} of {missed} misses ruled out"
        );
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
                check(&ray, &tris);
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

//! The flat binary BVH node, the robust ray/box slab test and the ordered stack traversal
//! of deforming meshes, whose boxes move over the shutter (static queries run on the same
//! trees collapsed eight-wide, in `wide`), and the traversal stack both share.

use std::cell::RefCell;

use glam::{BVec3A, Vec3, Vec3A};

use super::build::SAH_MAX_DEPTH;
use super::motion::Segment;
use super::wide::WIDTH;
use crate::geometry::Ray;
use crate::triangle::gamma;

/// One BVH node in 32 bytes, so that two siblings fill one 64-byte cache line.
///
/// An interior node has `count == 0` and its children at `start` and `start + 1`; a leaf
/// holds primitives `start .. start + count` of its BVH's primitive array.
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(C, align(32))]
pub(super) struct Node {
    pub min: Vec3,
    pub start: u32,
    pub max: Vec3,
    pub count: u32,
}

/// A deferred subtree on the traversal stack: its node, and the distance at which the ray
/// enters its box.
pub(super) type Deferred = (u32, f32);

/// Entries in each thread's traversal stack. A query's stack holds at most what one level
/// holds, twice (the instance level, and the mesh it searches above it). A level's path
/// from the root passes at most `2 · SAH_MAX_DEPTH + 1` nodes (see `build`; the eight-wide
/// tree is no deeper than the binary one it collapses), and each leaves at most seven of
/// its eight children behind (a binary node: one), so one level holds fewer than
/// [`LEVEL_STACK`] entries. A query past it would panic on the bounds check, not overrun.
pub(super) const STACK_CAPACITY: usize = 2 * LEVEL_STACK;

/// The most entries one level's traversal can hold (see [`STACK_CAPACITY`]).
pub(super) const LEVEL_STACK: usize = WIDTH * (2 * SAH_MAX_DEPTH as usize + 1);

thread_local! {
    /// Each thread's traversal stack, reused by every query: a fresh array per query had to
    /// be zeroed each time, 2.5% of a render's instructions. A fixed array rather than a
    /// `Vec`: a traversal keeps its height in a register, where `Vec::push` reloaded its
    /// length and capacity from memory at every push. The instance level and the mesh levels
    /// it enters share it, each working in the part above where its caller left it.
    static STACK: RefCell<[Deferred; STACK_CAPACITY]> =
        const { RefCell::new([(0, 0.0); STACK_CAPACITY]) };
}

/// Runs a query with this thread's traversal stack. Queries do not nest (an `accept`
/// callback must not start another), so the stack is never borrowed twice.
pub(super) fn with_stack<R>(query: impl FnOnce(&mut [Deferred]) -> R) -> R {
    STACK.with_borrow_mut(|stack| query(stack))
}

/// The far slab distance is scaled up by 1 + 2·gamma(3) to cover the rounding of both slab
/// distances (Ize, "Robust BVH Ray Traversal", JCGT 2(2), 2013), so a ray through a box's
/// face or edge is never culled, and triangles lying in that face stay watertight.
pub(super) const FAR_SCALE: f32 = 1.0 + 2.0 * gamma(3);

/// A ray prepared for slab tests.
#[derive(Clone, Copy, Debug)]
pub(super) struct BoxRay {
    origin: Vec3A,
    /// 1/dir with IEEE infinities for zero components (of the zero's sign).
    inv_dir: Vec3A,
    /// Whether each direction component is negative, so the near plane is the box's max.
    neg: BVec3A,
}

impl BoxRay {
    pub fn new(ray: &Ray) -> Self {
        let inv_dir = Vec3A::from(ray.dir).recip();
        Self {
            origin: ray.origin.into(),
            inv_dir,
            neg: inv_dir.cmplt(Vec3A::ZERO),
        }
    }

    /// Distance at which the ray enters `node`'s box, if it does so within `[0, t_max]`.
    /// (Static queries run eight-wide; this is their reference in tests.)
    #[cfg(test)]
    pub fn entry(&self, node: &Node, t_max: f32) -> Option<f32> {
        self.entry_box(node.min, node.max, t_max)
    }

    /// Distance at which the ray enters the box `[min, max]`, if it does so within
    /// `[0, t_max]`.
    #[inline(always)]
    pub fn entry_box(&self, min: Vec3, max: Vec3, t_max: f32) -> Option<f32> {
        // In SIMD lanes (Vec3A): the same IEEE operations per axis as three scalar ones.
        let lo = (Vec3A::from(min) - self.origin) * self.inv_dir;
        let hi = (Vec3A::from(max) - self.origin) * self.inv_dir;
        let near = Vec3A::select(self.neg, hi, lo);
        let far = Vec3A::select(self.neg, lo, hi);
        // 0 · inf = NaN arises when the ray lies in a slab's plane; such an axis must not
        // constrain the interval (Ize 2013). `max_or_acc`/`min_or_acc` keep the accumulator
        // when the candidate is NaN, and compile to single maxss/minss instructions, where
        // f32::max/min need four each to implement IEEE maxNum. (Lane-wise max/min and a
        // horizontal reduction, with NaN lanes masked first, took 5% more instructions.)
        let t0 = max_or_acc(max_or_acc(max_or_acc(0.0, near.x), near.y), near.z);
        let far = far * FAR_SCALE;
        let t1 = min_or_acc(min_or_acc(min_or_acc(t_max, far.x), far.y), far.z);
        (t0 <= t1).then_some(t0)
    }
}

/// `max(acc, x)`, keeping `acc` when `x` is NaN.
#[inline(always)]
fn max_or_acc(acc: f32, x: f32) -> f32 {
    if x > acc {
        x
    } else {
        acc
    }
}

/// `min(acc, x)`, keeping `acc` when `x` is NaN.
#[inline(always)]
fn min_or_acc(acc: f32, x: f32) -> f32 {
    if x < acc {
        x
    } else {
        acc
    }
}

/// Whether the ray's numbers allow any hit at all; a ray with a zero, infinite or NaN
/// direction, a non-finite origin or a non-positive `t_max` hits nothing.
#[inline(always)]
pub(super) fn ray_is_valid(ray: &Ray, t_max: f32) -> bool {
    // In SIMD lanes, one test for all six numbers: `x · 0` is ±0 for a finite `x` and NaN
    // for an infinity or a NaN. (Six scalar tests came to about 25 instructions, and every
    // ray takes this at the top level and in each instance it enters.)
    let (origin, dir) = (lanes_of(&ray.origin), lanes_of(&ray.dir));
    let finite = (origin * 0.0 + dir * 0.0).cmpeq(Vec3A::ZERO).all();
    finite && dir.cmpne(Vec3A::ZERO).any() && t_max > 0.0
}

/// `v` in SIMD lanes, read one number at a time. A query's ray was written just before
/// the call, often in stores of two numbers and one, and a load that spans two stores
/// waits for both to reach the cache (the CPU forwards a load from one store only): the
/// merged load LLVM makes of `Vec3A::from` cost a dozen cycles at every query.
#[inline(always)]
fn lanes_of(v: &Vec3) -> Vec3A {
    // Volatile only so that the three reads are not merged into wider ones.
    // SAFETY: each pointer comes from a reference to an `f32`.
    unsafe {
        Vec3A::new(
            std::ptr::read_volatile(&v.x),
            std::ptr::read_volatile(&v.y),
            std::ptr::read_volatile(&v.z),
        )
    }
}

/// Where traversal finds a node's box: in the node itself (`StaticBoxes`, in tests), or
/// interpolated at the ray's time from per-step boxes ([`MotionBoxes`]).
pub(super) trait NodeBoxes {
    /// Distance at which `ray` enters the box of `node` (number `index` in its array), if
    /// it does so within `[0, t_max]`.
    fn entry(&self, ray: &BoxRay, node: &Node, index: usize, t_max: f32) -> Option<f32>;
}

/// The node's own box: the reference for the eight-wide traversal in tests.
#[cfg(test)]
pub(super) struct StaticBoxes;

#[cfg(test)]
impl NodeBoxes for StaticBoxes {
    #[inline(always)]
    fn entry(&self, ray: &BoxRay, node: &Node, _: usize, t_max: f32) -> Option<f32> {
        ray.entry(node, t_max)
    }
}

/// A node's box at one motion step (24 bytes).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct StepBox {
    pub min: Vec3,
    pub max: Vec3,
}

/// Boxes of a motion BVH at one time: node `i`'s box at step `s` is `boxes[i·steps + s]`
/// (node-major, so the two steps a ray needs are adjacent, and so are a sibling pair's),
/// and the box at the ray's time is the lerp of the two bracketing steps' boxes.
///
/// That box is conservative: between two steps every vertex moves linearly, so at weight
/// `w1` a vertex is `lerp(v_k, v_k+1)`, and `box_k ∋ v_k`, `box_k+1 ∋ v_k+1` give
/// `lerp(box_k) ∋ lerp(v)`, also after rounding since [`Segment::lerp`] rounds
/// monotonically and the triangle test interpolates vertices with the same weights. A
/// parent's per-step boxes hold its children's, hence so do their lerps.
pub(super) struct MotionBoxes<'a> {
    pub boxes: &'a [StepBox],
    pub steps: usize,
    pub segment: Segment,
}

impl NodeBoxes for MotionBoxes<'_> {
    #[inline(always)]
    fn entry(&self, ray: &BoxRay, _: &Node, index: usize, t_max: f32) -> Option<f32> {
        let i = index * self.steps + self.segment.index;
        let (a, b) = (&self.boxes[i], &self.boxes[i + 1]);
        let min = self.segment.lerp(a.min, b.min);
        let max = self.segment.lerp(a.max, b.max);
        ray.entry_box(min, max, t_max)
    }
}

/// Visits the leaves whose boxes (as `boxes` sees them) the ray enters before `t_max`,
/// nearest child first.
///
/// `leaf(start, count, t_max, stack)` handles one leaf and may lower `t_max` (a closer
/// hit); it returns true to stop the traversal (an any-hit query that found one). Deferred
/// subtrees go on `stack` from its start; a leaf gets the part of it above them, for a
/// traversal of its own (the instance level's leaves search meshes).
#[inline(always)]
pub(super) fn traverse(
    nodes: &[Node],
    boxes: &impl NodeBoxes,
    ray: &BoxRay,
    t_max: &mut f32,
    stack: &mut [Deferred],
    mut leaf: impl FnMut(u32, u32, &mut f32, &mut [Deferred]) -> bool,
) {
    let Some(root) = nodes.first() else { return };
    if boxes.entry(ray, root, 0, *t_max).is_none() {
        return;
    }
    // Entries `..len` of `stack` are this traversal's; a leaf gets the rest.
    let mut len = 0;
    let mut node = root;
    loop {
        if node.count > 0 {
            if leaf(node.start, node.count, t_max, &mut stack[len..]) {
                return;
            }
        } else {
            let l = node.start as usize;
            let (left, right) = (&nodes[l], &nodes[l + 1]);
            match (
                boxes.entry(ray, left, l, *t_max),
                boxes.entry(ray, right, l + 1, *t_max),
            ) {
                (Some(dl), Some(dr)) => {
                    // Visit the nearer child now, the farther one later (if still worth it).
                    let (near, far, d_far) = if dl <= dr {
                        (left, l + 1, dr)
                    } else {
                        (right, l, dl)
                    };
                    stack[len] = (far as u32, d_far);
                    len += 1;
                    node = near;
                    continue;
                }
                (Some(_), None) => {
                    node = left;
                    continue;
                }
                (None, Some(_)) => {
                    node = right;
                    continue;
                }
                (None, None) => {}
            }
        }
        // Pop the next deferred subtree that a closer hit has not ruled out.
        loop {
            if len == 0 {
                return;
            }
            len -= 1;
            let (idx, d) = stack[len];
            if d <= *t_max {
                node = &nodes[idx as usize];
                break;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn node(min: Vec3, max: Vec3) -> Node {
        Node {
            min,
            start: 0,
            max,
            count: 1,
        }
    }

    #[test]
    fn node_is_32_bytes() {
        assert_eq!(std::mem::size_of::<Node>(), 32);
        assert_eq!(std::mem::align_of::<Node>(), 32);
    }

    #[test]
    fn slab_test_enters_and_misses() {
        let n = node(Vec3::splat(1.0), Vec3::splat(2.0));
        let r = BoxRay::new(&Ray::new(Vec3::ZERO, Vec3::ONE));
        assert_eq!(r.entry(&n, f32::INFINITY), Some(1.0));
        assert_eq!(r.entry(&n, 0.5), None);
        let behind = BoxRay::new(&Ray::new(Vec3::splat(3.0), Vec3::ONE));
        assert_eq!(behind.entry(&n, f32::INFINITY), None);
        // Origin inside: entry at 0.
        let inside = BoxRay::new(&Ray::new(Vec3::splat(1.5), -Vec3::ONE));
        assert_eq!(inside.entry(&n, f32::INFINITY), Some(0.0));
    }

    #[test]
    fn axis_parallel_rays_in_a_face_plane_are_not_culled() {
        // The ray runs inside the plane x = 1 of the box's face (0 · inf = NaN on x).
        let n = node(Vec3::new(1.0, 0.0, 0.0), Vec3::new(2.0, 1.0, 1.0));
        for (o, d) in [
            (Vec3::new(1.0, 0.5, -1.0), Vec3::Z),
            (Vec3::new(2.0, 0.5, -1.0), Vec3::Z),
            (Vec3::new(1.0, 0.5, 3.0), Vec3::new(-0.0, 0.0, -1.0)),
        ] {
            assert!(
                BoxRay::new(&Ray::new(o, d))
                    .entry(&n, f32::INFINITY)
                    .is_some(),
                "{o} {d}"
            );
        }
        // A flat box (a face of a cube) hit head on, and a ray beside it.
        let flat = node(Vec3::new(0.0, 0.0, 1.0), Vec3::new(1.0, 1.0, 1.0));
        let r = BoxRay::new(&Ray::new(Vec3::new(1.0, 1.0, 0.0), Vec3::Z));
        assert_eq!(r.entry(&flat, f32::INFINITY), Some(1.0));
        let r = BoxRay::new(&Ray::new(Vec3::new(1.5, 1.0, 0.0), Vec3::Z));
        assert_eq!(r.entry(&flat, f32::INFINITY), None);
    }

    #[test]
    fn rays_are_valid_exactly_when_every_number_allows_a_hit() {
        let values = [
            0.0,
            -0.0,
            1.0,
            -3.5,
            f32::MAX,
            f32::MIN_POSITIVE,
            f32::from_bits(1),
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NAN,
        ];
        let scalar =
            |o: Vec3, d: Vec3, t: f32| o.is_finite() && d.is_finite() && d != Vec3::ZERO && t > 0.0;
        let mut valid = 0;
        for (i, &a) in values.iter().enumerate() {
            for &b in &values {
                // Each value in each place of the origin and the direction, against
                // ordinary numbers elsewhere, and every t_max.
                for k in 0..3 {
                    let mut v = [0.5f32; 3];
                    v[k] = a;
                    let w = Vec3::from(v);
                    for (o, d) in [(w, Vec3::new(0.0, b, 1.0)), (Vec3::new(b, 1.0, 2.0), w)] {
                        let t = values[(i + k) % values.len()];
                        let ray = Ray::new(o, d);
                        assert_eq!(ray_is_valid(&ray, t), scalar(o, d, t), "{o} {d} {t}");
                        valid += usize::from(scalar(o, d, t));
                    }
                }
            }
        }
        // Both answers occur.
        assert!(valid > 0 && valid < 2 * 3 * values.len() * values.len());
        assert!(!ray_is_valid(&Ray::new(Vec3::ONE, Vec3::ZERO), 1.0));
        assert!(!ray_is_valid(
            &Ray::new(Vec3::ONE, Vec3::new(-0.0, 0.0, -0.0)),
            1.0
        ));
    }
}

//! Instances (a mesh placed by a transform, possibly moving over the shutter) and the
//! top-level BVH over them.

use std::sync::Arc;

use glam::{Affine3A, DMat4, Mat3A, Vec3};

use super::build::{self, half_area, BuildParams, BuildPrim};
use super::huge_pages::on_huge_pages;
use super::mesh::{MeshBvh, Part};
use super::motion::MotionTransform;
use super::node::{ray_is_valid, with_stack};
use super::wide::{collapse, traverse_wide, Walk, WideNode, WideRay};
use crate::geometry::{Aabb, Hit, Ray};
#[cfg(target_arch = "x86_64")]
use crate::simd;
use crate::triangle::gamma;

/// SAH costs for instances: testing one means transforming the ray and entering a mesh
/// BVH, several box tests' worth, so SAH splits down to small leaves.
const PARAMS: BuildParams = BuildParams {
    max_leaf: 2,
    traversal_cost: 1.0,
    intersect_cost: 3.0,
};

/// One mesh placed in the prepared frame's world space, by one transform or by a
/// [`MotionTransform`] over the shutter.
///
/// Rays enter the mesh through [`Instance::object_ray`] (static) or the placement at the
/// ray's time (moving), which keep the direction's length as the transform makes it, so
/// `t` means the same point in both spaces. A moving instance's `bounds` cover the whole
/// shutter, so the top level stays a static BVH; its matrices are those at time 0, and
/// [`Instance::placement`] gives them at any time. Cloning is cheap: the motion is shared.
#[derive(Clone, Debug, PartialEq)]
pub struct Instance {
    /// Index of the mesh in the scene's mesh list.
    pub mesh: u32,
    /// Object space to world space (at time 0 for a moving instance).
    pub to_world: Affine3A,
    /// World space to object space; all zeros when `to_world` is singular.
    pub to_object: Affine3A,
    /// Inverse transpose of `to_world`'s linear part, for normals (not normalised: scale
    /// the result). All zeros when `to_world` is singular.
    pub normal_to_world: Mat3A,
    /// World-space bounds (over the whole shutter), padded for the rounding of the
    /// transform; empty when the instance can never be hit.
    pub bounds: Aabb,
    /// The transform over the shutter; None for a static instance.
    pub motion: Option<Arc<MotionTransform>>,
    /// Whether the instance is static and `to_world` only translates (a glTF node without
    /// a rotation or scale, as most are, in the frame's camera-relative space): a ray then
    /// enters the mesh by adding to its origin alone, not through a matrix.
    pub translated: bool,
}

/// An instance's matrices at one time: what shading a hit needs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Placement {
    /// Object space to world space.
    pub to_world: Affine3A,
    /// World space to object space; all zeros when `to_world` is singular.
    pub to_object: Affine3A,
    /// Inverse transpose of `to_world`'s linear part, for normals (not normalised); all
    /// zeros when `to_world` is singular.
    pub normal_to_world: Mat3A,
}

impl Placement {
    /// The matrices for `to_world`; zero inverses when it cannot be inverted (a zero
    /// scale, a non-finite entry, or one so small that the inverse overflows).
    fn new(to_world: Affine3A) -> Placement {
        let det = to_world.matrix3.determinant();
        let to_object = if to_world.is_finite() && det != 0.0 && det.is_finite() {
            Some(to_world.inverse()).filter(|inv| inv.is_finite())
        } else {
            None
        };
        match to_object {
            Some(to_object) => Placement {
                to_world,
                to_object,
                normal_to_world: to_object.matrix3.transpose(),
            },
            None => Placement {
                to_world,
                to_object: Affine3A::ZERO,
                normal_to_world: Mat3A::ZERO,
            },
        }
    }

    fn is_singular(&self) -> bool {
        self.to_object == Affine3A::ZERO
    }

    /// The world ray in object space (the direction transformed, not renormalised).
    #[inline(always)]
    pub fn object_ray(&self, ray: &Ray) -> Ray {
        transform_ray(&self.to_object, ray)
    }
}

/// The f32 affine transform of a (camera-relative, f64) matrix, as static instances use.
fn to_f32_affine(m: &DMat4) -> Affine3A {
    Affine3A::from_mat4(m.as_mat4())
}

impl Instance {
    /// Places mesh `mesh`, whose object-space bounds are `mesh_bounds`, with `to_world`.
    ///
    /// A `to_world` that cannot be inverted (a zero scale, a non-finite entry, or one so
    /// small that the inverse overflows) gives an instance with empty bounds and zero
    /// inverse matrices: it is never hit, and nothing derived from it is NaN.
    pub fn new(mesh: u32, to_world: Affine3A, mesh_bounds: &Aabb) -> Instance {
        let p = Placement::new(to_world);
        let bounds = if p.is_singular() {
            Aabb::EMPTY
        } else {
            transform_bounds(&to_world, mesh_bounds)
        };
        Instance {
            mesh,
            to_world,
            to_object: p.to_object,
            normal_to_world: p.normal_to_world,
            bounds,
            motion: None,
            translated: to_world.matrix3 == Mat3A::IDENTITY,
        }
    }

    /// Places mesh `mesh` by `steps`, camera-relative world matrices at evenly spaced
    /// motion steps over the shutter (see [`MotionTransform`]).
    ///
    /// When every step converts to the same f32 transform, bit for bit, this is the static
    /// [`Instance::new`]; so it is when a step is not finite (then never hit, as a singular
    /// static instance). Otherwise the instance moves: its matrices are those at time 0
    /// and its bounds cover the mesh along the interpolated motion, rotation arcs included
    /// (see `MotionTransform::bounds` for why they are conservative). Steps that are
    /// singular at some times are fine: at those times the instance is not hit.
    ///
    /// # Panics
    /// If `steps` is empty.
    pub fn moving(mesh: u32, steps: &[DMat4], mesh_bounds: &Aabb) -> Instance {
        assert!(
            !steps.is_empty(),
            "a moving instance needs at least one step"
        );
        let first = to_f32_affine(&steps[0]);
        let bits = |m: &Affine3A| m.to_cols_array().map(f32::to_bits);
        let same = steps[1..]
            .iter()
            .all(|m| bits(&to_f32_affine(m)) == bits(&first));
        if same {
            return Instance::new(mesh, first, mesh_bounds);
        }
        if let Some(bad) = steps.iter().map(to_f32_affine).find(|m| !m.is_finite()) {
            return Instance::new(mesh, bad, mesh_bounds);
        }
        let motion = MotionTransform::new(steps);
        let p = Placement::new(motion.at(0.0));
        Instance {
            mesh,
            to_world: p.to_world,
            to_object: p.to_object,
            normal_to_world: p.normal_to_world,
            bounds: motion.bounds(mesh_bounds),
            motion: Some(Arc::new(motion)),
            translated: false,
        }
    }

    /// Whether any ray can hit this instance.
    pub fn is_hittable(&self) -> bool {
        !self.bounds.is_empty()
    }

    /// Whether the instance moves over the shutter.
    pub fn has_motion(&self) -> bool {
        self.motion.is_some()
    }

    /// The matrices at normalised shutter time `time`: the stored ones for a static
    /// instance, the interpolated ones for a moving instance (zero inverses at a time where
    /// it is singular).
    #[inline]
    pub fn placement(&self, time: f32) -> Placement {
        match &self.motion {
            None => Placement {
                to_world: self.to_world,
                to_object: self.to_object,
                normal_to_world: self.normal_to_world,
            },
            Some(motion) => Placement::new(motion.at(time)),
        }
    }

    /// Object space to world space at normalised shutter time `time`: the stored matrix
    /// for a static instance, the interpolated one for a moving instance. The part of
    /// [`Self::placement`] that makes no inverse, for what only places points.
    #[inline]
    pub fn to_world_at(&self, time: f32) -> Affine3A {
        match &self.motion {
            None => self.to_world,
            Some(motion) => motion.at(time),
        }
    }

    /// The world ray in the mesh's object space, by the stored `to_object` (time 0 for a
    /// moving instance). The direction is transformed but not renormalised, so ray
    /// parameters agree between the two spaces.
    pub fn object_ray(&self, ray: &Ray) -> Ray {
        if self.translated {
            // What the matrix gives, but for the sign of a zero component.
            return Ray {
                origin: ray.origin + Vec3::from(self.to_object.translation),
                ..*ray
            };
        }
        transform_ray(&self.to_object, ray)
    }

    /// The world ray in the mesh's object space where the instance is at `ray.time`.
    #[inline]
    fn object_ray_at_time(&self, ray: &Ray) -> Ray {
        match &self.motion {
            None => self.object_ray(ray),
            // Only the inverse is needed here; a singular time gives a zero direction,
            // which hits nothing.
            Some(motion) => Placement::new(motion.at(ray.time)).object_ray(ray),
        }
    }
}

#[inline(always)]
fn transform_ray(to_object: &Affine3A, ray: &Ray) -> Ray {
    Ray {
        origin: to_object.transform_point3(ray.origin),
        dir: to_object.transform_vector3(ray.dir),
        time: ray.time,
    }
}

/// World bounds of an object-space box: its eight corners transformed, each widened by a
/// bound on the rounding of `m·p + t` (three products and three sums: gamma(3), taken as
/// gamma(4) to cover the rounding of the bound itself), so that no world-space point of
/// the mesh can fall outside the box the top level tests.
pub(super) fn transform_bounds(m: &Affine3A, b: &Aabb) -> Aabb {
    if b.is_empty() {
        return Aabb::EMPTY;
    }
    let abs_m = m.matrix3.abs();
    let abs_t = Vec3::from(m.translation.abs());
    let mut out = Aabb::EMPTY;
    for c in b.corners() {
        let p = m.transform_point3(c);
        let err = (abs_m.mul_vec3(c.abs()) + abs_t) * gamma(4);
        out.grow(p - err);
        out.grow(p + err);
    }
    out
}

/// A leaf entry of the top level: an instance's mesh, whole or one lane of its root.
#[derive(Clone, Copy, Debug)]
struct Entry {
    instance: u32,
    part: Part,
}

/// The most instances the top level opens (see [`opened`]).
const OPEN_AT_MOST: usize = 16;

/// The instances whose meshes the top level lists by their root's lanes instead of whole:
/// of the [`OPEN_AT_MOST`] largest static ones (by the area of their world boxes), those
/// whose box holds the centre of a smaller instance's box. A mesh around others (the walls
/// of a room around its furniture) is entered by every ray that enters them, and by every
/// ray that starts inside it, whether or not the ray comes near a wall; its lanes' boxes,
/// a wall each, are entered only by the rays that reach them. (A piece of furniture whose
/// box holds the room's centre is not opened: a ray that hits it would enter several of
/// its faces, each an entry of its own.) Sorted.
fn opened<'m>(instances: &[Instance], mesh: &impl Fn(u32) -> &'m MeshBvh) -> Vec<u32> {
    let hittable = || (0..instances.len()).filter(|&i| instances[i].is_hittable());
    let area = |i: usize| {
        let b = instances[i].bounds;
        half_area(b.min.into(), b.max.into())
    };
    // (area, index), largest first: chosen in linear time, for scenes of millions.
    let mut largest: Vec<(f32, usize)> = hittable()
        .filter(|&i| !instances[i].has_motion() && !mesh(instances[i].mesh).has_motion())
        .map(|i| (area(i), i))
        .collect();
    let larger = |a: &(f32, usize), b: &(f32, usize)| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1));
    if largest.len() > OPEN_AT_MOST {
        largest.select_nth_unstable_by(OPEN_AT_MOST, larger);
        largest.truncate(OPEN_AT_MOST);
    }
    let mut opened: Vec<u32> = largest
        .into_iter()
        .filter(|&(size, i)| {
            let b = instances[i].bounds;
            hittable().any(|j| {
                let c = instances[j].bounds.center();
                area(j) < size && c.cmpge(b.min).all() && c.cmple(b.max).all()
            })
        })
        .map(|(_, i)| i as u32)
        .collect();
    opened.sort_unstable();
    opened
}

/// The top-level BVH over a prepared frame's instances, built with a binned SAH over
/// their world bounds (over the whole shutter for moving ones). Hits name instances by
/// their index in the list given to [`SceneBvh::build`], which [`SceneBvh::instances`]
/// returns unchanged.
///
/// Whether anything moves is decided once, at build time ([`SceneBvh::has_motion`]); each
/// query then runs one of two monomorphised loops, so a static scene's traversal is the
/// same loop as without motion support.
#[derive(Clone, Default)]
pub struct SceneBvh {
    instances: Vec<Instance>,
    /// The eight-wide tree over the instances' bounds.
    nodes: Vec<WideNode>,
    /// What the tree's leaves hold, in leaf order: instances, and parts of opened ones.
    entries: Vec<Entry>,
    /// Whether an instance moves or a mesh it places deforms.
    motion: bool,
    /// Whether an entry is a part of an instance's mesh (an instance was opened).
    opened: bool,
}

impl std::fmt::Debug for SceneBvh {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SceneBvh")
            .field("instances", &self.instances.len())
            .field("nodes", &self.nodes.len())
            .field("motion", &self.motion)
            .field("bounds", &self.bounds())
            .finish()
    }
}

impl SceneBvh {
    /// Builds the hierarchy over `instances`; `mesh(i)` is the BVH of mesh `i` (a lookup,
    /// so that static and per-frame deformed meshes can be mixed), asked only whether it
    /// deforms. Instances that cannot be hit (empty bounds) stay in the list but not in the
    /// tree.
    ///
    /// # Panics
    /// If there are more than `u32::MAX` instances.
    pub fn build<'m>(instances: Vec<Instance>, mesh: impl Fn(u32) -> &'m MeshBvh) -> SceneBvh {
        assert!(
            u32::try_from(instances.len()).is_ok(),
            "more than 2^32 - 1 instances"
        );
        let motion = instances
            .iter()
            .any(|inst| inst.has_motion() || mesh(inst.mesh).has_motion());
        let opened = opened(&instances, &mesh);
        let mut entries = Vec::new();
        let mut boxes = Vec::new();
        for (i, inst) in instances.iter().enumerate() {
            if !inst.is_hittable() {
                continue;
            }
            let instance = i as u32;
            if opened.contains(&instance) {
                for (bounds, part) in mesh(inst.mesh).root_parts() {
                    entries.push(Entry { instance, part });
                    boxes.push(transform_bounds(&inst.to_world, &bounds));
                }
            } else {
                entries.push(Entry {
                    instance,
                    part: Part::Whole,
                });
                boxes.push(inst.bounds);
            }
        }
        // Bounds that overflowed to infinity are clamped so that centroids stay finite.
        let limit = Vec3::splat(f32::MAX);
        let mut prims: Vec<BuildPrim> = boxes
            .iter()
            .enumerate()
            .map(|(i, b)| BuildPrim {
                min: b.min.clamp(-limit, limit),
                max: b.max.clamp(-limit, limit),
                index: i as u32,
            })
            .collect();
        let nodes = collapse(&build::build(&mut prims, &PARAMS), None);
        let entries = prims.iter().map(|p| entries[p.index as usize]).collect();
        SceneBvh {
            instances: on_huge_pages(instances),
            nodes: on_huge_pages(nodes),
            entries: on_huge_pages(entries),
            motion,
            opened: !opened.is_empty(),
        }
    }

    /// The instances, in the order given to [`SceneBvh::build`].
    pub fn instances(&self) -> &[Instance] {
        &self.instances
    }

    /// Whether any instance moves or any mesh it places deforms over the shutter: then
    /// queries interpolate at `ray.time`.
    pub fn has_motion(&self) -> bool {
        self.motion
    }

    /// World bounds of every hittable instance (over the whole shutter); empty when there
    /// is none.
    pub fn bounds(&self) -> Aabb {
        self.nodes.first().map_or(Aabb::EMPTY, WideNode::bounds)
    }

    /// Number of top-level nodes.
    pub fn node_count(&self) -> usize {
        self.nodes.len()
    }

    /// Bytes held by the top level (not counting the meshes' BVHs, nor motion transforms
    /// shared with other copies of the instances).
    pub fn memory_bytes(&self) -> usize {
        std::mem::size_of::<Self>()
            + std::mem::size_of_val(self.instances.as_slice())
            + std::mem::size_of_val(self.nodes.as_slice())
            + std::mem::size_of_val(self.entries.as_slice())
    }

    /// Closest hit with `0 < t < t_max` for which `accept(instance, triangle, b1, b2)` is
    /// true, with everything where it is at `ray.time`. `mesh(i)` is the BVH of mesh `i`
    /// (the one given to [`SceneBvh::build`]); `ray.dir` need not be unit length and `t` is
    /// in its units. A rejected hit (an alpha cut-out) is ignored and the search goes on.
    pub fn intersect<'m>(
        &self,
        mesh: impl Fn(u32) -> &'m MeshBvh,
        ray: &Ray,
        t_max: f32,
        accept: impl FnMut(u32, u32, f32, f32) -> bool,
    ) -> Option<Hit> {
        // SAFETY: without `AVX`, nothing is asked of the CPU.
        unsafe { self.query::<false, false, _>(mesh, ray, t_max, accept) }
    }

    /// Whether anything with `0 < t < t_max` accepted by `accept(instance, triangle, b1,
    /// b2)` lies on the ray at `ray.time`; stops at the first such hit (shadow rays).
    pub fn occluded<'m>(
        &self,
        mesh: impl Fn(u32) -> &'m MeshBvh,
        ray: &Ray,
        t_max: f32,
        accept: impl FnMut(u32, u32, f32, f32) -> bool,
    ) -> bool {
        // SAFETY: as in `intersect`.
        unsafe { self.query::<true, false, _>(mesh, ray, t_max, accept) }.is_some()
    }

    /// [`Self::intersect`] (`ANY_HIT` false) or [`Self::occluded`] (true: any hit found),
    /// by the search with or without motion, and with or without opened instances, as the
    /// scene needs (each its own loop: a scene pays for neither unless it has it). With
    /// `AVX`, for a caller compiled for AVX (`PreparedFrame::query_avx`, which the path
    /// loop's AVX copy calls once per ray): nodes are tested in AVX lanes without asking for
    /// the CPU's features again. Without, by the node test this process uses (see
    /// `simd.rs`).
    ///
    /// # Safety
    /// With `AVX`, the CPU must have AVX ([`simd::avx`] says so).
    #[inline(always)]
    pub(crate) unsafe fn query<
        'm,
        const ANY_HIT: bool,
        const AVX: bool,
        M: Fn(u32) -> &'m MeshBvh,
    >(
        &self,
        mesh: M,
        ray: &Ray,
        t_max: f32,
        accept: impl FnMut(u32, u32, f32, f32) -> bool,
    ) -> Option<Hit> {
        match (self.motion, self.opened) {
            (false, false) => {
                self.search::<ANY_HIT, false, false, AVX, M>(mesh, ray, t_max, accept)
            }
            (false, true) => self.search::<ANY_HIT, false, true, AVX, M>(mesh, ray, t_max, accept),
            (true, false) => self.search::<ANY_HIT, true, false, AVX, M>(mesh, ray, t_max, accept),
            (true, true) => self.search::<ANY_HIT, true, true, AVX, M>(mesh, ray, t_max, accept),
        }
    }

    /// [`Self::search_with`] in AVX lanes where the CPU has them (with `AVX` the caller has
    /// checked, see [`Self::query`]), else with the node test this process uses (see
    /// `simd.rs`).
    #[inline(always)]
    fn search<
        'm,
        const ANY_HIT: bool,
        const MOTION: bool,
        const OPENED: bool,
        const AVX: bool,
        M: Fn(u32) -> &'m MeshBvh,
    >(
        &self,
        mesh: M,
        ray: &Ray,
        t_max: f32,
        accept: impl FnMut(u32, u32, f32, f32) -> bool,
    ) -> Option<Hit> {
        #[cfg(target_arch = "x86_64")]
        if AVX || simd::avx() {
            // SAFETY: the CPU has AVX: `simd::avx` says so, and `AVX` is true only where it
            // does.
            return unsafe {
                self.search_avx::<ANY_HIT, MOTION, OPENED, M>(mesh, ray, t_max, accept)
            };
        }
        self.search_with::<ANY_HIT, MOTION, OPENED, false, M>(mesh, ray, t_max, accept)
    }

    /// [`Self::search_with`] in AVX lanes, a function of its own for each kind of search and
    /// hit filter. Inlined into one caller (`PreparedFrame::query_avx` held all eight), each
    /// query set up registers and stack for every kind: 0.4% more instructions on the
    /// Cornell box, 0.7% more on the animated demo with motion blur.
    ///
    /// # Safety
    /// The CPU must have AVX ([`simd::avx`] says so).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx")]
    #[inline(never)]
    unsafe fn search_avx<
        'm,
        const ANY_HIT: bool,
        const MOTION: bool,
        const OPENED: bool,
        M: Fn(u32) -> &'m MeshBvh,
    >(
        &self,
        mesh: M,
        ray: &Ray,
        t_max: f32,
        accept: impl FnMut(u32, u32, f32, f32) -> bool,
    ) -> Option<Hit> {
        self.search_with::<ANY_HIT, MOTION, OPENED, true, M>(mesh, ray, t_max, accept)
    }

    /// The closest accepted hit, or with `ANY_HIT` the first one found. With `MOTION`,
    /// moving instances are placed and deforming meshes interpolated at `ray.time`; the
    /// top level's boxes cover the shutter either way. With `OPENED`, entries may be parts
    /// of an instance's mesh (see [`opened`]); without, every entry is a whole mesh. With
    /// `AVX` (only in [`Self::search_avx`]), nodes are tested in AVX lanes at both
    /// levels.
    #[inline(always)]
    fn search_with<
        'm,
        const ANY_HIT: bool,
        const MOTION: bool,
        const OPENED: bool,
        const AVX: bool,
        M: Fn(u32) -> &'m MeshBvh,
    >(
        &self,
        mesh: M,
        ray: &Ray,
        t_max: f32,
        mut accept: impl FnMut(u32, u32, f32, f32) -> bool,
    ) -> Option<Hit> {
        if !ray_is_valid(ray, t_max) {
            return None;
        }
        let mut t_max = t_max;
        let mut best = None;
        with_stack(|stack| {
            traverse_wide::<AVX>(
                &self.nodes,
                &WideRay::new(ray),
                &mut t_max,
                stack,
                Walk {
                    root_lane: None,
                    nearest_first: !ANY_HIT,
                },
                |_, _| {},
                |start, count, t_max, stack| {
                    for entry in &self.entries[start as usize..(start + count) as usize] {
                        let instance = entry.instance;
                        let inst = &self.instances[instance as usize];
                        let bvh = mesh(inst.mesh);
                        let object_ray = if MOTION {
                            inst.object_ray_at_time(ray)
                        } else {
                            inst.object_ray(ray)
                        };
                        let hit = bvh.search_with::<ANY_HIT, MOTION, AVX>(
                            &object_ray,
                            *t_max,
                            stack,
                            if OPENED { entry.part } else { Part::Whole },
                            |tri, b1, b2| accept(instance, tri, b1, b2),
                        );
                        if let Some((t, triangle, b1, b2)) = hit {
                            *t_max = t;
                            best = Some(Hit {
                                t,
                                instance,
                                triangle,
                                b1,
                                b2,
                            });
                            if ANY_HIT {
                                return true;
                            }
                        }
                    }
                    false
                },
            )
        });
        best
    }
}

#[cfg(test)]
mod tests;

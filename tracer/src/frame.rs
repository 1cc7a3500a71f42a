//! A scene prepared for one frame ([`PreparedFrame`], made by
//! [`prepare_frame`](crate::prepare::prepare_frame)) and its ray queries: the closest hit,
//! occlusion, and the triangle a hit landed on at the ray's time.

use std::sync::Arc;

use glam::{Affine3A, DVec3, Mat3A, Vec3, Vec4};

use crate::bvh::{Instance, MeshBvh, Placement, SceneBvh};
use crate::camera::{Camera, ShutterEnd};
use crate::geometry::{barycentric, hit_point_error, translated_hit_point_error, Hit, Ray};
use crate::light::LightSet;
use crate::material::{AlphaMode, Material};
use crate::math;
use crate::motion::DeformedMesh;
use crate::sampler::hash_combine;
use crate::scene::{Features, Mesh, Primitive, Scene};
use crate::spectrum::{DenseSpectrum, Fluorescence};

/// A scene flattened for one frame: instances in camera-relative world space, their BVH,
/// the camera and the lights.
pub struct PreparedFrame {
    /// The scene (meshes, materials and textures are shared, not copied).
    pub scene: Arc<Scene>,
    /// Frame number (it keys the random numbers).
    pub frame: i32,
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// The camera, at the origin of the prepared space.
    pub camera: Camera,
    /// Where the camera sits in the scene's world space.
    pub camera_origin: DVec3,
    /// Top-level BVH over the instances. An instance's `mesh` below the scene's mesh count
    /// names a scene mesh; above it, an entry of `deformed`.
    pub bvh: SceneBvh,
    /// Meshes that skinning or morphing deforms in this frame.
    pub deformed: Vec<DeformedMesh>,
    /// Motion steps over the shutter (1: the static path).
    pub motion_steps: u32,
    /// Whether anything (camera or geometry) moves inside the shutter, so rays need times.
    pub motion: bool,
    /// Lights for next-event estimation.
    pub lights: LightSet,
    /// Per scene mesh, per primitive: whether a hit must be checked by [`PreparedFrame::accepts`]
    /// (alpha cut-outs, single-sided back faces). Meshes that need none pay nothing.
    pub(crate) hit_filter: Vec<Vec<bool>>,
    /// Per instance, whether its mesh has a primitive that needs the hit filter: a hit on
    /// any other instance is accepted without looking its triangle up.
    pub(crate) filtered_instances: Vec<bool>,
    /// Whether any instance needs the hit filter.
    pub(crate) any_hit_filter: bool,
    /// Per scene material, what the integrator reuses at every point that sees it.
    pub(crate) materials: Vec<PreparedMaterial>,
    /// The spectra of lights and emissive materials that have their own
    /// (TESSERA_lights_spectrum), scaled as [`DenseSpectrum::light`] says.
    pub(crate) light_spectra: Vec<DenseSpectrum>,
    /// The fluorescent paints of the materials that have one.
    pub(crate) fluorescence: Vec<Fluorescence>,
    /// What the frame uses.
    pub features: Features,
    /// Remarks for the user (for example, the default environment was used).
    pub warnings: Vec<String>,
}

/// A scene material with what does not change from point to point.
pub(crate) struct PreparedMaterial {
    /// The material at this frame's time (KHR_animation_pointer applied).
    pub material: Material,
    /// Its BSDF where every texture and the vertex colour are white (with the albedo
    /// curve of rough glass), so that points that see it so (most, in most scenes) need
    /// not build it again.
    pub bsdf: crate::bsdf::Bsdf,
    /// For a material without textures, its values at every point of a primitive
    /// without vertex colours: [`crate::material::Material::sample`] there, once.
    pub uniform: Option<crate::material::MaterialSample>,
    /// Its KHR_materials_dispersion where it refracts into a volume, else 0: the spectral
    /// path refracts each path at its hero wavelength's IOR.
    pub dispersion: f32,
    /// Its emission's spectrum (TESSERA_lights_spectrum), an index in
    /// [`PreparedFrame::light_spectra`].
    pub emission_spectrum: Option<u32>,
    /// Its fluorescent paint (TESSERA_materials_fluorescence), an index in
    /// [`PreparedFrame::fluorescence`].
    pub fluorescence: Option<u32>,
}

/// One triangle of an instance at a ray's time: where its data lives (its vertex
/// positions are in object space, world space for deformed meshes), and the instance's
/// transforms at that time.
pub(crate) struct TriangleAt<'a> {
    /// The primitive holding it (texture coordinates, colours, material).
    pub prim: &'a Primitive,
    /// Index of that primitive in its mesh.
    pub prim_index: usize,
    /// The triangle's index inside the primitive.
    pub t: usize,
    /// Its vertex indices.
    pub v: [usize; 3],
    /// The deformed mesh it belongs to, if any.
    pub deformed: Option<&'a DeformedMesh>,
    /// The instance.
    inst: &'a Instance,
    /// Its transforms at the ray's time when it moves, held by the caller; a still
    /// instance's are its own. (Borrowed, not held: a placement held here made the whole
    /// struct a copy on the stack at every hit.)
    moved: Option<&'a Placement>,
    /// The ray's shutter time.
    pub time: f32,
}

impl TriangleAt<'_> {
    /// Object space to world space.
    #[inline(always)]
    pub fn to_world(&self) -> &Affine3A {
        self.moved.map_or(&self.inst.to_world, |p| &p.to_world)
    }

    /// World space to object space.
    #[inline(always)]
    pub fn to_object(&self) -> &Affine3A {
        self.moved.map_or(&self.inst.to_object, |p| &p.to_object)
    }

    /// The normal matrix (inverse transpose of `to_world`'s linear part).
    #[inline(always)]
    pub fn normal_to_world(&self) -> &Mat3A {
        self.moved
            .map_or(&self.inst.normal_to_world, |p| &p.normal_to_world)
    }

    /// The world ray in object space (the direction as the transform makes it, not
    /// renormalised, so that `t` agrees between the spaces).
    #[inline(always)]
    pub fn object_ray(&self, ray: &Ray) -> Ray {
        match self.moved {
            None => self.inst.object_ray(ray),
            Some(p) => p.object_ray(ray),
        }
    }

    /// Object-space point `p`, known to within `error` per coordinate, in world space, and
    /// the bound on its error there ([`hit_point_error`]).
    #[inline(always)]
    pub fn world_point(&self, p: Vec3, error: Vec3) -> (Vec3, Vec3) {
        if self.inst.translated {
            let t = Vec3::from(self.inst.to_world.translation);
            return (p + t, translated_hit_point_error(t, p, error));
        }
        let m = self.to_world();
        (m.transform_point3(p), hit_point_error(m, p, error))
    }

    /// Vertex positions (object space), read where they are each time: held here, they
    /// were written to the stack and copied in wider loads than their stores, which the
    /// CPU cannot forward (a stall of a dozen cycles at every hit).
    #[inline(always)]
    pub fn positions(&self) -> [Vec3; 3] {
        match self.deformed {
            Some(d) => d.positions(self.prim_index, self.v, self.time),
            None => self.v_at(&self.prim.positions),
        }
    }

    /// The triangle's three entries of a per-vertex array (not `v.map`, whose array was
    /// built on the stack and copied, as above).
    #[inline(always)]
    fn v_at<T: Copy>(&self, of: &[T]) -> [T; 3] {
        [of[self.v[0]], of[self.v[1]], of[self.v[2]]]
    }

    /// Object-space geometric normal by the winding (not normalised), turned for the baked
    /// vertices of a mirrored node (a still instance's mirror is in its normal matrix).
    /// `positions` are [`Self::positions`], taken from a caller that needs them too: a
    /// deformed mesh's are interpolated over the shutter at each call.
    #[inline(always)]
    pub fn face_normal(&self, [a, b, c]: [Vec3; 3]) -> Vec3 {
        let n = (b - a).cross(c - a);
        if self.deformed.is_some_and(|d| d.mirrored) {
            -n
        } else {
            n
        }
    }

    /// World-space unit normal of the front face. The inverse transpose keeps the front
    /// face right for mirrored instances too (glTF flips the winding when the determinant
    /// is negative). Zero for a degenerate triangle. `positions` as for
    /// [`Self::face_normal`].
    #[inline(always)]
    pub fn front_normal(&self, positions: [Vec3; 3]) -> Vec3 {
        let n = self.face_normal(positions);
        if self.inst.translated {
            // The identity's product, but for the sign of a zero component.
            return math::normalize_or(n, Vec3::ZERO);
        }
        math::normalize_or(*self.normal_to_world() * n, Vec3::ZERO)
    }

    /// The object-space vertex normals interpolated at barycentrics `b1`, `b2` (not
    /// renormalised), or `None` when the primitive has none.
    #[inline(always)]
    pub fn normal_at(&self, b1: f32, b2: f32) -> Option<Vec3> {
        let deformed = |d: &DeformedMesh| d.normals(self.prim_index, self.v, self.time);
        self.interpolated(&self.prim.normals, deformed, b1, b2)
    }

    /// The object-space vertex tangents interpolated at barycentrics `b1`, `b2`, or
    /// `None` when the primitive has none.
    #[inline(always)]
    pub fn tangent_at(&self, b1: f32, b2: f32) -> Option<Vec4> {
        let deformed = |d: &DeformedMesh| d.tangents(self.prim_index, self.v, self.time);
        self.interpolated(&self.prim.tangents, deformed, b1, b2)
    }

    /// A per-vertex attribute (`of` in a still mesh, `deformed`'s in a deformed one)
    /// interpolated at barycentrics `b1`, `b2`; `None` when the primitive has none.
    /// Interpolated here, not returned as an array: an optional array was built on the
    /// stack and copied in wider loads than its stores.
    #[inline(always)]
    fn interpolated<T>(
        &self,
        of: &[T],
        deformed: impl FnOnce(&DeformedMesh) -> Option<[T; 3]>,
        b1: f32,
        b2: f32,
    ) -> Option<T>
    where
        T: Copy + core::ops::Mul<f32, Output = T> + core::ops::Add<Output = T>,
    {
        let [a, b, c] = match self.deformed {
            Some(d) => deformed(d)?,
            None if of.is_empty() => return None,
            None => self.v_at(of),
        };
        Some(barycentric(a, b, c, b1, b2))
    }
}

impl PreparedFrame {
    /// Scene material `index` as this frame sees it (animations applied).
    #[inline(always)]
    pub fn material(&self, index: u32) -> &Material {
        &self.materials[index as usize].material
    }

    /// The deformed mesh behind instance mesh index `mesh`, if it is one.
    #[inline]
    pub(crate) fn deformed_mesh(&self, mesh: u32) -> Option<&DeformedMesh> {
        (mesh as usize)
            .checked_sub(self.scene.meshes.len())
            .map(|k| &self.deformed[k])
    }

    /// The scene mesh drawn by instance mesh index `mesh` (the source of a deformed one).
    #[inline]
    pub(crate) fn source_mesh(&self, mesh: u32) -> &Mesh {
        let source = self.deformed_mesh(mesh).map_or(mesh, |d| d.source);
        &self.scene.meshes[source as usize]
    }

    /// The BVH of instance mesh index `mesh`.
    #[inline]
    pub(crate) fn mesh_bvh(&self, mesh: u32) -> &MeshBvh {
        match self.deformed_mesh(mesh) {
            Some(d) => &d.bvh,
            None => &self.scene.meshes[mesh as usize].bvh,
        }
    }

    /// Triangle `triangle` of instance `instance` at shutter time `time`; `moved` holds the
    /// instance's placement at that time if it moves.
    #[inline(always)]
    pub(crate) fn triangle_at<'a>(
        &'a self,
        instance: u32,
        triangle: u32,
        time: f32,
        moved: &'a mut Option<Placement>,
    ) -> TriangleAt<'a> {
        let mut tri = self.unplaced_triangle(instance, triangle, time);
        if tri.inst.has_motion() {
            tri.moved = Some(moved.insert(tri.inst.placement(time)));
        }
        tri
    }

    /// [`Self::triangle_at`] without a moving instance's placement at `time`, whose
    /// transforms it then reads as the stored ones: only for the triangle's data (its
    /// positions are at `time`).
    #[inline(always)]
    fn unplaced_triangle(&self, instance: u32, triangle: u32, time: f32) -> TriangleAt<'_> {
        let inst = &self.bvh.instances()[instance as usize];
        let mesh = self.source_mesh(inst.mesh);
        let (prim_index, t) = mesh.locate(triangle);
        let prim = &mesh.primitives[prim_index];
        let v = prim.triangle(t);
        TriangleAt {
            prim,
            prim_index,
            t,
            v,
            deformed: self.deformed_mesh(inst.mesh),
            inst,
            moved: None,
            time,
        }
    }

    /// Where the point `hit` landed on is, in world space, at the shutter's open and close
    /// (indexed by [`ShutterEnd`]): its barycentric place on its triangle, deformed and
    /// moved as the frame says at each end. A point on an instance that neither moves nor
    /// deforms is placed once, and only forward matrices are made (not the inverses of
    /// [`Self::triangle_at`], which shading needs and this does not).
    pub(crate) fn hit_points_at_ends(&self, hit: &Hit) -> [Vec3; 2] {
        let at = |end: ShutterEnd| {
            let tri = self.unplaced_triangle(hit.instance, hit.triangle, end.time());
            let [a, b, c] = tri.positions();
            let p = barycentric(a, b, c, hit.b1, hit.b2);
            tri.inst.to_world_at(end.time()).transform_point3(p)
        };
        let open = at(ShutterEnd::Open);
        let inst = &self.bvh.instances()[hit.instance as usize];
        if !inst.has_motion() && self.deformed_mesh(inst.mesh).is_none() {
            return [open; 2];
        }
        [open, at(ShutterEnd::Close)]
    }

    /// Whether a candidate hit counts: alpha-masked or blended surfaces cut away where
    /// their coverage says so, and a single-sided opaque surface is invisible from behind
    /// (glTF's back-face culling; transmissive surfaces keep both sides, since refracted
    /// rays must find the inside of the object).
    pub(crate) fn accepts(
        &self,
        ray: &Ray,
        instance: u32,
        triangle: u32,
        b1: f32,
        b2: f32,
    ) -> bool {
        let inst = &self.bvh.instances()[instance as usize];
        let mesh = self.source_mesh(inst.mesh);
        let (p, t) = mesh.locate(triangle);
        let source = self
            .deformed_mesh(inst.mesh)
            .map_or(inst.mesh, |d| d.source);
        if !self.hit_filter[source as usize][p] {
            return true;
        }
        let prim = &mesh.primitives[p];
        let mat = self.material(prim.material);
        if !mat.double_sided && !mat.transmits() {
            let mut moved = None;
            let tri = self.triangle_at(instance, triangle, ray.time, &mut moved);
            let facing = tri
                .face_normal(tri.positions())
                .dot(tri.to_object().transform_vector3(ray.dir));
            if facing > 0.0 {
                return false;
            }
        }
        if mat.alpha_mode == AlphaMode::Opaque {
            return true;
        }
        let (uvs, color) = (prim.uvs_at(t, b1, b2), prim.color_at(t, b1, b2));
        let alpha = mat.alpha(&self.scene.textures, uvs, color);
        // Stochastic coverage for blended surfaces, keyed by the ray and the triangle so
        // the result is a pure function of the sample.
        let key = hash_combine(
            hash_combine(
                ray.origin.x.to_bits() ^ ray.dir.y.to_bits(),
                ray.dir.x.to_bits(),
            ),
            triangle ^ (instance << 20),
        );
        let u = (key >> 8) as f32 / (1u32 << 24) as f32;
        !mat.cuts_away(alpha, u)
    }

    /// Whether a hit of triangle `t` of instance `i` counts, in a frame with a filter
    /// (see [`Self::accepts`]).
    #[inline(always)]
    fn counts(&self, ray: &Ray, i: u32, t: u32, b1: f32, b2: f32) -> bool {
        !self.filtered_instances[i as usize] || self.accepts(ray, i, t, b1, b2)
    }

    /// The closest accepted hit along `ray` before `t_max`.
    pub fn intersect(&self, ray: &Ray, t_max: f32) -> Option<Hit> {
        // SAFETY: without `AVX`, nothing is asked of the CPU.
        unsafe { self.query::<false, false>(ray, t_max) }
    }

    /// Whether anything accepted blocks `ray` before `t_max`.
    pub fn occluded(&self, ray: &Ray, t_max: f32) -> bool {
        // SAFETY: as in `intersect`.
        unsafe { self.query::<true, false>(ray, t_max) }.is_some()
    }

    /// [`Self::intersect`] (`ANY_HIT` false) or [`Self::occluded`] (true: a hit if any)
    /// for the path loop's AVX copy, into which it inlines (see `SceneBvh::query`).
    ///
    /// # Safety
    /// The CPU must have AVX ([`crate::simd::avx`] says so).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx")]
    #[inline]
    pub(crate) unsafe fn query_avx<const ANY_HIT: bool>(
        &self,
        ray: &Ray,
        t_max: f32,
    ) -> Option<Hit> {
        // SAFETY: the caller's CPU has AVX.
        unsafe { self.query::<ANY_HIT, true>(ray, t_max) }
    }

    /// The query of `SceneBvh::query`, with this frame's meshes and hit filter.
    ///
    /// # Safety
    /// With `AVX`, the CPU must have AVX.
    #[inline(always)]
    unsafe fn query<const ANY_HIT: bool, const AVX: bool>(
        &self,
        ray: &Ray,
        t_max: f32,
    ) -> Option<Hit> {
        let meshes = |m| self.mesh_bvh(m);
        // SAFETY: passed on from the caller.
        unsafe {
            if self.any_hit_filter {
                let counts = |i, t, b1, b2| self.counts(ray, i, t, b1, b2);
                self.bvh
                    .query::<ANY_HIT, AVX, _>(meshes, ray, t_max, counts)
            } else {
                self.bvh
                    .query::<ANY_HIT, AVX, _>(meshes, ray, t_max, |_, _, _, _| true)
            }
        }
    }
}

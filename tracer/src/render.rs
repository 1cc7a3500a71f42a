//! A scene prepared for one frame, and the tracer's one entry point, [`render_tile`].
//!
//! [`prepare_frame`] (in `prepare.rs`) poses the scene at the frame's time, moves it so the
//! camera sits at the origin, and builds the top-level BVH and the light set.
//! [`render_tile`] traces any rectangle and sample range of that frame; its result depends
//! on nothing else.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use glam::{DVec3, Vec3, Vec4};
use rayon::prelude::*;

use crate::animation::AnimationChoice;
use glam::{Affine3A, Mat3A};

use crate::bvh::{Instance, MeshBvh, Placement, SceneBvh};
use crate::camera::Camera;
use crate::film::{SampleRange, TileBuffer, TileRect};
use crate::geometry::Ray;
use crate::integrator;
use crate::light::{Environment, LightSet};
use crate::material::AlphaMode;
use crate::motion::{DeformedMesh, Shutter};
use crate::sampler::hash_combine;
use crate::scene::{Features, Mesh, Primitive, Scene};

pub use crate::prepare::prepare_frame;

/// Which camera renders the frame.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub enum CameraChoice {
    /// The scene's first camera, or one that frames the scene when it has none.
    #[default]
    Default,
    /// glTF camera index.
    Index(usize),
    /// glTF camera name.
    Name(String),
}

/// What is fixed for a whole frame: time, image size, camera, environment.
#[derive(Clone, Debug)]
pub struct FrameOptions {
    /// Frame number; with `fps`, frame f is at time f / fps.
    pub frame: i32,
    /// Frames per second.
    pub fps: f64,
    /// The shutter, relative to the frame's time; closed (no motion blur) by default.
    pub shutter: Shutter,
    /// Motion steps over an open shutter; `None` chooses from how much the scene moves
    /// (see `motion.rs`). Ignored when nothing moves.
    pub motion_steps: Option<u32>,
    /// Which animations play.
    pub animation: AnimationChoice,
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// The camera.
    pub camera: CameraChoice,
    /// Replaces the scene's environment. `None` keeps the scene's own; a scene that defines
    /// none (every glTF file) gets a uniform white environment of radiance 1 when it has no
    /// punctual light, so a bare model is lit as in a viewer, and darkness otherwise.
    pub environment: Option<Environment>,
}

impl Default for FrameOptions {
    fn default() -> Self {
        Self {
            frame: 0,
            fps: 24.0,
            shutter: Shutter::default(),
            motion_steps: None,
            animation: AnimationChoice::All,
            width: 640,
            height: 360,
            camera: CameraChoice::Default,
            environment: None,
        }
    }
}

/// Settings of the light transport itself, the same for every tile of a job.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RenderSettings {
    /// Maximum number of bounces: 0 shows only emitters seen directly, 1 adds direct light.
    pub max_depth: u32,
    /// A user seed, mixed into every random number.
    pub seed: u32,
    /// Adaptive sampling: each pixel stops once its estimated error is at or below this
    /// target (and at the end of the sample range if it never is).
    pub noise: Option<NoiseTarget>,
    /// Russian roulette: from this bounce on, a path whose throughput has fallen below 1
    /// ends with probability 1 − throughput and its survivors are weighted up. `None` never
    /// plays it, so paths end at `max_depth` only. The image converges to the same result
    /// either way; the setting trades noise for time (`tessera bench` measures it).
    pub russian_roulette: Option<u32>,
}

impl RenderSettings {
    /// The defaults, for constants (`..RenderSettings::DEFAULT`): 8 bounces, seed 0, no
    /// adaptive sampling, Russian roulette from the third bounce.
    pub const DEFAULT: RenderSettings = RenderSettings {
        max_depth: 8,
        seed: 0,
        noise: None,
        russian_roulette: Some(3),
    };
}

impl Default for RenderSettings {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// When a pixel has enough samples: its estimated error
/// ([`noise_estimate`](crate::film::noise_estimate)) is at or below `threshold` at
/// [`NoiseTarget::CHECKS_IN_A_ROW`] checks in a row, checked after `min_samples` and then
/// every [`NoiseTarget::CHECK_EVERY`] samples. Whether a pixel stops depends on its own
/// samples only, so the image is the same for any tile split; it must be rendered as one
/// sample range starting at 0.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NoiseTarget {
    /// The error to reach (Cycles' default is 0.01; smaller is cleaner and slower).
    pub threshold: f32,
    /// Samples every pixel takes before it may stop: the estimate of a handful of
    /// samples can be lucky, missing a rare bright path.
    pub min_samples: u32,
}

impl NoiseTarget {
    /// Samples between two checks (an even number, so both halves grow alike).
    pub const CHECK_EVERY: u32 = 4;
    /// Checks in a row that must find the error at the threshold. The estimate of one
    /// check is itself noisy, and stopping at the first low one stops on luck: with one
    /// check the demo's true mean error came out at the threshold, twice the estimate.
    pub const CHECKS_IN_A_ROW: u32 = 2;

    /// Whether a pixel with `taken` samples and estimated error `noise` may stop;
    /// `streak` carries the pixel's checks in a row at the threshold (start it at 0).
    pub fn reached(&self, taken: u32, noise: f32, streak: &mut u32) -> bool {
        if taken < self.min_samples.max(2) || !taken.is_multiple_of(Self::CHECK_EVERY) {
            return false;
        }
        *streak = if noise <= self.threshold {
            *streak + 1
        } else {
            0
        };
        *streak >= Self::CHECKS_IN_A_ROW
    }
}

/// An error preparing a frame.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum RenderError {
    /// The camera asked for does not exist or is not placed in the scene.
    #[error("camera {0}")]
    Camera(String),
    /// The image size is zero.
    #[error("image size {0}x{1} is empty")]
    EmptyImage(u32, u32),
    /// The frame rate, shutter or motion steps are unusable.
    #[error("{0}")]
    Time(String),
    /// The animation asked for does not exist.
    #[error("animation {0}")]
    Animation(String),
}

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
    /// Per scene material, its BSDF where every texture and the vertex colour are white
    /// (with the albedo curve of rough glass).
    pub(crate) material_bsdfs: Vec<crate::bsdf::Bsdf>,
    /// What the frame uses.
    pub features: Features,
    /// Remarks for the user (for example, the default environment was used).
    pub warnings: Vec<String>,
}

/// One triangle of an instance at a ray's time: where its data lives, its vertex
/// positions in object space (world space for deformed meshes), and the instance's
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
    /// Vertex positions (object space).
    pub positions: [Vec3; 3],
    /// The deformed mesh it belongs to, if any.
    pub deformed: Option<&'a DeformedMesh>,
    /// The instance.
    inst: &'a Instance,
    /// Its transforms at the ray's time when it moves; a still instance's are its own
    /// (not copied: this is on every hit's path).
    moved: Option<Placement>,
    /// The ray's shutter time.
    pub time: f32,
}

impl TriangleAt<'_> {
    /// Object space to world space.
    #[inline(always)]
    pub fn to_world(&self) -> &Affine3A {
        self.moved
            .as_ref()
            .map_or(&self.inst.to_world, |p| &p.to_world)
    }

    /// World space to object space.
    #[inline(always)]
    pub fn to_object(&self) -> &Affine3A {
        self.moved
            .as_ref()
            .map_or(&self.inst.to_object, |p| &p.to_object)
    }

    /// The normal matrix (inverse transpose of `to_world`'s linear part).
    #[inline(always)]
    pub fn normal_to_world(&self) -> &Mat3A {
        self.moved
            .as_ref()
            .map_or(&self.inst.normal_to_world, |p| &p.normal_to_world)
    }

    /// Object-space geometric normal by the winding (not normalised), turned for the baked
    /// vertices of a mirrored node (a still instance's mirror is in its normal matrix).
    pub fn face_normal(&self) -> Vec3 {
        let [a, b, c] = self.positions;
        let n = (b - a).cross(c - a);
        if self.deformed.is_some_and(|d| d.mirrored) {
            -n
        } else {
            n
        }
    }

    /// World-space unit normal of the front face. The inverse transpose keeps the front
    /// face right for mirrored instances too (glTF flips the winding when the determinant
    /// is negative). Zero for a degenerate triangle.
    pub fn front_normal(&self) -> Vec3 {
        (*self.normal_to_world() * self.face_normal()).normalize_or_zero()
    }

    /// Object-space vertex normals, or `None` when the primitive has none.
    pub fn normals(&self) -> Option<[Vec3; 3]> {
        match self.deformed {
            Some(d) => d.normals(self.prim_index, self.v, self.time),
            None => (!self.prim.normals.is_empty()).then(|| self.v.map(|i| self.prim.normals[i])),
        }
    }

    /// Object-space vertex tangents, or `None` when the primitive has none.
    pub fn tangents(&self) -> Option<[Vec4; 3]> {
        match self.deformed {
            Some(d) => d.tangents(self.prim_index, self.v, self.time),
            None => (!self.prim.tangents.is_empty()).then(|| self.v.map(|i| self.prim.tangents[i])),
        }
    }
}

impl PreparedFrame {
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

    /// Triangle `triangle` of instance `instance` at shutter time `time`.
    #[inline(always)]
    pub(crate) fn triangle_at(&self, instance: u32, triangle: u32, time: f32) -> TriangleAt<'_> {
        let inst = &self.bvh.instances()[instance as usize];
        let mesh = self.source_mesh(inst.mesh);
        let (prim_index, t) = mesh.locate(triangle);
        let prim = &mesh.primitives[prim_index];
        let v = prim.triangle(t);
        let deformed = self.deformed_mesh(inst.mesh);
        let positions = match deformed {
            Some(d) => d.positions(prim_index, v, time),
            None => v.map(|i| prim.positions[i]),
        };
        TriangleAt {
            prim,
            prim_index,
            t,
            v,
            positions,
            deformed,
            inst,
            moved: inst.motion.is_some().then(|| inst.placement(time)),
            time,
        }
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
        let mat = &self.scene.materials[prim.material as usize];
        if !mat.double_sided && mat.transmission == 0.0 {
            let tri = self.triangle_at(instance, triangle, ray.time);
            let facing = tri
                .face_normal()
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

    /// The closest accepted hit along `ray` before `t_max`.
    pub fn intersect(&self, ray: &Ray, t_max: f32) -> Option<crate::geometry::Hit> {
        let meshes = |m| self.mesh_bvh(m);
        if self.any_hit_filter {
            self.bvh.intersect(meshes, ray, t_max, |i, t, b1, b2| {
                !self.filtered_instances[i as usize] || self.accepts(ray, i, t, b1, b2)
            })
        } else {
            self.bvh.intersect(meshes, ray, t_max, |_, _, _, _| true)
        }
    }

    /// Whether anything accepted blocks `ray` before `t_max`.
    pub fn occluded(&self, ray: &Ray, t_max: f32) -> bool {
        let meshes = |m| self.mesh_bvh(m);
        if self.any_hit_filter {
            self.bvh.occluded(meshes, ray, t_max, |i, t, b1, b2| {
                !self.filtered_instances[i as usize] || self.accepts(ray, i, t, b1, b2)
            })
        } else {
            self.bvh.occluded(meshes, ray, t_max, |_, _, _, _| true)
        }
    }
}

/// Renders samples `samples` of the pixels in `rect` of `frame` (with a noise target, a
/// pixel stops early once it reaches it). Every pixel is a pure function of (pixel,
/// sample index, frame, settings), so any split into tiles and sample ranges gives the
/// same result. Parallel over rows with rayon.
pub fn render_tile(
    frame: &PreparedFrame,
    settings: &RenderSettings,
    rect: TileRect,
    samples: SampleRange,
) -> TileBuffer {
    let never = AtomicBool::new(false);
    render_tile_cancellable(frame, settings, rect, samples, &never)
        .expect("a render nobody cancels finishes")
}

/// [`render_tile`] that gives up, returning `None`, soon after `cancel` is set: each pixel
/// checks it, so a worker whose lease is gone stops within one pixel's samples per thread.
/// When it finishes, the tile is bit-identical to [`render_tile`]'s.
pub fn render_tile_cancellable(
    frame: &PreparedFrame,
    settings: &RenderSettings,
    rect: TileRect,
    samples: SampleRange,
    cancel: &AtomicBool,
) -> Option<TileBuffer> {
    let rows: Option<Vec<TileBuffer>> = (0..rect.height)
        .into_par_iter()
        .map(|row| {
            let mut buf = TileBuffer::new(TileRect::new(rect.x, rect.y + row, rect.width, 1));
            for col in 0..rect.width {
                if cancel.load(Ordering::Relaxed) {
                    return None;
                }
                let mut streak = 0;
                for index in samples.start..samples.end {
                    let s = integrator::trace_sample(
                        frame,
                        settings,
                        rect.x + col,
                        rect.y + row,
                        index,
                    );
                    let pixel = col as usize;
                    buf.add(pixel, index, &s);
                    if let Some(target) = &settings.noise {
                        let taken = index + 1 - samples.start;
                        if target.reached(taken, buf.noise(pixel), &mut streak) {
                            break;
                        }
                    }
                }
            }
            Some(buf)
        })
        .collect();
    let mut tile = TileBuffer::new(rect);
    rows?.iter().for_each(|row| tile.paste(row));
    Some(tile)
}

/// Renders `rect` split into `tile_size` tiles, in parallel, calling `tile_done` after
/// each tile (for progress bars). The result equals one [`render_tile`] of `rect`.
pub fn render_region(
    frame: &PreparedFrame,
    settings: &RenderSettings,
    rect: TileRect,
    samples: SampleRange,
    tile_size: u32,
    tile_done: &(dyn Fn(&TileBuffer) + Sync),
) -> TileBuffer {
    let tiles: Vec<TileBuffer> = rect
        .tiles(tile_size)
        .into_par_iter()
        .map(|t| {
            let buf = render_tile(frame, settings, t, samples);
            tile_done(&buf);
            buf
        })
        .collect();
    let mut out = TileBuffer::new(rect);
    tiles.iter().for_each(|t| out.paste(t));
    out
}

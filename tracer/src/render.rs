//! Preparing a scene for one frame, and the tracer's one entry point, [`render_tile`].
//!
//! [`prepare_frame`] walks the node graph once per frame, composing transforms in double
//! precision and moving the world so the camera sits at the origin (camera-relative
//! rendering: a scene far from the origin keeps its precision), then builds the top-level
//! BVH and the light set. [`render_tile`] traces any rectangle and sample range of that
//! frame; its result depends on nothing else.

use std::sync::Arc;

use glam::{Affine3A, DMat3, DMat4, DVec3, Vec3};
use rayon::prelude::*;

use crate::bvh::{Instance, SceneBvh};
use crate::camera::Camera;
use crate::film::{SampleRange, TileBuffer, TileRect};
use crate::geometry::Ray;
use crate::integrator;
use crate::light::{EmissiveTriangle, Environment, LightSet};
use crate::loader::framing_camera;
use crate::material::AlphaMode;
use crate::sampler::hash_combine;
use crate::scene::{Features, Scene};

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
            width: 640,
            height: 360,
            camera: CameraChoice::Default,
            environment: None,
        }
    }
}

/// Settings of the light transport itself, the same for every tile of a job.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RenderSettings {
    /// Maximum number of bounces: 0 shows only emitters seen directly, 1 adds direct light.
    pub max_depth: u32,
    /// A user seed, mixed into every random number.
    pub seed: u32,
}

impl Default for RenderSettings {
    fn default() -> Self {
        Self {
            max_depth: 8,
            seed: 0,
        }
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
    /// Top-level BVH over the instances.
    pub bvh: SceneBvh,
    /// Lights for next-event estimation.
    pub lights: LightSet,
    /// Per mesh, per primitive: whether a hit must be checked by [`PreparedFrame::accepts`]
    /// (alpha cut-outs, single-sided back faces). Meshes that need none pay nothing.
    pub(crate) hit_filter: Vec<Vec<bool>>,
    /// Whether any primitive needs the hit filter.
    pub(crate) any_hit_filter: bool,
    /// What the frame uses.
    pub features: Features,
    /// Remarks for the user (for example, the default environment was used).
    pub warnings: Vec<String>,
}

/// Removes scale and shear from a camera's placement: only position and orientation count.
fn rigid(m: &DMat4) -> (DVec3, DMat3) {
    let (_, rotation, translation) = m.to_scale_rotation_translation();
    let r = DMat3::from_quat(rotation.normalize());
    let r = if r.is_finite() { r } else { DMat3::IDENTITY };
    (translation, r)
}

fn to_f32_affine(m: &DMat4) -> Affine3A {
    Affine3A::from_mat4(m.as_mat4())
}

/// Flattens `scene` for one frame.
pub fn prepare_frame(
    scene: Arc<Scene>,
    options: &FrameOptions,
) -> Result<PreparedFrame, RenderError> {
    if options.width == 0 || options.height == 0 {
        return Err(RenderError::EmptyImage(options.width, options.height));
    }
    let aspect = options.width as f32 / options.height as f32;
    let mut nodes = Vec::new();
    scene.for_each_node_instance(|node, world| nodes.push((node, *world)));
    let mut warnings = Vec::new();

    // Camera: find the node placing the requested camera.
    let wanted = match &options.camera {
        CameraChoice::Default => (!scene.cameras.is_empty()).then_some(0),
        CameraChoice::Index(i) if *i < scene.cameras.len() => Some(*i),
        CameraChoice::Index(i) => {
            return Err(RenderError::Camera(format!(
                "{i} does not exist: the scene has {} camera(s)",
                scene.cameras.len()
            )))
        }
        CameraChoice::Name(name) => Some(
            scene
                .cameras
                .iter()
                .position(|c| c.name.as_deref() == Some(name.as_str()))
                .ok_or_else(|| RenderError::Camera(format!("'{name}' does not exist")))?,
        ),
    };
    let placed = wanted.and_then(|cam| {
        nodes
            .iter()
            .find(|(n, _)| scene.nodes[*n as usize].camera == Some(cam as u32))
            .map(|(_, m)| (scene.cameras[cam].projection, *m))
    });
    let (projection, camera_world) = match (wanted, placed) {
        (Some(_), Some(p)) => p,
        (Some(cam), None) if options.camera != CameraChoice::Default => {
            return Err(RenderError::Camera(format!(
                "{cam} is not placed by any node of the scene"
            )))
        }
        _ => framing_camera(&scene, aspect),
    };
    let (camera_origin, camera_rotation) = rigid(&camera_world);
    let camera = Camera {
        projection,
        to_world: Affine3A::from_mat3(camera_rotation.as_mat3()),
        aspect,
    };
    // Everything moves by -camera_origin, in double precision, before rounding to f32.
    let relative = DMat4::from_translation(-camera_origin);

    let mut instances = Vec::new();
    let mut punctual = Vec::new();
    for (node, world) in &nodes {
        let n = &scene.nodes[*node as usize];
        let to_world = to_f32_affine(&(relative * *world));
        if let Some(mesh) = n.mesh {
            let bounds = scene.meshes[mesh as usize].bvh.bounds();
            instances.push(Instance::new(mesh, to_world, &bounds));
        }
        if let Some(light) = n.light {
            punctual.push((scene.lights[light as usize], to_world));
        }
    }

    // Emissive triangles, in world space, for next-event estimation.
    let mut triangles = Vec::new();
    for (i, inst) in instances.iter().enumerate() {
        let mesh = &scene.meshes[inst.mesh as usize];
        for (p, prim) in mesh.primitives.iter().enumerate() {
            let material = &scene.materials[prim.material as usize];
            if !material.is_emissive() {
                continue;
            }
            for (t, &[a, b, c]) in prim.indices.iter().enumerate() {
                let [a, b, c] =
                    [a, b, c].map(|v| inst.to_world.transform_point3(prim.positions[v as usize]));
                triangles.push(EmissiveTriangle {
                    p: [a, b, c],
                    emission: material.emissive,
                    double_sided: material.double_sided,
                    instance: i as u32,
                    triangle: mesh.first_triangle[p] + t as u32,
                });
            }
        }
    }

    // Build the BSDF's energy tables now rather than inside the first tile's threads.
    crate::bsdf::precompute_tables(scene.features.transmission);
    let bvh = SceneBvh::build(instances);
    let mut features = scene.features;
    let environment = match (&options.environment, &scene.environment) {
        (Some(env), _) | (None, Some(env)) => env.clone(),
        (None, None) if punctual.is_empty() => {
            warnings.push(
                "the scene defines no environment and no punctual light: using a uniform white \
                 environment of radiance 1"
                    .into(),
            );
            Environment::Constant(Vec3::ONE)
        }
        (None, None) => Environment::Black,
    };
    features.environment = !matches!(environment, Environment::Black);
    let lights = LightSet::new(punctual, triangles, environment, bvh.bounds());

    let hit_filter: Vec<Vec<bool>> = scene
        .meshes
        .iter()
        .map(|m| {
            m.primitives
                .iter()
                .map(|p| {
                    let mat = &scene.materials[p.material as usize];
                    mat.alpha_mode != AlphaMode::Opaque
                        || (!mat.double_sided && mat.transmission == 0.0)
                })
                .collect()
        })
        .collect();
    let any_hit_filter = hit_filter.iter().flatten().any(|&f| f);

    Ok(PreparedFrame {
        scene,
        frame: options.frame,
        width: options.width,
        height: options.height,
        camera,
        camera_origin,
        bvh,
        lights,
        hit_filter,
        any_hit_filter,
        features,
        warnings,
    })
}

impl PreparedFrame {
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
        let mesh = &self.scene.meshes[inst.mesh as usize];
        let (p, t) = mesh.locate(triangle);
        if !self.hit_filter[inst.mesh as usize][p] {
            return true;
        }
        let prim = &mesh.primitives[p];
        let mat = &self.scene.materials[prim.material as usize];
        if !mat.double_sided && mat.transmission == 0.0 {
            let facing = prim
                .face_normal(t)
                .dot(inst.to_object.transform_vector3(ray.dir));
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
        let meshes = &self.scene.meshes;
        if self.any_hit_filter {
            self.bvh.intersect(meshes, ray, t_max, |i, t, b1, b2| {
                self.accepts(ray, i, t, b1, b2)
            })
        } else {
            self.bvh.intersect(meshes, ray, t_max, |_, _, _, _| true)
        }
    }

    /// Whether anything accepted blocks `ray` before `t_max`.
    pub fn occluded(&self, ray: &Ray, t_max: f32) -> bool {
        let meshes = &self.scene.meshes;
        if self.any_hit_filter {
            self.bvh.occluded(meshes, ray, t_max, |i, t, b1, b2| {
                self.accepts(ray, i, t, b1, b2)
            })
        } else {
            self.bvh.occluded(meshes, ray, t_max, |_, _, _, _| true)
        }
    }
}

/// Renders samples `samples` of the pixels in `rect` of `frame`. Every pixel is a pure
/// function of (pixel, sample index, frame, seed), so any split into tiles and sample
/// ranges gives the same result. Parallel over rows with rayon.
pub fn render_tile(
    frame: &PreparedFrame,
    settings: &RenderSettings,
    rect: TileRect,
    samples: SampleRange,
) -> TileBuffer {
    let rows: Vec<TileBuffer> = (0..rect.height)
        .into_par_iter()
        .map(|row| {
            let mut buf = TileBuffer::new(TileRect::new(rect.x, rect.y + row, rect.width, 1));
            for col in 0..rect.width {
                for index in samples.start..samples.end {
                    let s = integrator::trace_sample(
                        frame,
                        settings,
                        rect.x + col,
                        rect.y + row,
                        index,
                    );
                    buf.add(col as usize, &s);
                }
            }
            buf
        })
        .collect();
    let mut tile = TileBuffer::new(rect);
    rows.iter().for_each(|row| tile.paste(row));
    tile
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

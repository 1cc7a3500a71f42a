//! [`prepare_frame`]: a scene flattened for one frame.
//!
//! The node graph is posed at the frame's time (animations evaluated, transforms composed
//! in double precision) and moved so that the camera sits at the origin (camera-relative
//! rendering: a scene far from the origin keeps its precision). With an open shutter and
//! something that moves inside it, the graph is posed at every motion step: rigid instances
//! get per-step transforms, skinned and morphed meshes per-step vertices, a moving camera
//! per-step placements. A still scene, or a closed shutter, gets one pose and the static
//! path, which pays nothing per ray for motion blur.

use std::sync::Arc;

use glam::{Affine3A, DMat3, DMat4, DQuat, DVec3, Vec2, Vec3, Vec4};

use crate::animation::{self, Pose};
use crate::bsdf::Bsdf;
use crate::bvh::{Instance, SceneBvh};
use crate::camera::{Camera, Projection, RigidStep};
use crate::deform::{self, Deformed};
use crate::frame::{PreparedFrame, PreparedMaterial};
use crate::geometry::Aabb;
use crate::light::{EmissiveTriangle, Environment, LightSet};
use crate::loader::{framing_camera, mesh_bounds, scene_bounds};
use crate::material::{AlphaMode, Material};
use crate::motion::{auto_steps, place, step_positions, DeformedMesh, PixelFootprint, PROBES};
use crate::scene::{Node, Scene};
use crate::settings::{CameraChoice, FrameOptions, RenderError};

mod spectra;

use spectra::FrameSpectra;

/// The node graph at one time: every node instance and every mesh draw with its world
/// transform, and the first world transform of each node (the one joints of a skin use).
struct Posed {
    pose: Pose,
    /// Node instances (cameras and lights hang from these).
    instances: Vec<(u32, DMat4)>,
    /// Mesh draws: each node instance with a mesh, once per GPU instance.
    draws: Vec<(u32, DMat4)>,
    world: Vec<Option<DMat4>>,
}

impl Posed {
    fn new(scene: &Scene, animations: &[usize], seconds: f64) -> Self {
        let pose = animation::pose(scene, animations, seconds);
        let mut instances = Vec::new();
        scene.for_each_node_instance_with(
            |i| pose.local[i as usize],
            |i, m| instances.push((i, *m)),
        );
        let draws = instances
            .iter()
            .filter(|(i, _)| scene.nodes[*i as usize].mesh.is_some())
            .flat_map(|&(i, world)| {
                let node = &scene.nodes[i as usize];
                node.draw_transforms().iter().map(move |t| (i, world * *t))
            })
            .collect();
        let world = animation::world_transforms(scene, &pose);
        Self {
            pose,
            instances,
            draws,
            world,
        }
    }
}

/// Removes scale and shear from a camera's placement: only position and orientation count.
fn rigid(m: &DMat4) -> (DVec3, DQuat) {
    let (_, rotation, translation) = m.to_scale_rotation_translation();
    let r = rotation.normalize();
    let r = if r.is_finite() { r } else { DQuat::IDENTITY };
    (translation, r)
}

fn to_f32_affine(m: &DMat4) -> Affine3A {
    Affine3A::from_mat4(m.as_mat4())
}

/// Whether `m` is finite but cannot be inverted in f32, by the test [`Instance::new`]
/// makes (a zero scale on some axis): rays could not enter such an instance.
fn has_no_inverse(m: &DMat4) -> bool {
    let a = to_f32_affine(m);
    let det = a.matrix3.determinant();
    a.is_finite() && !(det != 0.0 && det.is_finite() && a.inverse().is_finite())
}

/// Whether placing `mesh` by the camera-relative `to_frame` in single precision resolves
/// it far more coarsely than its distance from the camera calls for. Rays meet an instance
/// in its object space, where the camera sits about as far from the origin as the
/// translation says, so positions there round relative to the translation, not to the
/// surface's distance: a unit cube scaled to 2e5 and moved 1e5 away, as a wall a metre
/// from the camera, would have centimetre steps. Such a mesh is baked into the frame in
/// double precision instead, where its vertices near the camera keep their detail. (Only
/// a camera outside the mesh's box can be near all of it and far from its origin.)
fn coarse_placement(mesh: &crate::scene::Mesh, to_frame: &DMat4) -> bool {
    // The rounding is 1024 times coarser than at the mesh's distance: ten bits lost.
    const LOST: f64 = 1024.0;
    let b = mesh.bvh.bounds();
    if b.is_empty() {
        return false;
    }
    let (mut lo, mut hi) = (DVec3::INFINITY, DVec3::NEG_INFINITY);
    for c in b.corners() {
        let p = to_frame.transform_point3(c.as_dvec3());
        (lo, hi) = (lo.min(p), hi.max(p));
    }
    // Distance from the camera (the origin) to the mesh's box in the frame.
    let distance = DVec3::ZERO.clamp(lo, hi).length();
    let translation = to_frame.w_axis.truncate().length();
    distance > 0.0 && translation.is_finite() && translation > LOST * distance
}

/// Whether `node` deforms its mesh: a skin whose mesh carries joint influences, or morph
/// targets whose weights are not all zero at some pose.
fn deforms(scene: &Scene, node: u32, poses: &[&Posed]) -> bool {
    let n = &scene.nodes[node as usize];
    let Some(mesh) = n.mesh.map(|m| &scene.meshes[m as usize]) else {
        return false;
    };
    let skinned = n.skin.is_some() && mesh.primitives.iter().any(|p| !p.joint_sets.is_empty());
    let morphed = mesh.primitives.iter().any(|p| !p.targets.is_empty())
        && poses.iter().any(|posed| {
            animation::morph_weights(scene, &posed.pose, node)
                .iter()
                .any(|&w| w != 0.0)
        });
    skinned || morphed
}

/// The primitives of instance `(node, world)`'s mesh deformed at `posed`, in the prepared
/// frame's camera-relative space (`relative` moves world space there).
fn deform_instance(
    scene: &Scene,
    posed: &Posed,
    node: u32,
    world: &DMat4,
    relative: &DMat4,
) -> Vec<Deformed> {
    let n: &Node = &scene.nodes[node as usize];
    let mesh = &scene.meshes[n.mesh.expect("only mesh nodes deform") as usize];
    let weights = animation::morph_weights(scene, &posed.pose, node);
    let joints = n
        .skin
        .and_then(|s| scene.skins.get(s as usize))
        .map(|skin| {
            deform::joint_matrices(skin, |j| posed.world[j as usize].map(|w| *relative * w))
        });
    mesh.primitives
        .iter()
        .map(|prim| {
            let skin = joints.as_deref().filter(|_| !prim.joint_sets.is_empty());
            let mut d = deform::deform(prim, weights, skin);
            if skin.is_none() {
                place(&mut d, &(*relative * *world));
            }
            d
        })
        .collect()
}

/// Up to this many vertices per primitive stand for a deforming mesh when choosing the
/// number of motion steps.
const PROBE_VERTICES: usize = 64;

/// Camera-space points that show how the frame moves at `posed`: the corners of every
/// mesh instance's box and a sample of each deforming mesh's vertices.
fn probe_points(
    scene: &Scene,
    posed: &Posed,
    deforming: &[bool],
    relative: &DMat4,
    camera_from_world: &DMat4,
) -> Vec<DVec3> {
    let mut points = Vec::new();
    for (j, (node, world)) in posed.draws.iter().enumerate() {
        let mesh = scene.nodes[*node as usize].mesh.expect("draws have a mesh");
        if deforming[j] {
            for d in deform_instance(scene, posed, *node, world, relative) {
                let stride = d.positions.len().div_ceil(PROBE_VERTICES).max(1);
                points.extend(
                    d.positions
                        .iter()
                        .step_by(stride)
                        .map(|p| camera_from_world.transform_point3(p.as_dvec3())),
                );
            }
        } else {
            let b = mesh_bounds(&scene.meshes[mesh as usize]);
            if b.is_empty() {
                continue;
            }
            let to_camera = *camera_from_world * *relative * *world;
            for c in 0..8 {
                let corner = DVec3::new(
                    if c & 1 == 0 { b.min.x } else { b.max.x } as f64,
                    if c & 2 == 0 { b.min.y } else { b.max.y } as f64,
                    if c & 4 == 0 { b.min.z } else { b.max.z } as f64,
                );
                points.push(to_camera.transform_point3(corner));
            }
        }
    }
    points
}

/// The requested camera's projection and world placement at `center` (mid-shutter), with
/// the index of the node instance placing it; a camera framing the scene over its whole
/// animation when the default camera is asked for and the scene has none.
fn find_camera(
    scene: &Scene,
    choice: &CameraChoice,
    center: &Posed,
    animations: &[usize],
    aspect: f32,
) -> Result<(Projection, DMat4, Option<usize>), RenderError> {
    let wanted = match choice {
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
        center
            .instances
            .iter()
            .position(|(n, _)| scene.nodes[*n as usize].camera == Some(cam as u32))
            .map(|j| (cam, j))
    });
    match (wanted, placed) {
        (Some(_), Some((cam, j))) => Ok((
            scene.cameras[cam].projection,
            center.instances[j].1,
            Some(j),
        )),
        (Some(cam), None) if *choice != CameraChoice::Default => Err(RenderError::Camera(format!(
            "{cam} is not placed by any node of the scene"
        ))),
        _ => {
            let (projection, world) = framing_camera(&animated_bounds(scene, animations), aspect);
            Ok((projection, world, None))
        }
    }
}

/// Flattens `scene` for one frame.
pub fn prepare_frame(
    scene: Arc<Scene>,
    options: &FrameOptions,
) -> Result<PreparedFrame, RenderError> {
    options.check()?;
    let animations = options
        .animation
        .resolve(&scene)
        .map_err(RenderError::Animation)?;
    let aspect = options.width as f32 / options.height as f32;
    let mut warnings = Vec::new();
    let posed_at = |s: f64| {
        let seconds = options.shutter.seconds(options.frame, options.fps, s);
        Posed::new(&scene, &animations, seconds)
    };
    let center = posed_at(0.5);

    let (projection, camera_world, camera_instance) =
        find_camera(&scene, &options.camera, &center, &animations, aspect)?;
    let (camera_origin, camera_rotation) = rigid(&camera_world);
    // Everything moves by -camera_origin, in double precision, before rounding to f32.
    let relative = DMat4::from_translation(-camera_origin);
    let camera_at = |posed: &Posed| match camera_instance {
        Some(j) => rigid(&(relative * posed.instances[j].1)),
        None => (DVec3::ZERO, camera_rotation),
    };

    // Motion steps: one unless the shutter is open and an animation plays inside it.
    let animated = animations
        .iter()
        .any(|&a| !scene.animations[a].channels.is_empty());
    let mut deforming: Vec<bool> = center
        .draws
        .iter()
        .map(|(n, _)| deforms(&scene, *n, &[&center]))
        .collect();
    let steps = if !(options.shutter.is_open() && animated) {
        1
    } else if let Some(n) = options.motion_steps {
        n
    } else {
        let probes: Vec<Posed> = (0..PROBES)
            .map(|i| posed_at(i as f64 / (PROBES - 1) as f64))
            .collect();
        let refs: Vec<&Posed> = probes.iter().collect();
        for (j, (n, _)) in center.draws.iter().enumerate() {
            deforming[j] = deforms(&scene, *n, &refs);
        }
        let points: Vec<Vec<DVec3>> = probes
            .iter()
            .map(|posed| {
                let (position, rotation) = camera_at(posed);
                let camera_from_world =
                    DMat4::from_rotation_translation(rotation, position).inverse();
                probe_points(&scene, posed, &deforming, &relative, &camera_from_world)
            })
            .collect();
        auto_steps(&points, pixel_footprint(&projection, options.height))
    };
    let poses: Vec<Posed> = if steps == 1 {
        vec![center]
    } else {
        step_positions(steps).into_iter().map(posed_at).collect()
    };
    if steps > 1 {
        let refs: Vec<&Posed> = poses.iter().collect();
        for (j, (n, _)) in poses[0].draws.iter().enumerate() {
            deforming[j] = deforms(&scene, *n, &refs);
        }
    }
    let mid = &poses[poses.len() / 2];

    let mut camera_steps: Vec<RigidStep> = Vec::with_capacity(poses.len());
    for posed in &poses {
        let (position, rotation) = camera_at(posed);
        let rotation = crate::math::same_hemisphere(
            camera_steps.last().map(|prev| prev.rotation),
            rotation.as_quat().normalize(),
        );
        camera_steps.push(RigidStep {
            position: position.as_vec3(),
            rotation,
        });
    }
    let camera_moves = camera_steps.iter().any(|s| *s != camera_steps[0]);
    let camera = Camera::new(
        projection,
        Affine3A::from_mat3(DMat3::from_quat(camera_rotation).as_mat3()),
        aspect,
        camera_moves.then(|| camera_steps.into()),
    );

    let (instances, deformed) = place_instances(&scene, &poses, &deforming, &relative);

    // Punctual lights sit where the middle step puts them: they light the frame but do not
    // blur inside the shutter.
    let spectra = FrameSpectra::new(&scene);
    // Lights and materials as KHR_animation_pointer sets them at the middle of the shutter.
    let mid_seconds = options.shutter.seconds(options.frame, options.fps, 0.5);
    let lights_now = animation::lights_at(&scene, &animations, mid_seconds);
    let materials_now = animation::materials_at(&scene, &animations, mid_seconds)
        .unwrap_or_else(|| scene.materials.clone());
    let punctual: Vec<_> = mid
        .instances
        .iter()
        .filter_map(|(node, world)| {
            let light = scene.nodes[*node as usize].light?;
            Some((
                lights_now[light as usize],
                to_f32_affine(&(relative * *world)),
                spectra.of_light.get(&light).copied(),
            ))
        })
        .collect();

    let n_scene_meshes = scene.meshes.len();
    let bvh = SceneBvh::build(instances, |m| {
        let m = m as usize;
        if m < n_scene_meshes {
            &scene.meshes[m].bvh
        } else {
            &deformed[m - n_scene_meshes].bvh
        }
    });
    let triangles = emissive_triangles(
        &scene,
        &materials_now,
        &bvh,
        &deformed,
        &spectra.of_material,
    );

    // Build the BSDF's energy tables and curves now rather than inside the first tile's
    // threads.
    crate::bsdf::precompute_tables(
        scene.features.transmission,
        scene.features.sheen,
        scene.features.anisotropy,
    );
    let materials = prepared_materials(&scene, materials_now, &spectra);
    let mut features = scene.features;
    let environment = frame_environment(options, &scene, punctual.is_empty(), &mut warnings);
    features.environment = !matches!(environment, Environment::Black);
    let lights = LightSet::new(punctual, triangles, environment, bvh.bounds());
    let motion = bvh.has_motion() || camera.moves();
    features.animation = motion;

    let (hit_filter, filtered_instances) = hit_filters(&scene, &bvh, &deformed);
    let any_hit_filter = filtered_instances.contains(&true);

    Ok(PreparedFrame {
        scene,
        frame: options.frame,
        width: options.width,
        height: options.height,
        camera,
        camera_origin,
        bvh,
        deformed,
        motion_steps: steps,
        motion,
        lights,
        hit_filter,
        filtered_instances,
        any_hit_filter,
        materials,
        light_spectra: spectra.dense,
        fluorescence: spectra.paints,
        features,
        warnings,
    })
}

/// The frame's instances, one per mesh draw: rigid ones with one transform per step
/// (`relative` moves the world so the camera sits at the origin), deformed ones
/// (`deforming[j]` for draw `j`) as per-frame meshes, which the second list holds.
fn place_instances(
    scene: &Scene,
    poses: &[Posed],
    deforming: &[bool],
    relative: &DMat4,
) -> (Vec<Instance>, Vec<DeformedMesh>) {
    let mut instances = Vec::new();
    let mut deformed = Vec::new();
    for (j, &(node, _)) in poses[0].draws.iter().enumerate() {
        let mesh = scene.nodes[node as usize].mesh.expect("draws have a mesh");
        // Rays cannot enter a placement that has no inverse (a zero scale on one axis): bake
        // its vertices into the frame, as for a deformed mesh, so that a mesh flattened onto
        // a plane draws as that plane (the limit of ever thinner scales). A zero scale on
        // every axis leaves only zero-area triangles, which draw nothing.
        let flattened = poses.len() == 1 && has_no_inverse(&(*relative * poses[0].draws[j].1));
        // So is a mesh that its placement would resolve far too coarsely near the camera.
        let coarse = poses.len() == 1
            && coarse_placement(
                &scene.meshes[mesh as usize],
                &(*relative * poses[0].draws[j].1),
            );
        if deforming[j] || flattened || coarse {
            let per_step = poses
                .iter()
                .map(|posed| deform_instance(scene, posed, node, &posed.draws[j].1, relative))
                .collect();
            let mut d = DeformedMesh::new(mesh, &scene.meshes[mesh as usize], per_step);
            // Skinned vertices are placed by their joints; the others by the node, whose
            // mirror glTF's winding rule follows.
            let n = &scene.nodes[node as usize];
            let skinned = n.skin.is_some()
                && scene.meshes[mesh as usize]
                    .primitives
                    .iter()
                    .any(|p| !p.joint_sets.is_empty());
            d.mirrored = !skinned && DMat3::from_mat4(poses[0].draws[j].1).determinant() < 0.0;
            let index = (scene.meshes.len() + deformed.len()) as u32;
            instances.push(Instance::new(index, Affine3A::IDENTITY, &d.bvh.bounds()));
            deformed.push(d);
        } else {
            let bounds = scene.meshes[mesh as usize].bvh.bounds();
            let worlds: Vec<DMat4> = poses.iter().map(|p| *relative * p.draws[j].1).collect();
            instances.push(if worlds.len() == 1 {
                Instance::new(mesh, to_f32_affine(&worlds[0]), &bounds)
            } else {
                Instance::moving(mesh, &worlds, &bounds)
            });
        }
    }
    (instances, deformed)
}

/// The environment the frame is lit by: the options', else the scene's; a scene with
/// neither and no punctual light gets a uniform white one (and a warning), since it would
/// otherwise render black.
fn frame_environment(
    options: &FrameOptions,
    scene: &Scene,
    no_punctual: bool,
    warnings: &mut Vec<String>,
) -> Environment {
    match (&options.environment, &scene.environment) {
        (Some(env), _) | (None, Some(env)) => env.clone(),
        (None, None) if no_punctual => {
            warnings.push(
                "the scene defines no environment and no punctual light: using a uniform white \
                 environment of radiance 1"
                    .into(),
            );
            Environment::Constant(Vec3::ONE)
        }
        (None, None) => Environment::Black,
    }
}

/// Per scene mesh and primitive, whether a hit needs [`PreparedFrame::accepts`] (alpha
/// cut-outs, single-sided back faces); and per instance, whether its mesh has any such
/// primitive.
fn hit_filters(
    scene: &Scene,
    bvh: &SceneBvh,
    deformed: &[DeformedMesh],
) -> (Vec<Vec<bool>>, Vec<bool>) {
    let n_scene_meshes = scene.meshes.len();
    let hit_filter: Vec<Vec<bool>> = scene
        .meshes
        .iter()
        .map(|m| {
            m.primitives
                .iter()
                .map(|p| {
                    let mat = &scene.materials[p.material as usize];
                    mat.alpha_mode != AlphaMode::Opaque || (!mat.double_sided && !mat.transmits())
                })
                .collect()
        })
        .collect();
    let filtered_instances: Vec<bool> = bvh
        .instances()
        .iter()
        .map(|inst| {
            let m = inst.mesh as usize;
            let source = if m < n_scene_meshes {
                m
            } else {
                deformed[m - n_scene_meshes].source as usize
            };
            hit_filter[source].contains(&true)
        })
        .collect();
    (hit_filter, filtered_instances)
}

/// Poses sampled over the animations' time range to bound where the scene goes.
const BOUNDS_POSES: usize = 9;

/// World bounds of the scene over the whole time range of `animations` (its still bounds
/// without animation), so that the framing camera of a scene without a camera keeps every
/// frame of a sequence in view, and stays the same from frame to frame.
fn animated_bounds(scene: &Scene, animations: &[usize]) -> Aabb {
    let Some((start, end)) = animation::time_range(scene, animations) else {
        return scene_bounds(scene);
    };
    let mut bounds = Aabb::EMPTY;
    for k in 0..BOUNDS_POSES {
        let seconds = start + (end - start) * k as f64 / (BOUNDS_POSES - 1) as f64;
        let posed = Posed::new(scene, animations, seconds);
        for (node, world) in &posed.draws {
            let mesh = scene.nodes[*node as usize].mesh.expect("draws have a mesh");
            if deforms(scene, *node, &[&posed]) {
                for d in deform_instance(scene, &posed, *node, world, &DMat4::IDENTITY) {
                    d.positions.iter().for_each(|p| bounds.grow(*p));
                }
            } else {
                let b = mesh_bounds(&scene.meshes[mesh as usize]);
                if !b.is_empty() {
                    for c in b.corners() {
                        bounds.grow(world.transform_point3(c.as_dvec3()).as_vec3());
                    }
                }
            }
        }
    }
    bounds
}

/// How wide a pixel is at a distance, for the automatic motion-step choice.
fn pixel_footprint(projection: &Projection, height: u32) -> PixelFootprint {
    let h = height.max(1) as f64;
    match *projection {
        Projection::Perspective { yfov, .. } => PixelFootprint {
            absolute: 0.0,
            per_distance: 2.0 * crate::math::tan_f64(0.5 * yfov as f64) / h,
        },
        Projection::Orthographic { ymag, .. } => PixelFootprint {
            absolute: 2.0 * ymag as f64 / h,
            per_distance: 0.0,
        },
    }
}

/// Emissive triangles in the prepared frame, for next-event estimation. Emitters that move
/// inside the shutter are left out: light sampling would need their position at each
/// ray's time. They still light the scene when paths hit them (the MIS weight is then 1,
/// since the light sampler's density for them is 0), which is unbiased, only noisier.
fn emissive_triangles(
    scene: &Scene,
    materials: &[Material],
    bvh: &SceneBvh,
    deformed: &[DeformedMesh],
    spectra: &[Option<u32>],
) -> Vec<EmissiveTriangle> {
    let mut triangles = Vec::new();
    for (i, inst) in bvh.instances().iter().enumerate() {
        if inst.motion.is_some() {
            continue;
        }
        let d = (inst.mesh as usize)
            .checked_sub(scene.meshes.len())
            .map(|k| &deformed[k]);
        if d.is_some_and(DeformedMesh::moves) {
            continue;
        }
        let mesh = &scene.meshes[d.map_or(inst.mesh, |d| d.source) as usize];
        for (p, prim) in mesh.primitives.iter().enumerate() {
            let material = &materials[prim.material as usize];
            if !material.is_emissive() {
                continue;
            }
            for t in 0..prim.indices.len() {
                let v = prim.triangle(t);
                let object = match d {
                    Some(d) => d.positions(p, v, 0.0),
                    None => v.map(|i| prim.positions[i]),
                };
                triangles.push(EmissiveTriangle {
                    p: object.map(|x| inst.to_world.transform_point3(x)),
                    emission: material.emission_factor(),
                    double_sided: material.double_sided,
                    uniform: material.uniform_emission(!prim.colors.is_empty()),
                    mirrored: inst.to_world.matrix3.determinant() < 0.0,
                    instance: i as u32,
                    triangle: mesh.first_triangle[p] + t as u32,
                    spectrum: spectra[prim.material as usize],
                });
            }
        }
    }
    triangles
}

/// Per material at the frame's time, its BSDF of the factors alone and, without textures, its values.
/// The BSDF carries the albedo curve of a rough refractive interface where the roughness
/// is not textured (see `bsdf/curve.rs`); materials without one use the shared tables.
fn prepared_materials(
    scene: &Scene,
    materials: Vec<Material>,
    spectra: &FrameSpectra,
) -> Vec<PreparedMaterial> {
    materials
        .into_iter()
        .enumerate()
        .map(|(i, m)| {
            let curve = if m.metallic_roughness_texture.is_some() {
                None
            } else {
                Bsdf::albedo_curve_for(m.factors())
            };
            PreparedMaterial {
                bsdf: Bsdf::new(m.factors()).with_albedo_curve(curve),
                dispersion: if m.is_dispersive() { m.dispersion } else { 0.0 },
                emission_spectrum: spectra.of_material[i],
                fluorescence: spectra.paint_of_material[i],
                uniform: (!m.has_textures())
                    .then(|| m.sample(&scene.textures, [Vec2::ZERO; 2], Vec4::ONE)),
                material: m,
            }
        })
        .collect()
}

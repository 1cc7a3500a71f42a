//! The loaded scene: glTF's node graph, meshes, materials, textures, cameras and lights,
//! converted once into the tracer's own types. A [`Scene`] is independent of time and
//! camera; [`crate::frame::PreparedFrame`] flattens it for one frame.

use std::collections::BTreeMap;

use glam::{DMat4, DQuat, DVec3, Vec2, Vec3, Vec4};

use crate::animation::Animation;

use crate::bvh::MeshBvh;
use crate::camera::Projection;
use crate::geometry::barycentric;
use crate::light::{Environment, PunctualLight};
use crate::material::Material;
use crate::spectrum::SpectrumShape;
use crate::texture::Texture;

/// A whole scene, ready to be prepared for any frame.
#[derive(Debug, Default)]
pub struct Scene {
    /// Every node of the glTF document, in document order.
    pub nodes: Vec<Node>,
    /// Root nodes of the scene being rendered (glTF's default scene, or the first).
    pub roots: Vec<u32>,
    /// Meshes, each with its own BVH, shared by every node that uses it.
    pub meshes: Vec<Mesh>,
    /// Materials; a primitive without one uses the glTF default material, which the loader
    /// appends here.
    pub materials: Vec<Material>,
    /// Decoded textures.
    pub textures: Vec<Texture>,
    /// Camera projections; a node places them.
    pub cameras: Vec<CameraDef>,
    /// Punctual lights in their node's space; a node places them.
    pub lights: Vec<PunctualLight>,
    /// TESSERA_lights_spectrum: the spectrum of each light (by index in `lights`) that
    /// has one; the others' colours are lifted to spectra like any RGB colour.
    pub light_spectra: BTreeMap<u32, SpectrumShape>,
    /// Light arriving from infinitely far away, when the scene defines it. glTF has no
    /// environment, so loaded scenes leave this `None` and the renderer picks a default
    /// (see [`crate::settings::FrameOptions::environment`]); built-in scenes set it.
    pub environment: Option<Environment>,
    /// glTF animations (node transforms and morph weights over time), in document order.
    pub animations: Vec<Animation>,
    /// glTF skins: which nodes are joints and their inverse bind matrices.
    pub skins: Vec<Skin>,
    /// What the scene needs from the tracer.
    pub features: Features,
    /// Problems that did not stop loading (an optional extension ignored, a degenerate
    /// normal replaced), each naming the glTF element.
    pub warnings: Vec<String>,
}

impl Scene {
    /// Calls `visit(node, world)` for every node instance reachable from [`Scene::roots`],
    /// parents before children, with the node's local-to-world transform composed in double
    /// precision. A node reached along two paths is visited twice (instancing). Child indices
    /// out of range are skipped, and a hand-built scene with a cycle stops descending after
    /// as many levels as it has nodes (the loader refuses cycles outright).
    pub fn for_each_node_instance(&self, visit: impl FnMut(u32, &DMat4)) {
        self.for_each_node_instance_with(|i| self.nodes[i as usize].local, visit);
    }

    /// [`Scene::for_each_node_instance`] with each node's local transform given by
    /// `local(node)` (an animation pose) instead of [`Node::local`].
    pub fn for_each_node_instance_with(
        &self,
        local: impl Fn(u32) -> DMat4,
        mut visit: impl FnMut(u32, &DMat4),
    ) {
        let n = self.nodes.len();
        let mut stack: Vec<(u32, DMat4, usize)> = self
            .roots
            .iter()
            .rev()
            .map(|&r| (r, DMat4::IDENTITY, 0))
            .collect();
        while let Some((i, parent, depth)) = stack.pop() {
            let Some(node) = self.nodes.get(i as usize) else {
                continue;
            };
            if depth > n {
                continue;
            }
            let world = parent * local(i);
            visit(i, &world);
            for &c in node.children.iter().rev() {
                stack.push((c, world, depth + 1));
            }
        }
    }

    /// [`Scene::for_each_mesh_draw_with`] with the nodes' own transforms.
    pub fn for_each_mesh_draw(&self, visit: impl FnMut(u32, &DMat4)) {
        self.for_each_mesh_draw_with(|i| self.nodes[i as usize].local, visit);
    }

    /// Calls `visit(node, world)` for every time a mesh is drawn: each node instance with a
    /// mesh ([`Scene::for_each_node_instance_with`]), once per GPU instance
    /// ([`Node::gpu_instances`]), with the world transform of that draw.
    pub fn for_each_mesh_draw_with(
        &self,
        local: impl Fn(u32) -> DMat4,
        mut visit: impl FnMut(u32, &DMat4),
    ) {
        self.for_each_node_instance_with(local, |i, world| {
            let node = &self.nodes[i as usize];
            if node.mesh.is_none() {
                return;
            }
            for t in node.draw_transforms() {
                visit(i, &(*world * *t));
            }
        });
    }

    /// How many times the default scene draws a mesh (what
    /// [`Scene::for_each_mesh_draw_with`] visits), counted without visiting: a node with
    /// several parents is reached once per path, so a small graph can ask for more draws
    /// than memory holds. Saturates at `u64::MAX`.
    pub fn mesh_draw_count(&self) -> u64 {
        // paths[i]: the number of root-to-node paths reaching node i (its instances).
        let n = self.nodes.len();
        let mut paths = vec![0u64; n];
        for &r in &self.roots {
            if let Some(p) = paths.get_mut(r as usize) {
                *p = p.saturating_add(1);
            }
        }
        for i in self.topological_order() {
            let here = paths[i];
            for &c in &self.nodes[i].children {
                if let Some(p) = paths.get_mut(c as usize) {
                    *p = p.saturating_add(here);
                }
            }
        }
        self.nodes
            .iter()
            .zip(&paths)
            .filter(|(node, _)| node.mesh.is_some())
            .map(|(node, &p)| p.saturating_mul(node.draw_transforms().len() as u64))
            .fold(0, u64::saturating_add)
    }

    /// Nodes with every parent before its children (Kahn's algorithm); nodes on a cycle
    /// (which the loader refuses) are left out.
    fn topological_order(&self) -> Vec<usize> {
        let n = self.nodes.len();
        let mut parents = vec![0usize; n];
        for node in &self.nodes {
            for &c in &node.children {
                if let Some(p) = parents.get_mut(c as usize) {
                    *p += 1;
                }
            }
        }
        let mut ready: Vec<usize> = (0..n).filter(|&i| parents[i] == 0).collect();
        let mut order = Vec::with_capacity(n);
        while let Some(i) = ready.pop() {
            order.push(i);
            for &c in &self.nodes[i].children {
                let c = c as usize;
                if c < n {
                    parents[c] -= 1;
                    if parents[c] == 0 {
                        ready.push(c);
                    }
                }
            }
        }
        order
    }
}

/// A glTF node: a local transform and what hangs from it.
#[derive(Clone, Debug)]
pub struct Node {
    /// The node's name, if any.
    pub name: Option<String>,
    /// Transform from this node's space to its parent's, in double precision so that
    /// scenes far from the origin keep their detail when composed.
    pub local: DMat4,
    /// The same transform as translation, rotation and scale when the file gave it so
    /// (the only form animation channels may target); `None` for a matrix node.
    pub trs: Option<Trs>,
    /// Child nodes.
    pub children: Vec<u32>,
    /// Mesh drawn at this node.
    pub mesh: Option<u32>,
    /// Camera placed at this node.
    pub camera: Option<u32>,
    /// Punctual light placed at this node.
    pub light: Option<u32>,
    /// Skin deforming this node's mesh; the node's own transform then does not apply to
    /// the mesh (glTF: joints place the vertices).
    pub skin: Option<u32>,
    /// Morph weights overriding the mesh's default weights.
    pub weights: Option<Vec<f32>>,
    /// EXT_mesh_gpu_instancing: the mesh is drawn once per transform, each applied in the
    /// node's space before the node's own (world = node world · instance). Empty: drawn
    /// once. Cameras, lights and children of the node are not instanced.
    pub gpu_instances: Vec<DMat4>,
}

impl Node {
    /// The transforms its mesh is drawn with, relative to the node: its GPU instances, or
    /// the node itself once.
    pub fn draw_transforms(&self) -> &[DMat4] {
        if self.gpu_instances.is_empty() {
            std::slice::from_ref(&DMat4::IDENTITY)
        } else {
            &self.gpu_instances
        }
    }
}

impl Default for Node {
    fn default() -> Self {
        Self {
            name: None,
            local: DMat4::IDENTITY,
            trs: None,
            children: Vec::new(),
            mesh: None,
            camera: None,
            light: None,
            skin: None,
            weights: None,
            gpu_instances: Vec::new(),
        }
    }
}

/// A node transform in glTF's decomposed form.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Trs {
    /// Translation.
    pub translation: DVec3,
    /// Rotation, a unit quaternion.
    pub rotation: DQuat,
    /// Scale (may be zero or negative).
    pub scale: DVec3,
}

impl Default for Trs {
    fn default() -> Self {
        Self {
            translation: DVec3::ZERO,
            rotation: DQuat::IDENTITY,
            scale: DVec3::ONE,
        }
    }
}

impl Trs {
    /// The matrix T · R · S.
    pub fn matrix(&self) -> DMat4 {
        DMat4::from_scale_rotation_translation(self.scale, self.rotation, self.translation)
    }
}

/// A glTF skin.
#[derive(Clone, Debug, Default)]
pub struct Skin {
    /// The skin's name, if any.
    pub name: Option<String>,
    /// Joint nodes; vertex JOINTS_n values index this list.
    pub joints: Vec<u32>,
    /// Per joint, mesh space to the joint's bind space (identity when the file has none).
    pub inverse_bind: Vec<DMat4>,
}

/// A camera definition: a glTF camera without its placement.
#[derive(Clone, Debug)]
pub struct CameraDef {
    /// The camera's name, if any.
    pub name: Option<String>,
    /// Its projection.
    pub projection: Projection,
}

/// One glTF mesh: its triangle primitives and one BVH over all of them.
#[derive(Debug)]
pub struct Mesh {
    /// The mesh's name, if any.
    pub name: Option<String>,
    /// Primitives; triangle `i` of the mesh belongs to the primitive whose range holds it.
    pub primitives: Vec<Primitive>,
    /// `first_triangle[p]` is the mesh-wide index of primitive `p`'s first triangle.
    pub first_triangle: Vec<u32>,
    /// The primitive of each mesh-wide triangle, so that a hit finds its own without a
    /// search (33 instructions a hit on the Cornell box's walls); empty when the mesh has
    /// one primitive.
    primitive_of: Vec<u32>,
    /// The acceleration structure over every triangle of the mesh.
    pub bvh: MeshBvh,
    /// Default morph target weights (glTF `mesh.weights`); empty without morph targets.
    pub weights: Vec<f32>,
}

/// One triangle primitive with its vertex attributes, all in the mesh's object space.
#[derive(Clone, Debug, Default)]
pub struct Primitive {
    /// Vertex positions.
    pub positions: Vec<Vec3>,
    /// Vertex normals; empty when the primitive has none (flat shading).
    pub normals: Vec<Vec3>,
    /// Vertex tangents (xyz, w = bitangent sign); empty when not needed or absent.
    pub tangents: Vec<Vec4>,
    /// TEXCOORD_0 and TEXCOORD_1; empty when absent.
    pub uvs: [Vec<Vec2>; 2],
    /// COLOR_0 as linear RGBA; empty when absent.
    pub colors: Vec<Vec4>,
    /// Triangles as vertex indices.
    pub indices: Vec<[u32; 3]>,
    /// Index into [`Scene::materials`].
    pub material: u32,
    /// Skinning influences, one entry per JOINTS_n/WEIGHTS_n pair; empty when unskinned.
    pub joint_sets: Vec<JointSet>,
    /// Morph targets, in the order `weights` refer to them.
    pub targets: Vec<MorphTarget>,
}

/// One JOINTS_n/WEIGHTS_n pair: four joint indices (into the skin's joint list) and their
/// weights per vertex.
#[derive(Clone, Debug, Default)]
pub struct JointSet {
    /// Joint indices per vertex.
    pub joints: Vec<[u16; 4]>,
    /// Weights per vertex.
    pub weights: Vec<[f32; 4]>,
}

/// One morph target: per-vertex displacements; an attribute the target lacks is empty.
#[derive(Clone, Debug, Default)]
pub struct MorphTarget {
    /// POSITION displacements.
    pub positions: Vec<Vec3>,
    /// NORMAL displacements.
    pub normals: Vec<Vec3>,
    /// TANGENT displacements (xyz only, as glTF defines).
    pub tangents: Vec<Vec3>,
}

impl Mesh {
    /// Builds the mesh's BVH over all its primitives' triangles.
    pub fn new(name: Option<String>, primitives: Vec<Primitive>) -> Self {
        let mut first_triangle = Vec::with_capacity(primitives.len());
        let mut triangles = Vec::new();
        for prim in &primitives {
            first_triangle.push(triangles.len() as u32);
            triangles.extend(prim.indices.iter().map(|&[a, b, c]| {
                [
                    prim.positions[a as usize],
                    prim.positions[b as usize],
                    prim.positions[c as usize],
                ]
            }));
        }
        let bvh = MeshBvh::build(&triangles);
        let primitive_of = if primitives.len() > 1 {
            (0..primitives.len() as u32)
                .zip(&primitives)
                .flat_map(|(p, prim)| std::iter::repeat_n(p, prim.indices.len()))
                .collect()
        } else {
            Vec::new()
        };
        Self {
            name,
            primitives,
            first_triangle,
            primitive_of,
            bvh,
            weights: Vec::new(),
        }
    }

    /// The primitive holding mesh-wide triangle `tri`, and the triangle's index inside it.
    #[inline(always)]
    pub fn locate(&self, tri: u32) -> (usize, usize) {
        let p = if self.primitive_of.is_empty() {
            0
        } else {
            self.primitive_of[tri as usize] as usize
        };
        (p, (tri - self.first_triangle[p]) as usize)
    }

    /// Number of triangles over all primitives.
    pub fn triangle_count(&self) -> usize {
        self.primitives.iter().map(|p| p.indices.len()).sum()
    }
}

/// What a scene needs from the tracer, so that it pays only for that.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Features {
    /// Any material samples a texture.
    pub textures: bool,
    /// Any material transmits light.
    pub transmission: bool,
    /// Any material is alpha-masked (cut-outs in shadow rays too).
    pub alpha_mask: bool,
    /// Any material emits light.
    pub emissive: bool,
    /// The scene has punctual lights.
    pub punctual_lights: bool,
    /// The environment emits light.
    pub environment: bool,
    /// Any primitive uses a normal map.
    pub normal_maps: bool,
    /// The scene has animations (in a prepared frame: something moves inside the shutter).
    pub animation: bool,
    /// A node draws a skinned mesh.
    pub skinning: bool,
    /// A mesh has morph targets.
    pub morphing: bool,
    /// Any material has a clear coat (KHR_materials_clearcoat).
    pub clearcoat: bool,
    /// Any material has a sheen (KHR_materials_sheen).
    pub sheen: bool,
    /// Any transmitting material bounds a volume (KHR_materials_volume).
    pub volume: bool,
    /// Any material has an iridescent film (KHR_materials_iridescence).
    pub iridescence: bool,
    /// Any material refracts negatively (TESSERA_materials_metamaterial).
    pub metamaterial: bool,
    /// Any material's diffuse base transmits (KHR_materials_diffuse_transmission).
    pub diffuse_transmission: bool,
    /// Any material is anisotropic (KHR_materials_anisotropy).
    pub anisotropy: bool,
    /// Any refracting volume bends light by wavelength (KHR_materials_dispersion).
    pub dispersion: bool,
    /// A light or an emissive material has its own spectrum (TESSERA_lights_spectrum).
    pub light_spectra: bool,
    /// Any material fluoresces (TESSERA_materials_fluorescence).
    pub fluorescence: bool,
}

impl Features {
    /// Adds what `m` needs from the tracer (its normal map aside: whether one counts
    /// depends on the primitive's tangents).
    pub fn add_material(&mut self, m: &Material) {
        self.textures |= m.has_textures();
        self.transmission |= m.transmission > 0.0;
        self.alpha_mask |= m.alpha_mode != crate::material::AlphaMode::Opaque;
        self.emissive |= m.is_emissive();
        self.clearcoat |= m.clearcoat > 0.0;
        self.sheen |= m.has_sheen();
        self.volume |= m.is_volume();
        self.iridescence |= m.iridescence > 0.0;
        self.metamaterial |= m.metamaterial.is_some();
        self.diffuse_transmission |= m.diffuse_transmission > 0.0;
        self.anisotropy |= m.is_anisotropic();
        self.dispersion |= m.is_dispersive();
        self.light_spectra |= m.emission_spectrum.is_some() && m.is_emissive();
        self.fluorescence |= m.is_fluorescent();
    }

    /// Whether a feature depends on wavelength, so that the scene renders on the spectral
    /// path whatever the settings ask.
    pub fn needs_spectral(&self) -> bool {
        self.dispersion || self.light_spectra || self.fluorescence
    }

    /// Names of the features in use, for summaries and EXR metadata.
    pub fn names(&self) -> Vec<&'static str> {
        let all = [
            (self.textures, "textures"),
            (self.transmission, "transmission"),
            (self.alpha_mask, "alpha-mask"),
            (self.emissive, "emissive"),
            (self.punctual_lights, "punctual-lights"),
            (self.environment, "environment"),
            (self.normal_maps, "normal-maps"),
            (self.animation, "animation"),
            (self.skinning, "skinning"),
            (self.morphing, "morphing"),
            (self.clearcoat, "clearcoat"),
            (self.sheen, "sheen"),
            (self.volume, "volume"),
            (self.iridescence, "iridescence"),
            (self.metamaterial, "metamaterial"),
            (self.diffuse_transmission, "diffuse-transmission"),
            (self.anisotropy, "anisotropy"),
            (self.dispersion, "dispersion"),
            (self.light_spectra, "light-spectra"),
            (self.fluorescence, "fluorescence"),
        ];
        all.iter().filter(|(on, _)| *on).map(|(_, n)| *n).collect()
    }
}

impl Primitive {
    /// Vertex indices of triangle `t`.
    pub fn triangle(&self, t: usize) -> [usize; 3] {
        self.indices[t].map(|i| i as usize)
    }

    /// Both texture coordinate sets at barycentrics (b1, b2) of triangle `t`
    /// (zero for a set the primitive lacks).
    pub fn uvs_at(&self, t: usize, b1: f32, b2: f32) -> [Vec2; 2] {
        let [i0, i1, i2] = self.triangle(t);
        [0, 1].map(|s| match self.uvs[s].as_slice() {
            [] => Vec2::ZERO,
            uv => barycentric(uv[i0], uv[i1], uv[i2], b1, b2),
        })
    }

    /// Vertex colour at barycentrics (b1, b2) of triangle `t` (white without COLOR_0).
    pub fn color_at(&self, t: usize, b1: f32, b2: f32) -> Vec4 {
        let [i0, i1, i2] = self.triangle(t);
        match self.colors.as_slice() {
            [] => Vec4::ONE,
            c => barycentric(c[i0], c[i1], c[i2], b1, b2),
        }
    }

    /// Object-space geometric normal of triangle `t` by its winding (not normalised).
    pub fn face_normal(&self, t: usize) -> Vec3 {
        let [a, b, c] = self.triangle(t).map(|i| self.positions[i]);
        (b - a).cross(c - a)
    }
}

/// Builds a scene in code: the demo scene, tests and benchmarks use it.
#[derive(Debug, Default)]
pub struct SceneBuilder {
    scene: Scene,
}

impl SceneBuilder {
    /// Adds a material and returns its index.
    pub fn material(&mut self, m: Material) -> u32 {
        self.scene.materials.push(m);
        self.scene.materials.len() as u32 - 1
    }

    fn root(&mut self, node: Node) -> u32 {
        self.scene.nodes.push(node);
        let id = self.scene.nodes.len() as u32 - 1;
        self.scene.roots.push(id);
        id
    }

    /// Adds a mesh and a root node drawing it with transform `local`; returns the node.
    pub fn mesh(&mut self, name: &str, primitives: Vec<Primitive>, local: DMat4) -> u32 {
        self.scene
            .meshes
            .push(Mesh::new(Some(name.into()), primitives));
        let mesh = Some(self.scene.meshes.len() as u32 - 1);
        self.root(Node {
            name: Some(name.into()),
            local,
            mesh,
            ..Default::default()
        })
    }

    /// Adds a mesh and a root node drawing it, placed by `trs` (the form animations can
    /// drive); returns the node.
    pub fn mesh_trs(&mut self, name: &str, primitives: Vec<Primitive>, trs: Trs) -> u32 {
        let node = self.mesh(name, primitives, trs.matrix());
        self.scene.nodes[node as usize].trs = Some(trs);
        node
    }

    /// Adds an animation.
    pub fn animation(&mut self, animation: Animation) {
        self.scene.animations.push(animation);
    }

    /// Adds a camera placed by a root node with transform `local`; returns the node.
    pub fn camera(&mut self, camera: CameraDef, local: DMat4) -> u32 {
        let name = camera.name.clone();
        self.scene.cameras.push(camera);
        let camera = Some(self.scene.cameras.len() as u32 - 1);
        self.root(Node {
            name,
            local,
            camera,
            ..Default::default()
        })
    }

    /// Adds a punctual light placed by a root node with transform `local`.
    pub fn light(&mut self, light: PunctualLight, local: DMat4) -> u32 {
        self.scene.lights.push(light);
        let light = Some(self.scene.lights.len() as u32 - 1);
        self.root(Node {
            local,
            light,
            ..Default::default()
        })
    }

    /// Adds a punctual light of its own spectrum (TESSERA_lights_spectrum), its colour
    /// filtering that spectrum, placed by a root node with transform `local`.
    pub fn light_with_spectrum(
        &mut self,
        light: PunctualLight,
        spectrum: SpectrumShape,
        local: DMat4,
    ) -> u32 {
        let node = self.light(light, local);
        let index = self.scene.lights.len() as u32 - 1;
        self.scene.light_spectra.insert(index, spectrum);
        node
    }

    /// Sets the environment.
    pub fn environment(&mut self, environment: Environment) {
        self.scene.environment = Some(environment);
    }

    /// The scene, with its feature flags derived from what was added.
    pub fn finish(mut self) -> Scene {
        let s = &self.scene;
        let mats = &s.materials;
        let mut features = Features {
            punctual_lights: !s.lights.is_empty(),
            light_spectra: !s.light_spectra.is_empty(),
            environment: s.environment.as_ref().is_some_and(|e| !e.is_black()),
            normal_maps: mats.iter().any(|m| m.normal_texture.is_some()),
            animation: !s.animations.is_empty(),
            skinning: s.nodes.iter().any(|n| n.skin.is_some()),
            morphing: s.meshes.iter().any(|m| !m.weights.is_empty()),
            ..Features::default()
        };
        mats.iter().for_each(|m| features.add_material(m));
        features.emissive |= crate::animation::animates_emission(s);
        self.scene.features = features;
        self.scene
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A primitive of `n` triangles, each its own three vertices, the first at `x`.
    fn strip(n: usize, x: f32) -> Primitive {
        Primitive {
            positions: (0..3 * n)
                .map(|i| Vec3::new(x + i as f32, (i % 3) as f32, 0.0))
                .collect(),
            indices: (0..n as u32)
                .map(|t| [3 * t, 3 * t + 1, 3 * t + 2])
                .collect(),
            ..Primitive::default()
        }
    }

    #[test]
    fn every_triangle_is_located_in_its_primitive() {
        // An empty primitive between two others, and a mesh of one primitive.
        let mesh = Mesh::new(None, vec![strip(2, 0.0), strip(0, 10.0), strip(3, 20.0)]);
        let found: Vec<_> = (0..5).map(|tri| mesh.locate(tri)).collect();
        assert_eq!(found, [(0, 0), (0, 1), (2, 0), (2, 1), (2, 2)]);
        let single = Mesh::new(None, vec![strip(4, 0.0)]);
        assert_eq!(single.locate(3), (0, 3));
    }
}

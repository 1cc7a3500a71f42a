//! The loaded scene: glTF's node graph, meshes, materials, textures, cameras and lights,
//! converted once into the tracer's own types. A [`Scene`] is independent of time and
//! camera; [`crate::render::PreparedFrame`] flattens it for one frame.

use glam::{DMat4, Vec2, Vec3, Vec4};

use crate::bvh::MeshBvh;
use crate::camera::Projection;
use crate::light::{Environment, PunctualLight};
use crate::material::Material;
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
    /// Light arriving from infinitely far away.
    pub environment: Environment,
    /// What the scene needs from the tracer.
    pub features: Features,
    /// Problems that did not stop loading (an optional extension ignored, a degenerate
    /// normal replaced), each naming the glTF element.
    pub warnings: Vec<String>,
}

/// A glTF node: a local transform and what hangs from it.
#[derive(Clone, Debug)]
pub struct Node {
    /// The node's name, if any.
    pub name: Option<String>,
    /// Transform from this node's space to its parent's, in double precision so that
    /// scenes far from the origin keep their detail when composed.
    pub local: DMat4,
    /// Child nodes.
    pub children: Vec<u32>,
    /// Mesh drawn at this node.
    pub mesh: Option<u32>,
    /// Camera placed at this node.
    pub camera: Option<u32>,
    /// Punctual light placed at this node.
    pub light: Option<u32>,
}

impl Default for Node {
    fn default() -> Self {
        Self {
            name: None,
            local: DMat4::IDENTITY,
            children: Vec::new(),
            mesh: None,
            camera: None,
            light: None,
        }
    }
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
    /// The acceleration structure over every triangle of the mesh.
    pub bvh: MeshBvh,
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
}

impl Mesh {
    /// Builds the mesh's BVH over all its primitives' triangles.
    pub fn new(name: Option<String>, primitives: Vec<Primitive>) -> Self {
        let mut first_triangle = Vec::with_capacity(primitives.len());
        let mut triangles = Vec::new();
        for prim in &primitives {
            first_triangle.push(triangles.len() as u32);
            triangles.extend(prim.indices.iter().map(|&[a, b, c]| {
                [prim.positions[a as usize], prim.positions[b as usize], prim.positions[c as usize]]
            }));
        }
        let bvh = MeshBvh::build(&triangles);
        Self { name, primitives, first_triangle, bvh }
    }

    /// The primitive holding mesh-wide triangle `tri`, and the triangle's index inside it.
    pub fn locate(&self, tri: u32) -> (usize, usize) {
        let p = self.first_triangle.partition_point(|&f| f <= tri) - 1;
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
}

impl Features {
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
        ];
        all.iter().filter(|(on, _)| *on).map(|(_, n)| *n).collect()
    }
}

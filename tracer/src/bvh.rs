//! Bounding volume hierarchies: a binned-SAH BVH per mesh (built once, shared by every
//! instance) and a top-level BVH over the instances of a prepared frame.
//!
//! | module | what it holds |
//! |---|---|
//! | `build` | the binned SAH builder shared by both levels (Wald 2007) |
//! | `node` | the 32-byte node, the robust slab test (Ize 2013) and the ordered traversal |
//! | `mesh` | [`MeshBvh`]: triangles in object space, reordered into the BVH's own array |
//! | `instance` | [`Instance`] and [`SceneBvh`]: placed meshes and the BVH over them |
//!
//! Both levels share one flat node layout in which a node's two children are adjacent and
//! always stored after it. That keeps the door open for what motion blur and skinning will
//! need: refitting is one reverse pass over the nodes, and an instance with several
//! transforms over the shutter only changes how [`Instance::object_ray`] and
//! [`Instance::bounds`] are computed, not the traversal.

mod build;
mod instance;
mod mesh;
mod node;

pub use instance::{Instance, SceneBvh};
pub use mesh::MeshBvh;

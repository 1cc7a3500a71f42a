//! Bounding volume hierarchies: a binned-SAH BVH per mesh (built once, shared by every
//! instance) and a top-level BVH over the instances of a prepared frame, both with motion
//! blur where the scene moves.
//!
//! | module | what it holds |
//! |---|---|
//! | `build` | the binned SAH builder shared by both levels (Wald 2007) |
//! | `node` | the 32-byte node, per-step boxes, the slab test (Ize 2013), the traversal |
//! | `wide` | the binary tree collapsed eight-wide, its slab test in SIMD lanes, its traversal |
//! | `mesh` | [`MeshBvh`]: object-space triangles in the BVH's own order, at 1..S steps |
//! | `instance` | [`Instance`], [`Placement`], [`SceneBvh`]: placed meshes, the BVH over them |
//! | `motion` | the shutter-time convention; [`MotionTransform`] (lerp, slerp, lerp) |
//! | `huge_pages` | large arrays moved onto 2 MiB pages, which few TLB entries cover |
//!
//! Both levels are built as binary trees in one flat layout, a node's two children adjacent
//! and stored after it, and queried as those trees collapsed eight-wide: slab tests in
//! SIMD lanes check a node's eight children. The top level lists most instances whole, but
//! a large static one around others (a room around its furniture) by the lanes of its
//! mesh's root, each with its own world box, so that rays enter only the walls they reach.
//!
//! Motion blur: time is the normalised shutter position in [0, 1], and motion is given at
//! `S` evenly spaced steps (step `k` at `k / (S - 1)`).
//! - A deforming mesh ([`MeshBvh::build_motion`]) keeps its vertices at every step and
//!   its binary tree with every node's box at every step, beside the 32-byte nodes; a ray
//!   at a time sees triangles and boxes linearly interpolated between the two steps around
//!   it.
//! - A moving instance ([`Instance::moving`]) carries a [`MotionTransform`]: translation,
//!   rotation and stretch interpolated separately (lerp, slerp, lerp). Its bounds cover the
//!   whole shutter, so the top level is an ordinary static BVH; rays enter the mesh through
//!   the placement at their time ([`Instance::placement`]).
//! - Whether anything moves is decided when the hierarchy is built ([`SceneBvh::has_motion`],
//!   [`MeshBvh::has_motion`]) and picks, once per query, one of two loops monomorphised by a
//!   const parameter: a static scene runs the same loop as if motion did not exist.

mod build;
mod huge_pages;
mod instance;
mod mesh;
mod motion;
mod node;
mod wide;

pub use instance::{Instance, Placement, SceneBvh};
pub use mesh::MeshBvh;
pub use motion::{MotionTransform, Segment};

pub(crate) use huge_pages::on_huge_pages;

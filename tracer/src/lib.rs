//! Tessera's path tracer core: no network, no async, no database.
//!
//! | module | what it holds |
//! |---|---|
//! | [`scene`] | the loaded scene: nodes, meshes, materials, cameras, lights, skins |
//! | [`animation`] | glTF animation samplers evaluated into a pose at any time, and KHR_animation_pointer's lights and materials |
//! | [`deform`] | morph targets and linear blend skinning of a primitive for one pose |
//! | [`loader`] | glTF 2.0 (.gltf/.glb) into a [`scene::Scene`], with errors naming the element |
//! | [`demo`] | the built-in scenes, authored in code: the demo, the Cornell box, the spectral showcase |
//! | [`export`] | a [`scene::Scene`] into a self-contained GLB that the loader reads back |
//! | [`shapes`] | quads, cubes and spheres as triangle primitives |
//! | [`geometry`] | rays, hits, boxes, shading frames, the self-intersection offset |
//! | [`triangle`] | the watertight ray/triangle test |
//! | [`math`] | sine, power and the rest, the same bits on every machine |
//! | [`bvh`] | SAH BVH per mesh and the top-level BVH over instances |
//! | [`simd`] | which compiled copy of the hot loops runs: AVX's where the CPU has it, else SSE2's |
//! | [`camera`] | perspective and orthographic cameras |
//! | [`texture`] | images, samplers, KHR_texture_transform, sRGB |
//! | [`material`] | glTF materials and their evaluation at a hit |
//! | [`bsdf`] | the glTF metallic-roughness BSDF, GGX with visible-normal sampling |
//! | [`light`] | punctual, emissive-triangle and environment lights; the light sampler |
//! | [`sampler`] | random numbers as a pure function of (pixel, sample, dimension, frame, seed) |
//! | [`integrator`] | unidirectional path tracing with NEE and MIS, in RGB or at four sampled wavelengths |
//! | [`spectrum`] | light per wavelength: the CIE observer, RGB lifted to spectra, hero wavelengths, light spectra, fluorescent paint |
//! | [`film`] | tile buffers: beauty, albedo, normal, depth |
//! | [`motion`] | the shutter, motion steps, meshes deformed for one frame |
//! | [`limits`] | the bounds of a render request: image size, samples, depth, fps, motion |
//! | [`settings`] | what a render is asked for: frame options, sampling settings, noise target |
//! | `prepare` | [`render::prepare_frame`]: the scene posed, placed and built for one frame |
//! | [`frame`] | the prepared frame and its ray queries (closest hit, occlusion, the triangle hit) |
//! | [`render`] | the one entry point, [`render::render_tile`] |
//! | [`output`] | multi-layer EXR files and ACES-tone-mapped PNG previews |
//!
//! Units follow the glTF specs: emission in nits (cd/m²) is radiance, point and spot
//! lights are in candela (radiant intensity), directional lights in lux (irradiance). The
//! tracer treats these photometric numbers directly as its radiometric units, so a white
//! Lambertian plane under a 1 lux directional light at normal incidence reflects radiance
//! 1/π.
#![warn(missing_docs)]
// `!(x > 0.0)` is how the tracer rejects NaN together with the values it guards against;
// rewriting it as `x <= 0.0` would let NaN through.
#![allow(clippy::neg_cmp_op_on_partial_ord)]
// Unit tests compare against the platform's maths and build scenes with glam's rotations.
#![cfg_attr(test, allow(clippy::disallowed_methods))]

pub mod animation;
pub mod bsdf;
pub mod bvh;
pub mod camera;
pub mod deform;
pub mod demo;
pub mod export;
pub mod film;
pub mod frame;
pub mod geometry;
pub mod integrator;
pub mod light;
pub mod limits;
pub mod loader;
pub mod material;
pub mod math;
pub mod motion;
pub mod output;
mod prepare;
pub mod render;
pub mod sampler;
pub mod scene;
pub mod settings;
pub mod shapes;
pub mod simd;
pub mod spectrum;
#[cfg(test)]
mod test_rng;
pub mod texture;
pub mod triangle;

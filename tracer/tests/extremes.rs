//! Numerical stability at the extremes: a matrix of scenes pushed to extreme scales,
//! angles, materials, lights, geometry, path lengths, times and image shapes. Every case
//! asserts that no pixel is NaN or infinite and that the result is within a stated
//! tolerance of the expected value (analytic, or the same scene at a normal setting).
//! Each case prints what it measured, so `cargo test -p tracer --test extremes --
//! --nocapture` gives the table of the closing note.

// Test scenes and closed forms use the platform's maths; tracer::math is for the tracer.
#![allow(clippy::disallowed_methods)]

mod common;

#[path = "extremes/support.rs"]
mod support;

#[path = "extremes/scale.rs"]
mod scale;

#[path = "extremes/geometry.rs"]
mod geometry;

#[path = "extremes/materials.rs"]
mod materials;

#[path = "extremes/lights.rs"]
mod lights;

#[path = "extremes/time_and_image.rs"]
mod time_and_image;

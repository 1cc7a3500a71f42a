//! The bounds of a render request, defined once. The tracer refuses frame options past
//! them ([`FrameOptions::check`](crate::settings::FrameOptions::check)); `tessera render`
//! and the server's job specs refuse the same numbers at their input, naming the flag or
//! the field, so a job the tracer would refuse is never accepted.

/// Longest side of an image, pixels.
pub const MAX_RESOLUTION: u32 = 16_384;
/// Samples per pixel.
pub const MAX_SPP: u32 = 1_000_000;
/// Bounces.
pub const MAX_DEPTH: u32 = 1_024;
/// Frames per second.
pub const MAX_FPS: f64 = 1_000.0;
/// Motion steps across an open shutter.
pub const MAX_MOTION_STEPS: u32 = 64;
/// Largest |open| or |close| of a shutter, in frames: a shutter spanning more than this is
/// a mistake, not a look.
pub const MAX_SHUTTER_FRAMES: f64 = 1.0e4;

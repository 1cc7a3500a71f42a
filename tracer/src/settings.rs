//! What a render is asked for: the frame's options (time, image size, camera,
//! environment), the sampling settings, adaptive sampling's target, and the errors of
//! preparing a frame.

use crate::animation::AnimationChoice;
use crate::light::Environment;
use crate::limits::{MAX_FPS, MAX_MOTION_STEPS, MAX_RESOLUTION};
use crate::motion::Shutter;

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

impl FrameOptions {
    /// Checks the numbers against [`crate::limits`] before any work.
    pub fn check(&self) -> Result<(), RenderError> {
        let side = 1..=MAX_RESOLUTION;
        if !side.contains(&self.width) || !side.contains(&self.height) {
            return Err(RenderError::ImageSize(self.width, self.height));
        }
        if !(self.fps.is_finite() && self.fps > 0.0 && self.fps <= MAX_FPS) {
            return Err(RenderError::Time(format!(
                "fps {} must be above 0 and at most {MAX_FPS}",
                self.fps
            )));
        }
        self.shutter.validate().map_err(RenderError::Time)?;
        if let Some(n) = self.motion_steps {
            if !(1..=MAX_MOTION_STEPS).contains(&n) {
                return Err(RenderError::Time(format!(
                    "motion steps {n} must be between 1 and {MAX_MOTION_STEPS}"
                )));
            }
        }
        Ok(())
    }
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
    /// Carry light at four sampled wavelengths rather than in RGB (the spectral path). A
    /// scene with a wavelength-dependent feature ([`crate::scene::Features::needs_spectral`])
    /// takes it whatever this says; any other converges to the same image with more
    /// colour noise, which lets the two paths be compared.
    pub spectral: bool,
    /// The same sampling pattern on every frame: the frame number leaves the random
    /// numbers' key (the seed stays in it), so an animation's noise stays in place from
    /// frame to frame instead of changing, which a per-frame denoiser turns into a steady
    /// image rather than flicker (production's fix; Blender's "animated seed" off). Each
    /// frame's own pattern by default.
    pub fixed_pattern: bool,
    /// Clamps light that reaches the camera after two or more surfaces (every bounce's
    /// light but the first surface's direct light) to at most this in its largest RGB
    /// channel, per path contribution: Cycles' "clamp indirect". It darkens what it
    /// clamps (bias) to remove the fireflies of rare bright paths, such as caustics seen
    /// on a diffuse wall; `tessera bench clamp` measures both. `None` (the default)
    /// clamps nothing.
    pub clamp_indirect: Option<f32>,
}

impl RenderSettings {
    /// The defaults, for constants (`..RenderSettings::DEFAULT`): 8 bounces, seed 0, no
    /// adaptive sampling, Russian roulette from the third bounce.
    pub const DEFAULT: RenderSettings = RenderSettings {
        max_depth: 8,
        seed: 0,
        noise: None,
        russian_roulette: Some(3),
        spectral: false,
        fixed_pattern: false,
        clamp_indirect: None,
    };
}

impl Default for RenderSettings {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// Checks a [`RenderSettings::clamp_indirect`]: a finite number above zero (zero would
/// drop every bounce's light; use a smaller `max_depth` for that).
pub fn check_clamp(limit: f32) -> Result<(), String> {
    if limit.is_finite() && limit > 0.0 {
        Ok(())
    } else {
        Err(format!("clamp {limit} must be a finite number above 0"))
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
    /// A side of the image is zero or past [`MAX_RESOLUTION`].
    #[error("image size {0}x{1}: each side must be 1 to {MAX_RESOLUTION} pixels")]
    ImageSize(u32, u32),
    /// The frame rate, shutter or motion steps are unusable.
    #[error("{0}")]
    Time(String),
    /// The animation asked for does not exist.
    #[error("animation {0}")]
    Animation(String),
}

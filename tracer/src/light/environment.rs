//! Equirectangular environment maps: loading, lookup and importance sampling.
//!
//! # Orientation
//! Directions are in glTF world space (+Y up, right-handed). For a unit direction
//! `d` in the map's own frame (the world frame unless [`EnvironmentMap::with_rotation`]
//! turned the map):
//!
//! * `θ = acos(d.y)` ∈ [0, π], `v = θ / π`: the top row of the image (v = 0) is straight
//!   up (+Y), the bottom row straight down.
//! * `φ = atan2(d.z, d.x)` ∈ (−π, π], `u = 0.5 + φ / 2π`: the centre of the image
//!   (u = 0.5) looks along +X, u = 0.75 along +Z, u = 0.25 along −Z (glTF's default
//!   camera view), and the left/right edges along −X.
//!
//! and back: `d = (sin θ cos φ, cos θ, sin θ sin φ)`. This is the convention of Blender and
//! three.js for a scene exported to glTF, so a panorama lights a scene as it does there.
//!
//! # Lookup and sampling
//! Lookup is nearest-pixel, so the radiance and the sampling density are constant on the
//! same cells: with bilinear filtering a pixel of zero luminance could still return light
//! near a bright neighbour, where the sampler would never go. Directions are sampled with
//! a 2D piecewise-constant distribution over pixels weighted by luminance × sin θ of the
//! pixel's row centre (pbrt-v4), and the density in (u, v) is converted to solid angle
//! exactly: `pdf(ω) = pdf(u, v) / (2π² sin θ)`, with θ of the direction itself.

use std::path::Path;
use std::sync::Arc;

use glam::{Quat, Vec2, Vec3};

use super::distribution::Distribution2D;
use super::{luminance, LightError};
use crate::math;

/// An equirectangular high-dynamic-range image of the light arriving from infinitely far
/// away, in linear RGB (nits). Cloning is cheap: the pixels and sampling tables are shared.
#[derive(Clone)]
pub struct EnvironmentMap {
    data: Arc<MapData>,
    /// Map frame → world.
    rotation: Quat,
}

struct MapData {
    width: usize,
    height: usize,
    /// Row by row from the top (v = 0), `pixels[y * width + x]`.
    pixels: Vec<Vec3>,
    distribution: Distribution2D,
    /// ∫ luminance(L) dω over the sphere (sr·nits).
    luminance_integral: f32,
}

impl std::fmt::Debug for EnvironmentMap {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("EnvironmentMap")
            .field("width", &self.data.width)
            .field("height", &self.data.height)
            .field("rotation", &self.rotation)
            .finish_non_exhaustive()
    }
}

impl EnvironmentMap {
    /// Loads the first RGB(A) layer of an OpenEXR file (alpha is ignored).
    pub fn load(path: impl AsRef<Path>) -> Result<Self, LightError> {
        let path = path.as_ref();
        let image = exr::prelude::read_first_rgba_layer_from_file(path, create_pixels, set_pixel)
            .map_err(|source| LightError::Exr {
            path: path.display().to_string(),
            source,
        })?;
        let (width, height, pixels) = image.layer_data.channel_data.pixels;
        Self::from_pixels(width, height, pixels)
    }

    /// Decodes the first RGB(A) layer of an OpenEXR file held in memory (a scene shipped
    /// as one package carries its environment this way). `name` is used in errors.
    pub fn decode(bytes: &[u8], name: &str) -> Result<Self, LightError> {
        use exr::prelude::*;
        let image = read()
            .no_deep_data()
            .largest_resolution_level()
            .rgba_channels(create_pixels, set_pixel)
            .first_valid_layer()
            .all_attributes()
            .from_buffered(std::io::Cursor::new(bytes))
            .map_err(|source| LightError::Exr {
                path: name.to_string(),
                source,
            })?;
        let (width, height, pixels) = image.layer_data.channel_data.pixels;
        Self::from_pixels(width, height, pixels)
    }

    /// A map from `width` × `height` linear RGB pixels, row by row from the top. Negative
    /// and non-finite channel values are replaced by 0.
    pub fn from_pixels(width: usize, height: usize, pixels: Vec<Vec3>) -> Result<Self, LightError> {
        if width == 0 || height == 0 || width.checked_mul(height) != Some(pixels.len()) {
            return Err(LightError::Size {
                width,
                height,
                pixels: pixels.len(),
            });
        }
        let mut pixels = pixels;
        for p in &mut pixels {
            *p = Vec3::from_array(
                p.to_array()
                    .map(|c| if c.is_finite() && c > 0.0 { c } else { 0.0 }),
            );
        }
        // Sampling weights: luminance × sin θ of the row centre. Rows have equal Δθ, so
        // the sin θ factor makes the weight proportional to each pixel's solid angle.
        let mut func = Vec::with_capacity(width * height);
        let mut luminance_integral = 0.0f64;
        let d_phi = 2.0 * std::f64::consts::PI / width as f64;
        for y in 0..height {
            let theta = std::f32::consts::PI * (y as f32 + 0.5) / height as f32;
            let sin_theta = math::sin(theta);
            let theta0 = std::f64::consts::PI * y as f64 / height as f64;
            let theta1 = std::f64::consts::PI * (y + 1) as f64 / height as f64;
            let row_solid_angle = d_phi * (math::cos_f64(theta0) - math::cos_f64(theta1));
            for x in 0..width {
                let l = luminance(pixels[y * width + x]);
                func.push(l * sin_theta);
                luminance_integral += l as f64 * row_solid_angle;
            }
        }
        let distribution = Distribution2D::new(&func, width, height);
        Ok(Self {
            data: Arc::new(MapData {
                width,
                height,
                pixels,
                distribution,
                luminance_integral: luminance_integral as f32,
            }),
            rotation: Quat::IDENTITY,
        })
    }

    /// The same map turned by `rotation` (map frame → world): a direction `d` of the
    /// map's frame (see the module docs) arrives from `rotation * d` in the world.
    pub fn with_rotation(mut self, rotation: Quat) -> Self {
        self.rotation = rotation.normalize();
        self
    }

    /// The rotation from the map's frame to the world.
    pub fn rotation(&self) -> Quat {
        self.rotation
    }

    /// Width in pixels.
    pub fn width(&self) -> usize {
        self.data.width
    }

    /// Height in pixels.
    pub fn height(&self) -> usize {
        self.data.height
    }

    /// The pixel at column `x`, row `y` (from the top).
    pub fn pixel(&self, x: usize, y: usize) -> Vec3 {
        self.data.pixels[y * self.data.width + x]
    }

    /// Equirectangular coordinates (u, v) ∈ [0, 1]² of the world direction `dir` (need not
    /// be unit; zero gives (0.5, 0.5)).
    pub fn direction_to_uv(&self, dir: Vec3) -> Vec2 {
        let d = math::normalize_or(self.rotation.inverse() * dir, Vec3::ZERO);
        let theta = math::acos(d.y.clamp(-1.0, 1.0));
        let phi = math::atan2(d.z, d.x);
        Vec2::new(
            0.5 + phi / (2.0 * std::f32::consts::PI),
            theta / std::f32::consts::PI,
        )
    }

    /// The unit world direction of equirectangular coordinates (u, v).
    pub fn uv_to_direction(&self, uv: Vec2) -> Vec3 {
        self.rotation * local_direction(uv).0
    }

    /// Radiance arriving from the world direction `dir` (nearest pixel).
    pub fn radiance(&self, dir: Vec3) -> Vec3 {
        let uv = self.direction_to_uv(dir);
        let x = ((uv.x * self.data.width as f32) as usize).min(self.data.width - 1);
        let y = ((uv.y * self.data.height as f32) as usize).min(self.data.height - 1);
        self.pixel(x, y)
    }

    /// ∫ luminance(L(ω)) dω over the sphere: the map's total, for power estimates.
    pub fn luminance_integral(&self) -> f32 {
        self.data.luminance_integral
    }

    /// Samples a world direction with density proportional to luminance (per pixel).
    /// Returns (unit direction, radiance, solid-angle pdf); `None` for an all-black map or
    /// a sample at a pole where the density is undefined.
    pub fn sample(&self, u: Vec2) -> Option<(Vec3, Vec3, f32)> {
        if self.data.distribution.integral() <= 0.0 {
            return None;
        }
        let (uv, _) = self.data.distribution.sample(u);
        let dir = self.rotation * local_direction(uv).0;
        // Density and radiance are re-read from the direction itself, not from `uv`, so
        // that they equal what `pdf` and `radiance` answer for it bit for bit (MIS needs
        // that); they differ from the drawn cell's only in float-wide slivers at cell edges.
        let pdf = self.pdf(dir);
        (pdf > 0.0).then(|| (dir, self.radiance(dir), pdf))
    }

    /// Solid-angle density of [`Self::sample`] for the world direction `dir`.
    pub fn pdf(&self, dir: Vec3) -> f32 {
        if self.data.distribution.integral() <= 0.0 {
            return 0.0;
        }
        let d = math::normalize_or(self.rotation.inverse() * dir, Vec3::ZERO);
        // Not sqrt(1 − y²): that cancels catastrophically near the poles.
        let sin_theta = Vec2::new(d.x, d.z).length();
        if sin_theta <= 0.0 {
            return 0.0;
        }
        let pdf_uv = self.data.distribution.pdf(self.direction_to_uv(dir));
        let pdf = pdf_uv / (2.0 * std::f32::consts::PI * std::f32::consts::PI * sin_theta);
        if pdf.is_finite() {
            pdf
        } else {
            0.0
        }
    }
}

/// The unit direction (map frame) of (u, v), and sin θ.
fn local_direction(uv: Vec2) -> (Vec3, f32) {
    let theta = uv.y * std::f32::consts::PI;
    let phi = (uv.x - 0.5) * 2.0 * std::f32::consts::PI;
    let (sin_theta, cos_theta) = math::sin_cos(theta);
    let (sin_phi, cos_phi) = math::sin_cos(phi);
    (
        Vec3::new(sin_theta * cos_phi, cos_theta, sin_theta * sin_phi),
        sin_theta,
    )
}

type Pixels = (usize, usize, Vec<Vec3>);

fn create_pixels(resolution: exr::math::Vec2<usize>, _: &exr::image::RgbaChannels) -> Pixels {
    let (w, h) = (resolution.width(), resolution.height());
    (w, h, vec![Vec3::ZERO; w * h])
}

fn set_pixel(
    pixels: &mut Pixels,
    position: exr::math::Vec2<usize>,
    (r, g, b, _a): (f32, f32, f32, f32),
) {
    let w = pixels.0;
    pixels.2[position.y() * w + position.x()] = Vec3::new(r, g, b);
}

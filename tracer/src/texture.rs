//! Textures: 8-bit images with glTF samplers (wrap modes, nearest or bilinear filtering),
//! KHR_texture_transform, and the sRGB transfer function applied when a colour is read.

use glam::{Vec2, Vec4};

/// How texture coordinates outside `[0, 1]` are mapped (glTF sampler `wrapS`/`wrapT`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Wrap {
    /// Tile the image (glTF's default).
    #[default]
    Repeat,
    /// Tile it, mirrored every other time.
    MirroredRepeat,
    /// Clamp to the edge texel.
    ClampToEdge,
}

/// Magnification filter; we apply the same to minification, since a path tracer
/// integrates over many samples per pixel.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Filter {
    /// Nearest texel.
    Nearest,
    /// Bilinear interpolation (glTF's usual default).
    #[default]
    Linear,
}

/// A decoded image with its sampler, as RGBA8 (the transfer function is applied on read).
#[derive(Clone, Debug)]
pub struct Texture {
    /// Width in texels.
    pub width: u32,
    /// Height in texels.
    pub height: u32,
    /// Row-major RGBA texels, top row first (glTF's UV origin is the top-left corner).
    pub texels: Vec<[u8; 4]>,
    /// Horizontal wrap.
    pub wrap_s: Wrap,
    /// Vertical wrap.
    pub wrap_t: Wrap,
    /// Filter.
    pub filter: Filter,
}

/// KHR_texture_transform: `uv' = T * R * S * uv`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct UvTransform {
    /// Offset.
    pub offset: Vec2,
    /// Rotation in radians, counter-clockwise in UV space.
    pub rotation: f32,
    /// Scale.
    pub scale: Vec2,
}

impl UvTransform {
    /// Applies the transform to a texture coordinate, as the extension's matrix does.
    pub fn apply(&self, uv: Vec2) -> Vec2 {
        let s = uv * self.scale;
        let (sin, cos) = crate::math::sin_cos(self.rotation);
        Vec2::new(cos * s.x + sin * s.y, -sin * s.x + cos * s.y) + self.offset
    }
}

/// A material's use of a texture.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TextureRef {
    /// Index into [`crate::scene::Scene::textures`].
    pub texture: u32,
    /// Which TEXCOORD_n set (after any KHR_texture_transform override).
    pub texcoord: u32,
    /// KHR_texture_transform, if present.
    pub transform: Option<UvTransform>,
}

impl TextureRef {
    /// The texture coordinate to sample for this reference.
    pub fn uv(&self, uvs: [Vec2; 2]) -> Vec2 {
        let uv = uvs[(self.texcoord as usize).min(1)];
        match &self.transform {
            Some(t) => t.apply(uv),
            None => uv,
        }
    }
}

/// 8-bit sRGB to linear, precomputed: texture reads are hot.
fn srgb_lut() -> &'static [f32; 256] {
    static LUT: std::sync::OnceLock<[f32; 256]> = std::sync::OnceLock::new();
    LUT.get_or_init(|| std::array::from_fn(|i| srgb_to_linear(i as f32 / 255.0)))
}

/// The sRGB electro-optical transfer function.
pub fn srgb_to_linear(c: f32) -> f32 {
    if c <= 0.04045 {
        c / 12.92
    } else {
        crate::math::powf((c + 0.055) / 1.055, 2.4)
    }
}

/// Inverse of [`srgb_to_linear`].
pub fn linear_to_srgb(c: f32) -> f32 {
    if c <= 0.0031308 {
        c * 12.92
    } else {
        1.055 * crate::math::powf(c, 1.0 / 2.4) - 0.055
    }
}

fn wrap(i: i64, n: u32, mode: Wrap) -> usize {
    let n = n as i64;
    let w = match mode {
        Wrap::Repeat => i.rem_euclid(n),
        Wrap::ClampToEdge => i.clamp(0, n - 1),
        Wrap::MirroredRepeat => {
            let m = i.rem_euclid(2 * n);
            if m < n {
                m
            } else {
                2 * n - 1 - m
            }
        }
    };
    w as usize
}

impl Texture {
    fn fetch(&self, x: i64, y: i64, srgb: bool) -> Vec4 {
        let x = wrap(x, self.width, self.wrap_s);
        let y = wrap(y, self.height, self.wrap_t);
        let t = self.texels[y * self.width as usize + x];
        let a = t[3] as f32 / 255.0;
        if srgb {
            let lut = srgb_lut();
            Vec4::new(
                lut[t[0] as usize],
                lut[t[1] as usize],
                lut[t[2] as usize],
                a,
            )
        } else {
            Vec4::new(t[0] as f32, t[1] as f32, t[2] as f32, t[3] as f32) / 255.0
        }
    }

    /// Samples at `uv`; with `srgb` the RGB channels are decoded to linear (alpha is always
    /// linear). Bilinear filtering happens after decoding, as GPUs do for sRGB formats.
    pub fn sample(&self, uv: Vec2, srgb: bool) -> Vec4 {
        // Non-finite coordinates (from degenerate UVs) read texel 0 rather than poison.
        let uv = if uv.is_finite() { uv } else { Vec2::ZERO };
        let x = uv.x as f64 * self.width as f64;
        let y = uv.y as f64 * self.height as f64;
        match self.filter {
            Filter::Nearest => self.fetch(x.floor() as i64, y.floor() as i64, srgb),
            Filter::Linear => {
                let (x, y) = (x - 0.5, y - 0.5);
                let (x0, y0) = (x.floor(), y.floor());
                let (fx, fy) = ((x - x0) as f32, (y - y0) as f32);
                let (x0, y0) = (x0 as i64, y0 as i64);
                let a = self
                    .fetch(x0, y0, srgb)
                    .lerp(self.fetch(x0 + 1, y0, srgb), fx);
                let b = self
                    .fetch(x0, y0 + 1, srgb)
                    .lerp(self.fetch(x0 + 1, y0 + 1, srgb), fx);
                a.lerp(b, fy)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn checker() -> Texture {
        Texture {
            width: 2,
            height: 2,
            texels: vec![
                [0, 0, 0, 255],
                [255, 255, 255, 255],
                [255, 255, 255, 255],
                [0, 0, 0, 255],
            ],
            wrap_s: Wrap::Repeat,
            wrap_t: Wrap::Repeat,
            filter: Filter::Nearest,
        }
    }

    #[test]
    fn srgb_round_trips_and_hits_known_values() {
        assert!((srgb_to_linear(0.5) - 0.21404).abs() < 1e-4);
        for i in 0..=100 {
            let c = i as f32 / 100.0;
            assert!((linear_to_srgb(srgb_to_linear(c)) - c).abs() < 1e-5);
        }
    }

    #[test]
    fn wrap_modes_map_outside_coordinates() {
        assert_eq!(wrap(-1, 4, Wrap::Repeat), 3);
        assert_eq!(wrap(5, 4, Wrap::Repeat), 1);
        assert_eq!(wrap(-1, 4, Wrap::ClampToEdge), 0);
        assert_eq!(wrap(9, 4, Wrap::ClampToEdge), 3);
        assert_eq!(wrap(4, 4, Wrap::MirroredRepeat), 3);
        assert_eq!(wrap(-1, 4, Wrap::MirroredRepeat), 0);
        assert_eq!(wrap(8, 4, Wrap::MirroredRepeat), 0);
    }

    #[test]
    fn nearest_and_bilinear_reads() {
        let mut t = checker();
        assert_eq!(t.sample(Vec2::new(0.25, 0.25), false).x, 0.0);
        assert_eq!(t.sample(Vec2::new(0.75, 0.25), false).x, 1.0);
        assert_eq!(t.sample(Vec2::new(1.25, 0.25), false).x, 0.0, "repeat");
        t.filter = Filter::Linear;
        // The centre of the image is equidistant from all four texels.
        assert!((t.sample(Vec2::new(0.5, 0.5), false).x - 0.5).abs() < 1e-6);
    }

    #[test]
    fn texture_transform_matches_the_extension_matrix() {
        let t = UvTransform {
            offset: Vec2::new(0.5, 0.0),
            rotation: std::f32::consts::FRAC_PI_2,
            scale: Vec2::splat(2.0),
        };
        // Scale (1,0) -> (2,0); rotate by +90° in the spec's matrix -> (0,-2); offset -> (0.5,-2).
        let r = t.apply(Vec2::new(1.0, 0.0));
        assert!((r - Vec2::new(0.5, -2.0)).length() < 1e-5, "{r}");
    }
}

//! The string attributes of a Tessera EXR's header: [`ExrMetadata`] in, the same pairs
//! read back, with OpenEXR's standard text attributes mapped to the typed fields that the
//! `exr` crate keeps them in.

use ::exr::meta::attribute::{AttributeValue, Text};
use ::exr::meta::header::{standard_names, ImageAttributes, LayerAttributes};

use super::OutputError;
use crate::film::SamplingSummary;

/// Header attributes of an EXR file: (name, value) string pairs, written in order as
/// OpenEXR `string` attributes (UTF-8) of the file's one header.
///
/// Names are free-form (`tessera/spp`); the few standard OpenEXR text attributes (`owner`,
/// `comments`, `capDate`, `software`, `renderingTransform`, `lookModTransform`,
/// `wrapmodes`, `view`) are allowed too. Every file gets `software` = `Tessera <version>`
/// unless the list names it.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct ExrMetadata {
    /// The attributes, each name at most once.
    pub attributes: Vec<(String, String)>,
}

impl ExrMetadata {
    /// Tessera version that rendered the image.
    pub const VERSION: &'static str = "tessera/version";
    /// Samples per pixel asked for (the most any pixel takes).
    pub const SPP: &'static str = "tessera/spp";
    /// The render settings (the job's settings, serialised).
    pub const SETTINGS: &'static str = "tessera/settings";
    /// The scene features the tracer enabled.
    pub const FEATURES: &'static str = "tessera/features";
    /// Mean samples per pixel reached.
    pub const SPP_MEAN: &'static str = "tessera/spp-mean";
    /// Fewest samples a pixel took.
    pub const SPP_MIN: &'static str = "tessera/spp-min";
    /// Most samples a pixel took.
    pub const SPP_MAX: &'static str = "tessera/spp-max";
    /// Mean estimated relative error over the pixels (absent when no pixel had enough
    /// samples for an estimate).
    pub const NOISE: &'static str = "tessera/noise";
    /// Seconds spent rendering the image (summed over its tiles on a farm).
    pub const RENDER_SECONDS: &'static str = "tessera/render-seconds";
    /// The denoiser that made the `denoised` layer (absent when there is none).
    pub const DENOISER: &'static str = "tessera/denoiser";
    /// Seconds the denoiser took.
    pub const DENOISE_SECONDS: &'static str = "tessera/denoise-seconds";

    /// No attributes.
    pub fn new() -> Self {
        Self::default()
    }

    /// `self` with what the samples reached ([`SPP_MEAN`](Self::SPP_MEAN),
    /// [`SPP_MIN`](Self::SPP_MIN), [`SPP_MAX`](Self::SPP_MAX), [`NOISE`](Self::NOISE)).
    pub fn with_sampling(self, s: &SamplingSummary) -> Self {
        let out = self
            .with(Self::SPP_MEAN, format!("{:.3}", s.mean_samples))
            .with(Self::SPP_MIN, s.min_samples.to_string())
            .with(Self::SPP_MAX, s.max_samples.to_string());
        match s.mean_noise {
            Some(e) => out.with(Self::NOISE, format!("{e:.6}")),
            None => out,
        }
    }

    /// `self` with `name` set to `value`.
    pub fn with(mut self, name: impl Into<String>, value: impl Into<String>) -> Self {
        self.set(name, value);
        self
    }

    /// Sets `name` to `value`, replacing an earlier value.
    pub fn set(&mut self, name: impl Into<String>, value: impl Into<String>) {
        let (name, value) = (name.into(), value.into());
        match self.attributes.iter_mut().find(|(n, _)| *n == name) {
            Some(slot) => slot.1 = value,
            None => self.attributes.push((name, value)),
        }
    }

    /// The value of `name`, if set.
    pub fn get(&self, name: &str) -> Option<&str> {
        self.attributes
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, v)| v.as_str())
    }
}

/// The standard OpenEXR text attributes that `exr` keeps in typed fields, by name.
fn standard_texts(a: &LayerAttributes) -> [(&'static str, &Option<Text>); 8] {
    [
        ("owner", &a.owner),
        ("comments", &a.comments),
        ("capDate", &a.capture_date),
        ("software", &a.software_name),
        ("renderingTransform", &a.rendering_transform_name),
        ("lookModTransform", &a.look_modification_transform_name),
        ("wrapmodes", &a.wrap_mode_name),
        ("view", &a.view_name),
    ]
}

/// The typed field of `a` that holds the standard text attribute `name`, if it is one
/// of [`standard_texts`].
fn standard_text_mut<'a>(a: &'a mut LayerAttributes, name: &str) -> Option<&'a mut Option<Text>> {
    Some(match name {
        "owner" => &mut a.owner,
        "comments" => &mut a.comments,
        "capDate" => &mut a.capture_date,
        "software" => &mut a.software_name,
        "renderingTransform" => &mut a.rendering_transform_name,
        "lookModTransform" => &mut a.look_modification_transform_name,
        "wrapmodes" => &mut a.wrap_mode_name,
        "view" => &mut a.view_name,
        _ => return None,
    })
}

/// Puts `meta` into `attributes`, refusing names OpenEXR reserves for other types or
/// cannot store, and names given twice.
pub(super) fn set_attributes(
    attributes: &mut LayerAttributes,
    meta: &ExrMetadata,
) -> Result<(), OutputError> {
    let bad = |name: &str, reason| OutputError::BadAttribute {
        name: name.to_string(),
        reason,
    };
    for (k, (name, value)) in meta.attributes.iter().enumerate() {
        if name.is_empty() {
            return Err(bad(name, "the name is empty"));
        }
        // OpenEXR 2 allows names up to 255 bytes ("long names"), without NUL.
        if name.len() > 255 {
            return Err(bad(name, "the name is longer than 255 bytes"));
        }
        if name.contains('\0') {
            return Err(bad(name, "the name contains a NUL byte"));
        }
        if meta.attributes[..k].iter().any(|(n, _)| n == name) {
            return Err(bad(name, "the name is given twice"));
        }
        // Strings are stored as their UTF-8 bytes, as OpenEXR's C++ library does
        // (`exr::Text::from` would refuse characters above U+00FF).
        let text = Text::from_slice_unchecked(value.as_bytes());
        if let Some(field) = standard_text_mut(attributes, name) {
            *field = Some(text);
        } else if standard_names::ALL.contains(&name.as_bytes()) {
            return Err(bad(
                name,
                "the name is a standard OpenEXR attribute of another type",
            ));
        } else {
            attributes.other.insert(
                Text::from_slice_unchecked(name.as_bytes()),
                AttributeValue::Text(text),
            );
        }
    }
    Ok(())
}

/// Every string attribute of a header, sorted by name; bytes that are not UTF-8 are
/// replaced.
pub(super) fn string_attributes(
    image: &ImageAttributes,
    layer: &LayerAttributes,
) -> Vec<(String, String)> {
    let text = |t: &Text| String::from_utf8_lossy(t.bytes()).into_owned();
    let mut out: Vec<(String, String)> = standard_texts(layer)
        .into_iter()
        .filter_map(|(name, value)| Some((name.to_string(), text(value.as_ref()?))))
        .collect();
    for (name, value) in image.other.iter().chain(&layer.other) {
        if let AttributeValue::Text(value) = value {
            out.push((text(name), text(value)));
        }
    }
    out.sort();
    out
}

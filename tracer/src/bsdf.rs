//! The glTF metallic-roughness BSDF (glTF 2.0 Appendix B, with KHR_materials_specular,
//! _ior and _transmission) in a local shading frame whose normal is +Z.
//!
//! # Model
//!
//! With `α = roughness²`, `c` the base colour, `m` metallic, `t` transmission, `s`
//! specular and `η` the IOR:
//!
//! ```text
//! f       = m · metal + (1 − m)(1 − t) · plastic + (1 − m) t · glass
//! metal   = GGX reflection with Schlick Fresnel, F0 = c; Turquin compensation
//! plastic = s · GGX reflection with Schlick Fresnel, F0 = min(((η−1)/(η+1))² · specularColor, 1),
//!           Turquin compensation; plus c/π · (1 − E_spec(μo))       (albedo scaling)
//! glass   = dielectric interface, smooth or rough (Walter et al. 2007), exact Fresnel F:
//!           reflection s · min(specularColor, 1) · F, refraction c · (1 − s'·F) / η²,
//!           s' = s · max(min(specularColor, 1)); plus a multiple-scattering lobe;
//!           or, for transmission without KHR_materials_volume, a thin wall that
//!           refracts nothing (`bsdf/thin.rs`)
//! ```
//!
//! This is the glTF layering `mix(dielectric_brdf, metal_brdf, metallic)` with
//! `dielectric_brdf = fresnel_mix(layer = specular_brdf, base = mix(diffuse, btdf, t))`,
//! except that the transmissive part is one dielectric interface with the exact Fresnel
//! for both of its lobes: a clear glass must be an energy-conserving interface, and the
//! boundary of a volume (KHR_materials_volume) refracts as the surface of a solid. GGX uses
//! height-correlated Smith masking-shadowing and spherical-cap visible-normal sampling
//! (Dupuy & Benyoub 2023).
//!
//! # Conventions
//!
//! - All directions are unit vectors in the shading frame and point away from the surface.
//!   `wo.z < 0` means the ray arrived from below: for the transmissive part it is inside
//!   the object (the relative index becomes 1/η); the opaque parts are two-sided (they
//!   mirror both directions into the upper hemisphere), so a shading normal that disagrees
//!   with the geometry does not turn a surface black.
//! - Radiance transport: refraction into a medium of relative index η scales radiance by
//!   1/η² (the BTDF carries that factor, as pbrt-v4's does for `TransportMode::Radiance`);
//!   a path that enters and leaves an object gets η² back, so the factors cancel.
//! - `α < ALPHA_MIN = 1e-3` (roughness < 0.032) is a perfectly smooth, delta lobe, as in
//!   pbrt-v4's `EffectivelySmooth`. Below that the highlight is narrower than 0.06° (a
//!   mirror to the eye), `D` exceeds 3·10⁵, and the half vector of a sampled pair can no
//!   longer be recovered in f32 to the precision that `pdf(wo, wi)` needs to match the
//!   sampled pdf. The dielectric interface is also smooth when `|η − 1| < 1e-3`: its
//!   refracted lobe is then narrower than α·|η − 1| < 1e-3 radians, and at η = 1 exactly
//!   it is a straight pass-through.
//! - Directions within `COS_EPS = 1e-6` of the tangent plane evaluate to zero and are never
//!   sampled; this keeps every `1/cos` finite and loses a solid angle of order 1e-6.
//! - Lobes are sampled in proportion to their estimated albedo at `wo`, and `pdf` is the
//!   matching mixture over the non-delta lobes; a non-delta sample returns the whole
//!   `eval` and `pdf` (one-sample MIS between lobes). A microfacet reflection that points
//!   below the horizon, or a refraction above it, is folded through the tangent plane
//!   rather than lost, and `pdf` counts both ways of reaching a direction.
//!
//! # Energy
//!
//! Single-scattering GGX loses the light that bounces more than once among the
//! microfacets. `bsdf/tables.rs` integrates directional albedos once, on first use, and:
//!
//! - the metal and the specular layer get Turquin et al.'s (2019) factor
//!   `1 + F0 (1 − E1(μo)) / E1(μo)`, exact for F0 = 1;
//! - the diffuse base under the specular layer is weighted by `1 − E_spec(μo)`, the
//!   energy the (compensated) layer leaves, so white plastic conserves energy;
//! - the rough dielectric interface gets a Kulla-Conty-style multiple-scattering lobe: the
//!   energy `1 − E(μo, α, η)` that single scattering misses (from a table over both sides
//!   and IOR) leaves as a cosine lobe, reflected and refracted in the proportion the
//!   single-scattered light is. Scaling the lobes up by `1/E` instead (as for the metal)
//!   conserves energy too, but inside glass, where most samples are rejected by total
//!   internal reflection, it multiplies path weights bounce after bounce into a
//!   heavy-tailed estimator.
//!
//! A material whose roughness is not textured can carry its own albedo curves over μ
//! (`bsdf/curve.rs`, [`Bsdf::with_albedo_curve`]), 20 to 50 times more precise than the
//! tables: rough glass traps light for hundreds of bounces, and per-bounce errors
//! compound there. Frames attach them to rough refractive materials.
//!
//! The tests in `bsdf/tests.rs` measure the white furnace of each part.

mod anisotropy;
mod base;
mod coat;
mod curve;
mod fresnel;
mod glass;
mod iridescence;
mod layers;
mod metamaterial;
mod microfacet;
mod sheen;
mod tables;
mod thin;
mod view;

pub use curve::AlbedoCurve;
pub use view::BsdfAt;

use view::AtWo;

#[cfg(test)]
mod anisotropy_tests;
#[cfg(test)]
mod chi2;
#[cfg(test)]
mod layer_tests;
#[cfg(test)]
mod tests;
#[cfg(test)]
mod transmission_tests;

use glam::{Vec2, Vec3};

/// Below this α the microfacet lobes are delta lobes (see the module documentation).
pub(crate) const ALPHA_MIN: f32 = 1e-3;
/// Directions closer than this (in cosine) to the tangent plane evaluate to zero.
const COS_EPS: f32 = 1e-6;
/// Dielectric interfaces with `|η − 1|` below this are smooth (see the module docs).
const ETA_SMOOTH: f32 = 1e-3;
/// Largest IOR accepted; larger values are clamped (the compensation table ends at 10.5,
/// and no real dielectric comes near 100).
const IOR_MAX: f32 = 100.0;
/// Lobe-selection probabilities never drop below this fraction of a present lobe's
/// weight, so a lobe whose albedo estimate is tiny can still be sampled.
const LOBE_FLOOR: f32 = 1e-3;

/// Surface parameters after textures are applied, at one shading point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfaceParams {
    /// Linear base colour.
    pub base_color: Vec3,
    /// Metallic, 0..1.
    pub metallic: f32,
    /// Perceptual roughness, 0..1.
    pub roughness: f32,
    /// Index of refraction of the material (the outside is assumed to be 1).
    pub ior: f32,
    /// KHR_materials_specular factor.
    pub specular: f32,
    /// KHR_materials_specular colour.
    pub specular_color: Vec3,
    /// KHR_materials_transmission factor.
    pub transmission: f32,
    /// Whether the transmitting part is a thin wall (glTF's default without
    /// KHR_materials_volume): light passes through without bending and both sides are
    /// outside. Otherwise it is the boundary of a solid that refracts.
    pub thin_walled: bool,
    /// The parameters of the material extensions beyond the base, for a material that
    /// has any (`None` keeps the parameters of the commonest materials small).
    pub extensions: Option<ExtensionParams>,
}

/// The parameters of the material extensions: the layers over the base (see
/// `bsdf/layers.rs`), the film, the metamaterial, diffuse transmission, anisotropy.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ExtensionParams {
    /// KHR_materials_clearcoat factor, 0..1 (0: no coat).
    pub clearcoat: f32,
    /// Its perceptual roughness, 0..1.
    pub clearcoat_roughness: f32,
    /// KHR_materials_sheen colour, each channel 0..1 (black: no sheen).
    pub sheen_color: Vec3,
    /// Its roughness, 0..1 (the Charlie α itself, as the extension defines it).
    pub sheen_roughness: f32,
    /// KHR_materials_iridescence factor, 0..1 (0: no thin film).
    pub iridescence: f32,
    /// The film's IOR.
    pub iridescence_ior: f32,
    /// The film's thickness in nanometres (0: no film).
    pub iridescence_thickness: f32,
    /// TESSERA_materials_metamaterial: the negative refractive index of the transmitting
    /// part (0: none, an ordinary dielectric of `ior`).
    pub metamaterial_index: f32,
    /// Its impedance relative to the outside (1: matched).
    pub metamaterial_impedance: f32,
    /// KHR_materials_diffuse_transmission factor, 0..1: the share of the diffuse base
    /// that passes to the other side.
    pub diffuse_transmission: f32,
    /// Its colour.
    pub diffuse_transmission_color: Vec3,
    /// KHR_materials_anisotropy strength, 0..1: the base's microfacet lobes are rougher
    /// along the shading frame's x axis, `α_x = mix(α, 1, strength²)` (the caller points
    /// that axis in the material's anisotropy direction).
    pub anisotropy: f32,
}

impl Default for SurfaceParams {
    /// The glTF defaults: white, fully metallic and rough, IOR 1.5, specular 1, white
    /// specular colour, no transmission.
    fn default() -> Self {
        Self {
            base_color: Vec3::ONE,
            metallic: 1.0,
            roughness: 1.0,
            ior: 1.5,
            specular: 1.0,
            specular_color: Vec3::ONE,
            transmission: 0.0,
            thin_walled: false,
            extensions: None,
        }
    }
}

/// A sampled direction.
#[derive(Clone, Copy, Debug)]
pub struct BsdfSample {
    /// Incident direction, local frame.
    pub wi: Vec3,
    /// BSDF value for (wo, wi), without the cosine. For a delta sample, the value of the
    /// sampled delta lobe such that `f · |wi.z| / pdf` is the throughput weight.
    pub f: Vec3,
    /// Solid-angle pdf (for a delta lobe: the probability of choosing it).
    pub pdf: f32,
    /// Whether a delta (perfectly smooth) lobe was sampled.
    pub delta: bool,
}

/// The BSDF at one shading point.
#[derive(Clone, Copy, Debug)]
pub struct Bsdf {
    /// The parameters it was made from (as given, before clamping).
    pub params: SurfaceParams,
    /// Base colour clamped to [0, 1].
    base: Vec3,
    /// The diffuse base's reflection colour, `(1 − dt) · base`, and its transmission
    /// colour, `dt · diffuseTransmissionColor` (KHR_materials_diffuse_transmission).
    diffuse_r: Vec3,
    diffuse_t: Vec3,
    /// The share of diffuse samples sent to the other side.
    p_dt: f32,
    /// GGX α = roughness² (along the bitangent where the material is anisotropic).
    alpha: f32,
    /// The microfacet distribution of the metal, the specular layer and the refractive
    /// interface: α along both axes, or stretched along the frame's x axis by
    /// KHR_materials_anisotropy.
    ggx: microfacet::Ggx,
    /// Whether the microfacet lobes are delta lobes (α below `ALPHA_MIN` along both
    /// axes).
    smooth: bool,
    /// The IOR, clamped to [1, IOR_MAX].
    eta: f32,
    /// Mixing weight of the metal.
    w_metal: f32,
    /// Mixing weight of the opaque dielectric (specular layer over diffuse).
    w_plastic: f32,
    /// Mixing weight of the refractive dielectric.
    w_glass: f32,
    /// KHR_materials_specular factor, clamped to [0, 1].
    spec: f32,
    /// F0 of the specular layer, `min(((η−1)/(η+1))² · specularColor, 1)`.
    f0_spec: Vec3,
    /// Reflection tint of the refractive interface, `s · min(specularColor, 1)`.
    glass_tint: Vec3,
    /// Largest component of `glass_tint`: the interface reflects `glass_s · F` and
    /// refracts the rest.
    glass_s: f32,
    /// Whether the refractive interface is smooth (delta reflection and refraction).
    glass_smooth: bool,
    /// Whether the transmitting part is a thin wall (`bsdf/thin.rs`) rather than an
    /// interface into a solid.
    thin: bool,
    /// Whether any microfacet lobe is present (metal, specular layer, rough interface): a
    /// Lambertian surface (specular 0) skips their tables and evaluation.
    microfacet: bool,
    /// The lobe probabilities of a Lambertian BSDF ([`Bsdf::is_lambertian`]), which no
    /// `wo` changes; `None` for any other.
    lambertian: Option<[f32; 3]>,
    /// Whether the base (what lies under any layers) is a diffuse reflector alone
    /// ([`Bsdf::is_lambertian`] without diffuse transmission): its f and pdf are the
    /// diffuse lobe's.
    diffuse_only: bool,
    /// Conductor-table position for α (meaningful when not smooth).
    cond: tables::ConductorCoord,
    /// Dielectric-table positions for (α, η), outside and inside (meaningful when the
    /// glass part is present and rough).
    diel: [tables::DielectricCoord; 2],
    /// The material's own albedo curve for (α, η), used instead of both tables.
    curve: Option<&'static AlbedoCurve>,
    /// The clear coat and sheen over all of the above, where the material has either
    /// (see `bsdf/layers.rs`).
    layers: Option<layers::Layers>,
    /// The iridescent film over the base's specular lobes (`bsdf/iridescence.rs`).
    film: Option<iridescence::ThinFilm>,
    /// The negative-index medium the transmitting part leads into, in place of the
    /// dielectric (`bsdf/metamaterial.rs`).
    meta: Option<metamaterial::Metamaterial>,
}

/// Builds the energy-compensation tables now rather than at the first rough surface a
/// render meets (about 0.1 s for the conductor table, 0.25 s more for the dielectric one
/// with `with_dielectric`, 0.3 s for the sheen's albedo with `with_sheen`, 0.7 s for
/// the anisotropic lobes' albedo table with `with_anisotropy`, at opt-level 3).
/// Optional: call it while preparing a frame so that no rendering thread waits on the
/// build, and only ask for the tables the scene's materials use.
pub fn precompute_tables(with_dielectric: bool, with_sheen: bool, with_anisotropy: bool) {
    tables::conductor();
    if with_dielectric {
        tables::dielectric();
    }
    if with_sheen {
        sheen::precompute();
    }
    if with_anisotropy {
        anisotropy::table();
    }
}

/// A finite value clamped to [lo, hi]; NaN becomes `default`.
fn sane(x: f32, lo: f32, hi: f32, default: f32) -> f32 {
    if x.is_nan() {
        default
    } else {
        x.clamp(lo, hi)
    }
}

fn sane3(v: Vec3, lo: f32, hi: f32) -> Vec3 {
    Vec3::new(
        sane(v.x, lo, hi, 0.0),
        sane(v.y, lo, hi, 0.0),
        sane(v.z, lo, hi, 0.0),
    )
}

fn mean(v: Vec3) -> f32 {
    (v.x + v.y + v.z) * (1.0 / 3.0)
}

/// Mirrors a direction through the tangent plane.
fn flip(v: Vec3) -> Vec3 {
    Vec3::new(v.x, v.y, -v.z)
}

/// Albedo of the compensated GGX reflection lobe with Schlick F0 (scalar), given the
/// tabulated `e1`, `ew` and the compensation ratio `k = (1 − e1)/e1`.
fn compensated_albedo(f0: f32, e1: f32, ew: f32, k: f32) -> f32 {
    (f0 * e1 + (1.0 - f0) * ew) * (1.0 + f0 * k)
}

impl Bsdf {
    /// The BSDF for these parameters. Out-of-range or NaN parameters are clamped into
    /// their glTF ranges (base colour and factors to [0, 1], IOR to [1, 100]; a NaN IOR
    /// becomes 1.5).
    pub fn new(params: SurfaceParams) -> Self {
        let base = sane3(params.base_color, 0.0, 1.0);
        let metallic = sane(params.metallic, 0.0, 1.0, 0.0);
        let roughness = sane(params.roughness, 0.0, 1.0, 1.0);
        let transmission = sane(params.transmission, 0.0, 1.0, 0.0);
        let spec = sane(params.specular, 0.0, 1.0, 1.0);
        let spec_color = sane3(params.specular_color, 0.0, f32::MAX);
        let meta = params.extensions.and_then(|l| {
            let n = sane(l.metamaterial_index, -IOR_MAX, 0.0, 0.0);
            (n < 0.0).then(|| metamaterial::Metamaterial {
                index: n.abs().max(metamaterial::MIN_INDEX),
                impedance: sane(
                    l.metamaterial_impedance,
                    metamaterial::MIN_INDEX,
                    IOR_MAX,
                    1.0,
                ),
            })
        });
        // A metamaterial's interface is smooth and bounds a solid; its |n| is the index
        // that radiance and path weights see.
        let eta = match &meta {
            Some(m) => m.index,
            None => sane(params.ior, 1.0, IOR_MAX, 1.5),
        };
        let thin = params.thin_walled && meta.is_none();
        let film = params.extensions.and_then(|l| {
            iridescence::ThinFilm::new(
                sane(l.iridescence, 0.0, 1.0, 0.0),
                sane(l.iridescence_ior, 1.0, IOR_MAX, 1.3),
                sane(l.iridescence_thickness, 0.0, f32::MAX, 0.0),
                l.clearcoat > 0.0,
            )
        });
        let layers = params.extensions.and_then(|l| {
            layers::Layers::new(
                sane(l.clearcoat, 0.0, 1.0, 0.0),
                sane(l.clearcoat_roughness, 0.0, 1.0, 0.0),
                sane3(l.sheen_color, 0.0, 1.0),
                sane(l.sheen_roughness, 0.0, 1.0, 0.0),
            )
        });

        let (dt, dt_color) = params.extensions.map_or((0.0, Vec3::ZERO), |l| {
            (
                sane(l.diffuse_transmission, 0.0, 1.0, 0.0),
                sane3(l.diffuse_transmission_color, 0.0, 1.0),
            )
        });
        let (diffuse_r, diffuse_t) = if dt > 0.0 {
            ((1.0 - dt) * base, dt * dt_color)
        } else {
            (base, Vec3::ZERO)
        };
        let p_dt = if diffuse_t.max_element() > 0.0 {
            mean(diffuse_t) / (mean(diffuse_r) + mean(diffuse_t))
        } else {
            0.0
        };

        let alpha = roughness * roughness;
        let strength = params
            .extensions
            .map_or(0.0, |l| sane(l.anisotropy, 0.0, 1.0, 0.0));
        let alpha_x = alpha + (1.0 - alpha) * strength * strength;
        let smooth = alpha_x < ALPHA_MIN;
        // A lobe rough along one axis only is still rough: the smooth axis keeps the
        // smallest α whose pdf f32 resolves (see ALPHA_MIN).
        let ggx = microfacet::Ggx {
            ax: alpha_x.max(ALPHA_MIN),
            ay: alpha.max(ALPHA_MIN),
        };
        let r0 = ((eta - 1.0) / (eta + 1.0)).powi(2);
        let f0_spec = (r0 * spec_color).min(Vec3::ONE);
        let glass_tint = spec * spec_color.min(Vec3::ONE);
        let glass_smooth = smooth || (eta - 1.0).abs() < ETA_SMOOTH || meta.is_some();
        let table_alpha = ggx.ay;
        let w_plastic = (1.0 - metallic) * (1.0 - transmission);
        let w_glass = (1.0 - metallic) * transmission;
        let microfacet = !smooth
            && (metallic > 0.0 || w_plastic * spec > 0.0 || (w_glass > 0.0 && !glass_smooth));
        let mut bsdf = Self {
            params,
            base,
            diffuse_r,
            diffuse_t,
            p_dt,
            alpha,
            ggx,
            smooth,
            eta,
            w_metal: metallic,
            w_plastic,
            w_glass,
            spec,
            f0_spec,
            glass_tint,
            glass_s: glass_tint.max_element(),
            glass_smooth,
            thin,
            microfacet,
            lambertian: None,
            diffuse_only: false,
            // Table positions only where a lobe looks them up: a Lambertian surface, the
            // commonest, needs none.
            cond: if microfacet {
                tables::ConductorTable::coord(table_alpha)
            } else {
                Default::default()
            },
            diel: if w_glass > 0.0 && !glass_smooth && !thin {
                [false, true].map(|inside| tables::DielectricTable::coord(table_alpha, eta, inside))
            } else {
                Default::default()
            },
            curve: None,
            layers,
            film,
            meta,
        };
        bsdf.lambertian = bsdf.lambertian_lobes();
        bsdf.diffuse_only = bsdf.is_lambertian() && bsdf.p_dt == 0.0;
        bsdf
    }

    /// The albedo curve a material with these (untextured) parameters should carry: one
    /// for a rough refractive interface, whose light can stay trapped for hundreds of
    /// bounces where the shared tables' error would add up (see `bsdf/curve.rs`). Built
    /// on first request (about 0.3 s) and kept for the process.
    pub fn albedo_curve_for(params: SurfaceParams) -> Option<&'static AlbedoCurve> {
        let b = Self::new(params);
        (b.w_glass > 0.0 && !b.glass_smooth && !b.thin && !b.ggx.is_anisotropic())
            .then(|| curve::interned(b.alpha, b.eta))?
    }

    /// This BSDF with the albedo curve of its material (from [`Bsdf::albedo_curve_for`]);
    /// a curve made for another (α, η), as where a texture changes the roughness, or for
    /// an anisotropic lobe, is ignored and the shared tables serve.
    pub fn with_albedo_curve(mut self, curve: Option<&'static AlbedoCurve>) -> Self {
        self.curve = curve.filter(|c| c.is_for(self.alpha, self.eta) && !self.ggx.is_anisotropic());
        self
    }

    /// The albedo curve it carries (see [`Bsdf::with_albedo_curve`]).
    pub fn albedo_curve(&self) -> Option<&'static AlbedoCurve> {
        self.curve
    }

    /// Whether every lobe is perfectly smooth, so that `eval` and `pdf` are zero
    /// everywhere and only `sample` can find directions (no light sampling, no MIS).
    pub fn is_delta(&self) -> bool {
        let metal = self.w_metal == 0.0 || self.smooth;
        let plastic = self.w_plastic == 0.0
            || (self.smooth && self.diffuse_r.max_element() == 0.0 && self.p_dt == 0.0);
        let glass = self.w_glass == 0.0 || self.glass_smooth;
        metal && plastic && glass && self.layers.is_none_or(|l| l.is_delta())
    }

    /// A cheap albedo for the denoiser's albedo layer: the base colour of each part,
    /// mixed as the material mixes (the plastic's base colour is blended towards its
    /// specular F0 by the specular weight; refractive glass reports its tint).
    pub fn albedo(&self) -> Vec3 {
        let f0_max = self.f0_spec.max_element();
        let plastic = self.base * (1.0 - self.spec * f0_max) + self.spec * self.f0_spec;
        self.w_metal * self.base + self.w_plastic * plastic + self.w_glass * self.base
    }

    /// The material's index of refraction (clamped to [1, 100]).
    pub fn eta(&self) -> f32 {
        self.eta
    }

    /// Whether light it transmits passes a thin wall (no bending, no medium entered)
    /// rather than refracting into or out of a solid.
    pub fn is_thin_walled(&self) -> bool {
        self.thin
    }

    /// f(wo, wi) without the cosine; zero for delta lobes.
    pub fn eval(&self, wo: Vec3, wi: Vec3) -> Vec3 {
        self.at(wo).map_or(Vec3::ZERO, |at| at.eval(wi))
    }

    /// The solid-angle pdf with which [`Bsdf::sample`] returns `wi`; zero for delta lobes.
    pub fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        self.at(wo).map_or(0.0, |at| at.pdf(wi))
    }

    /// `eval(wo, wi)` and `pdf(wo, wi)` together, sharing the work that depends on `wo`
    /// (for light sampling with MIS, which needs both).
    pub fn eval_and_pdf(&self, wo: Vec3, wi: Vec3) -> (Vec3, f32) {
        self.at(wo)
            .map_or((Vec3::ZERO, 0.0), |at| at.eval_and_pdf(wi))
    }

    /// Samples an incident direction from `u_lobe` (lobe choice) and `u` (direction).
    /// `None` when no direction carries energy (a black material, a grazing `wo`, total
    /// internal reflection where part of the light is absorbed, or a sample that grazes
    /// the tangent plane).
    pub fn sample(&self, wo: Vec3, u_lobe: f32, u: Vec2) -> Option<BsdfSample> {
        self.at(wo)?.sample(u_lobe, u)
    }
}

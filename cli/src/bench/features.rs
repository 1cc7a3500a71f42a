//! What each scene feature costs in `tessera bench`: camera paths per second of the same
//! demo scene without a feature and with it, and the time to prepare its frame. A scene
//! should pay only for what it uses, so an animated scene with the shutter closed should
//! cost what the still one does.

use std::sync::Arc;
use std::time::Instant;

use serde::Serialize;

use glam::DMat4;
use tracer::film::{SampleRange, TileRect};
use tracer::motion::Shutter;
use tracer::render::{prepare_frame, render_region, FrameOptions, PreparedFrame, RenderSettings};

use tracer::material::{Material, Metamaterial};
use tracer::scene::{Features, JointSet, Node, Scene, Skin};
use tracer::texture::{Texture, TextureRef};

/// `tessera bench features`: the report's feature table alone.
#[derive(clap::Args)]
pub struct FeaturesArgs {
    /// Image size, WIDTHxHEIGHT.
    #[arg(long, default_value = "64x64", value_parser = crate::args::parse_size)]
    pub size: (u32, u32),
    /// Samples per pixel of each timed render.
    #[arg(long, default_value_t = 32)]
    pub spp: u32,
    /// Timed renders of each scene, taken in turn with its comparison; the fastest counts.
    #[arg(long, default_value_t = 3, value_parser = clap::value_parser!(u32).range(1..=20))]
    pub runs: u32,
}

/// Prints the feature table.
pub fn run(args: FeaturesArgs) -> anyhow::Result<()> {
    print!("{}", table(&feature_costs(args.size, args.spp, args.runs)?));
    Ok(())
}

/// One feature's price.
#[derive(Serialize)]
pub struct FeatureCost {
    /// The feature, and the two scenes compared.
    pub feature: String,
    /// Camera paths per second without it.
    pub without: f64,
    /// Camera paths per second with it.
    pub with: f64,
    /// Seconds to prepare the frame (pose, deform, build the BVHs) without it.
    pub prepare_without: f64,
    /// Seconds to prepare the frame with it.
    pub prepare_with: f64,
}

impl FeatureCost {
    /// The extra time per path it costs, as a fraction (0.1: 10% slower).
    pub fn cost(&self) -> f64 {
        self.without / self.with - 1.0
    }
}

/// Each measurement renders for at least this long, so that short renders time well.
const MIN_SECONDS: f64 = 0.5;

/// `scene`'s frame prepared (posed, deformed, its BVHs built), and the seconds it took.
fn prepare(scene: Scene, options: &FrameOptions) -> anyhow::Result<(PreparedFrame, f64)> {
    let start = Instant::now();
    let frame = prepare_frame(Arc::new(scene), options)?;
    Ok((frame, start.elapsed().as_secs_f64()))
}

/// Renders `frame` at `spp` and depth 8 for at least [`MIN_SECONDS`]: camera paths per
/// second.
fn paths_per_second(frame: &PreparedFrame, spp: u32) -> f64 {
    let rect = TileRect::new(0, 0, frame.width, frame.height);
    let render = |spp| {
        render_region(
            frame,
            &RenderSettings::default(),
            rect,
            SampleRange::new(0, spp),
            8,
            &|_| {},
        )
    };
    let (start, mut renders) = (Instant::now(), 0u32);
    while renders == 0 || start.elapsed().as_secs_f64() < MIN_SECONDS {
        render(spp);
        renders += 1;
    }
    let paths = rect.area() as f64 * f64::from(spp) * f64::from(renders);
    paths / start.elapsed().as_secs_f64()
}

/// One feature's price: both frames prepared, each rendered once to warm up (the first
/// render of a process builds the BSDF tables), then timed in turn `runs` times, the
/// fastest of each counting: on a shared machine the speed drifts between runs, and the
/// fastest is the one least disturbed.
fn price(
    feature: &str,
    without: (Scene, &FrameOptions),
    with: (Scene, &FrameOptions),
    spp: u32,
    runs: u32,
) -> anyhow::Result<FeatureCost> {
    let (frame_without, prepare_without) = prepare(without.0, without.1)?;
    let (frame_with, prepare_with) = prepare(with.0, with.1)?;
    let (mut fastest_without, mut fastest_with) = (0.0f64, 0.0f64);
    for frame in [&frame_without, &frame_with] {
        paths_per_second(frame, 1);
    }
    for _ in 0..runs {
        fastest_without = fastest_without.max(paths_per_second(&frame_without, spp));
        fastest_with = fastest_with.max(paths_per_second(&frame_with, spp));
    }
    Ok(FeatureCost {
        feature: feature.into(),
        without: fastest_without,
        with: fastest_with,
        prepare_without,
        prepare_with,
    })
}

/// The demo with its glass sphere opaque (a dielectric that does not transmit).
fn without_transmission() -> Scene {
    let mut scene = tracer::demo::demo_scene();
    for m in &mut scene.materials {
        m.transmission = 0.0;
    }
    scene.features.transmission = false;
    scene.features.volume = false;
    scene
}

/// The demo with a 256x256 checker as every material's base colour texture. The checker
/// is near white, so that the light stays almost as it was and what is measured is the
/// texture lookups, not paths that end sooner on darker walls.
fn with_textures() -> Scene {
    let mut scene = tracer::demo::demo_scene();
    let texels = (0..256 * 256)
        .map(|i| {
            let on = ((i % 256) / 32 + (i / 256) / 32) % 2 == 0;
            if on {
                [255, 255, 255, 255]
            } else {
                [245, 245, 245, 255]
            }
        })
        .collect();
    scene.textures.push(Texture {
        width: 256,
        height: 256,
        texels,
        wrap_s: Default::default(),
        wrap_t: Default::default(),
        filter: Default::default(),
    });
    let texture = scene.textures.len() as u32 - 1;
    for m in &mut scene.materials {
        m.base_color_texture = Some(TextureRef {
            texture,
            texcoord: 0,
            transform: None,
        });
    }
    scene.features.textures = true;
    scene
}

/// The demo with `edit` applied to every material, its feature flags set by `mark`.
fn with_every_material(edit: impl Fn(&mut Material), mark: impl Fn(&mut Features)) -> Scene {
    let mut scene = tracer::demo::demo_scene();
    scene.materials.iter_mut().for_each(edit);
    mark(&mut scene.features);
    scene
}

/// The demo with a layer on every material: a clear coat (factor 1, roughness 0.1), or a
/// white sheen (roughness 0.5).
fn with_layer(clearcoat: bool) -> Scene {
    with_every_material(
        |m| {
            if clearcoat {
                m.clearcoat = 1.0;
                m.clearcoat_roughness = 0.1;
            } else {
                m.sheen_color = glam::Vec3::ONE;
                m.sheen_roughness = 0.5;
            }
        },
        |f| {
            f.clearcoat = clearcoat;
            f.sheen = !clearcoat;
        },
    )
}

/// The demo with its glass sphere a thin wall (KHR_materials_transmission without a
/// volume), or a solid whose inside absorbs (KHR_materials_volume with attenuation).
fn with_glass_volume(volume: bool) -> Scene {
    with_every_material(
        |m| {
            if m.transmission > 0.0 {
                m.thickness = if volume { 2.0 } else { 0.0 };
                m.attenuation_color = glam::Vec3::new(0.9, 0.95, 1.0);
                m.attenuation_distance = 1.0;
            }
        },
        |f| f.volume = volume,
    )
}

/// The demo with its glass sphere an impedance-matched n = −1 metamaterial.
fn with_metamaterial() -> Scene {
    with_every_material(
        |m| {
            if m.transmission > 0.0 {
                m.metamaterial = Some(Metamaterial {
                    refractive_index: -1.0,
                    impedance: 1.0,
                });
            }
        },
        |f| f.metamaterial = true,
    )
}

/// The demo with an iridescent film (factor 1, 400 nm, IOR 1.3) on every material.
fn with_iridescence() -> Scene {
    with_every_material(|m| m.iridescence = 1.0, |f| f.iridescence = true)
}

/// The demo with half of every diffuse base's light passed to the other side.
fn with_diffuse_transmission() -> Scene {
    with_every_material(
        |m| m.diffuse_transmission = 0.5,
        |f| f.diffuse_transmission = true,
    )
}

/// The demo with anisotropy of strength 0.8 on every material, along tangents given to
/// every primitive (the demo's meshes have none).
fn with_anisotropy() -> Scene {
    let mut scene = with_every_material(|m| m.anisotropy_strength = 0.8, |f| f.anisotropy = true);
    for prim in scene.meshes.iter_mut().flat_map(|m| &mut m.primitives) {
        prim.tangents = prim
            .normals
            .iter()
            .map(|&n| tracer::geometry::Frame::from_normal(n).x.extend(1.0))
            .collect();
    }
    scene
}

/// The demo with its metal sphere skinned to one joint that stands where the sphere's node
/// does: the same image, but the sphere is posed by skinning, into a mesh (and BVH) of the
/// frame's own.
fn with_skinning() -> Scene {
    let mut scene = tracer::demo::demo_scene();
    let node = scene
        .nodes
        .iter()
        .position(|n| n.name.as_deref() == Some("metal sphere"))
        .expect("the demo has a metal sphere");
    let mesh = scene.nodes[node].mesh.expect("the sphere's node draws it") as usize;
    for prim in &mut scene.meshes[mesh].primitives {
        let n = prim.positions.len();
        prim.joint_sets = vec![JointSet {
            joints: vec![[0; 4]; n],
            weights: vec![[1.0, 0.0, 0.0, 0.0]; n],
        }];
    }
    let joint = Node {
        name: Some("metal sphere joint".into()),
        local: scene.nodes[node].local,
        trs: scene.nodes[node].trs,
        ..Default::default()
    };
    scene.nodes.push(joint);
    let joint = scene.nodes.len() as u32 - 1;
    scene.roots.push(joint);
    scene.nodes[node].skin = Some(scene.skins.len() as u32);
    scene.skins.push(Skin {
        name: Some("metal sphere skin".into()),
        joints: vec![joint],
        inverse_bind: vec![DMat4::IDENTITY],
    });
    scene.features.skinning = true;
    scene
}

/// The price of an animation with the shutter closed, of the motion path on a still
/// image, of motion blur, of skinning, of transmission, of textures, and of each material
/// extension where every material (or the glass) has it, on `size` images at `spp`.
pub fn feature_costs(size: (u32, u32), spp: u32, runs: u32) -> anyhow::Result<Vec<FeatureCost>> {
    let still = FrameOptions {
        width: size.0,
        height: size.1,
        frame: 12,
        ..Default::default()
    };
    let open = FrameOptions {
        shutter: Shutter {
            open: -0.25,
            close: 0.25,
        },
        ..still.clone()
    };
    // Open for 2e-4 frames: the objects move less than 0.1 mm (the image is the still
    // one), but every ray carries a time and meets interpolated placements.
    let barely_open = FrameOptions {
        shutter: Shutter {
            open: -1e-4,
            close: 1e-4,
        },
        motion_steps: Some(2),
        ..still.clone()
    };
    let demo = tracer::demo::demo_scene;
    let animated = tracer::demo::animated_demo_scene;
    let cost = |feature: &str, without: (Scene, &FrameOptions), with: (Scene, &FrameOptions)| {
        price(feature, without, with, spp, runs)
    };
    Ok(vec![
        cost(
            "animation, shutter closed (still demo vs animated demo at frame 12)",
            (demo(), &still),
            (animated(), &still),
        )?,
        cost(
            "the motion path on a still image (animated demo, shutter closed vs open for \
             2e-4 frames in 2 steps: nothing moves 0.1 mm)",
            (animated(), &still),
            (animated(), &barely_open),
        )?,
        cost(
            "motion blur (animated demo, shutter closed vs -0.25..0.25)",
            (animated(), &still),
            (animated(), &open),
        )?,
        cost(
            "skinning (demo vs its metal sphere skinned to one joint)",
            (demo(), &still),
            (with_skinning(), &still),
        )?,
        cost(
            "transmission (demo with the glass sphere opaque vs glass)",
            (without_transmission(), &still),
            (demo(), &still),
        )?,
        cost(
            "textures (demo vs a near-white 256x256 checker on every material)",
            (demo(), &still),
            (with_textures(), &still),
        )?,
        cost(
            "clear coat (demo vs a coat of roughness 0.1 on every material)",
            (demo(), &still),
            (with_layer(true), &still),
        )?,
        cost(
            "sheen (demo vs a white sheen of roughness 0.5 on every material)",
            (demo(), &still),
            (with_layer(false), &still),
        )?,
        cost(
            "volume (demo with its glass sphere a thin wall vs a solid that absorbs)",
            (with_glass_volume(false), &still),
            (with_glass_volume(true), &still),
        )?,
        cost(
            "iridescence (demo vs a 400 nm film on every material)",
            (demo(), &still),
            (with_iridescence(), &still),
        )?,
        cost(
            "diffuse transmission (demo vs half of every diffuse base passed through)",
            (demo(), &still),
            (with_diffuse_transmission(), &still),
        )?,
        cost(
            "anisotropy (demo vs strength 0.8 on every material)",
            (demo(), &still),
            (with_anisotropy(), &still),
        )?,
        cost(
            "metamaterial (demo's glass sphere vs the sphere as n = -1)",
            (demo(), &still),
            (with_metamaterial(), &still),
        )?,
    ])
}

/// The markdown table of `costs`.
pub fn table(costs: &[FeatureCost]) -> String {
    let mut out = "| feature | without (M paths/s) | with (M paths/s) | cost per path | \
                   prepare without (ms) | prepare with (ms) |\n\
                   |---|---:|---:|---:|---:|---:|\n"
        .to_string();
    for c in costs {
        out += &format!(
            "| {} | {:.3} | {:.3} | {:+.0}% | {:.2} | {:.2} |\n",
            c.feature,
            c.without / 1e6,
            c.with / 1e6,
            c.cost() * 100.0,
            c.prepare_without * 1e3,
            c.prepare_with * 1e3
        );
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_variants_change_only_their_feature() {
        let opaque = without_transmission();
        assert!(!opaque.features.transmission);
        assert!(opaque.materials.iter().all(|m| m.transmission == 0.0));
        let skinned = with_skinning();
        assert!(skinned.features.skinning);
        assert_eq!(skinned.skins.len(), 1);
        let textured = with_textures();
        assert!(textured.features.textures);
        assert_eq!(textured.textures.len(), 1);
        // The textured demo has textures, and its glass the opaque one lacks: transmission
        // into a volume.
        assert_eq!(
            textured.features.names().len(),
            opaque.features.names().len() + 3
        );
        assert!(!opaque.features.names().contains(&"volume"));
        let (coated, sheened) = (with_layer(true), with_layer(false));
        assert!(coated.materials.iter().all(|m| m.clearcoat == 1.0));
        assert!(sheened.materials.iter().all(|m| m.has_sheen()));
        let plus = |extra: &'static str| {
            let mut names = tracer::demo::demo_scene().features.names();
            names.push(extra);
            names.sort_unstable();
            names
        };
        let sorted = |scene: &Scene| {
            let mut names = scene.features.names();
            names.sort_unstable();
            names
        };
        assert_eq!(sorted(&coated), plus("clearcoat"));
        assert_eq!(sorted(&sheened), plus("sheen"));
        assert_eq!(sorted(&with_iridescence()), plus("iridescence"));
        assert_eq!(sorted(&with_metamaterial()), plus("metamaterial"));
        assert_eq!(
            sorted(&with_diffuse_transmission()),
            plus("diffuse-transmission")
        );
        let anisotropic = with_anisotropy();
        assert_eq!(sorted(&anisotropic), plus("anisotropy"));
        assert!(anisotropic.meshes.iter().all(|m| m
            .primitives
            .iter()
            .all(|p| p.tangents.len() == p.positions.len())));
        // The volume row differs in that alone: a thin wall against a solid.
        let (thin, solid) = (with_glass_volume(false), with_glass_volume(true));
        assert!(!thin.features.volume && solid.features.volume);
        assert_eq!(sorted(&solid), sorted(&tracer::demo::demo_scene()));
        assert!(thin.materials.iter().all(|m| !m.is_volume()));
    }

    /// The skinned sphere stands where the plain one does, posed into a mesh of the
    /// frame's own: the first hits agree.
    #[test]
    fn the_skinned_sphere_stands_where_the_plain_one_does() {
        let options = FrameOptions {
            width: 24,
            height: 24,
            ..Default::default()
        };
        let first_hits = |scene: Scene| {
            let frame = prepare_frame(Arc::new(scene), &options).unwrap();
            let settings = RenderSettings {
                max_depth: 0,
                ..RenderSettings::DEFAULT
            };
            let rect = TileRect::new(0, 0, 24, 24);
            let image = render_region(&frame, &settings, rect, SampleRange::new(0, 4), 8, &|_| {});
            (frame.deformed.len(), image.resolve().normal)
        };
        let (plain_deformed, plain) = first_hits(tracer::demo::demo_scene());
        let (skinned_deformed, skinned) = first_hits(with_skinning());
        assert_eq!((plain_deformed, skinned_deformed), (0, 1));
        let sphere = plain.iter().filter(|n| n.length() > 0.5).count();
        let differ = plain
            .iter()
            .zip(&skinned)
            .filter(|(a, b)| (**a - **b).length() > 1e-3)
            .count();
        assert!(sphere > 400, "{sphere} pixels hit something");
        assert!(
            differ <= plain.len() / 100,
            "{differ} of 576 first hits differ"
        );
    }

    #[test]
    fn every_feature_is_priced() {
        let costs = feature_costs((8, 8), 1, 1).unwrap();
        assert_eq!(costs.len(), 13);
        assert!(costs.iter().all(|c| c.without > 0.0 && c.with > 0.0));
        assert!(table(&costs).contains("| motion blur"));
    }
}

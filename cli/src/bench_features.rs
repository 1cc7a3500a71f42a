//! What each scene feature costs in `tessera bench`: camera paths per second of the same
//! demo scene without a feature and with it. A scene should pay only for what it uses, so
//! an animated scene with the shutter closed should cost what the still one does.

use std::sync::Arc;
use std::time::Instant;

use serde::Serialize;

use tracer::film::{SampleRange, TileRect};
use tracer::motion::Shutter;
use tracer::render::{prepare_frame, render_region, FrameOptions, RenderSettings};
use tracer::scene::Scene;
use tracer::texture::{Texture, TextureRef};

/// One feature's price.
#[derive(Serialize)]
pub struct FeatureCost {
    /// The feature, and the two scenes compared.
    pub feature: String,
    /// Camera paths per second without it.
    pub without: f64,
    /// Camera paths per second with it.
    pub with: f64,
}

impl FeatureCost {
    /// The extra time per path it costs, as a fraction (0.1: 10% slower).
    pub fn cost(&self) -> f64 {
        self.without / self.with - 1.0
    }
}

/// Each measurement renders for at least this long, so that short renders time well.
const MIN_SECONDS: f64 = 0.5;

/// Camera paths per second rendering `scene` framed by `options` at `spp` and depth 8,
/// after one warm-up render (the first render of a process builds the BSDF tables).
fn paths_per_second(scene: Scene, options: &FrameOptions, spp: u32) -> anyhow::Result<f64> {
    let frame = prepare_frame(Arc::new(scene), options)?;
    let rect = TileRect::new(0, 0, frame.width, frame.height);
    let render = |spp| {
        render_region(
            &frame,
            &RenderSettings::default(),
            rect,
            SampleRange::new(0, spp),
            8,
            &|_| {},
        )
    };
    render(1);
    let (start, mut renders) = (Instant::now(), 0u32);
    while renders == 0 || start.elapsed().as_secs_f64() < MIN_SECONDS {
        render(spp);
        renders += 1;
    }
    let paths = rect.area() as f64 * f64::from(spp) * f64::from(renders);
    Ok(paths / start.elapsed().as_secs_f64())
}

/// The demo with its glass sphere opaque (a dielectric that does not transmit).
fn without_transmission() -> Scene {
    let mut scene = tracer::demo::demo_scene();
    for m in &mut scene.materials {
        m.transmission = 0.0;
    }
    scene.features.transmission = false;
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

/// The price of motion blur, of an animation with the shutter closed, of transmission and
/// of textures, on `size` images at `spp`.
pub fn feature_costs(size: (u32, u32), spp: u32) -> anyhow::Result<Vec<FeatureCost>> {
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
    let demo = tracer::demo::demo_scene;
    let animated = tracer::demo::animated_demo_scene;
    let cost = |feature: &str, without: (Scene, &FrameOptions), with: (Scene, &FrameOptions)| {
        Ok::<_, anyhow::Error>(FeatureCost {
            feature: feature.into(),
            without: paths_per_second(without.0, without.1, spp)?,
            with: paths_per_second(with.0, with.1, spp)?,
        })
    };
    Ok(vec![
        cost(
            "animation, shutter closed (still demo vs animated demo at frame 12)",
            (demo(), &still),
            (animated(), &still),
        )?,
        cost(
            "motion blur (animated demo, shutter closed vs -0.25..0.25)",
            (animated(), &still),
            (animated(), &open),
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
    ])
}

/// The markdown table of `costs`.
pub fn table(costs: &[FeatureCost]) -> String {
    let mut out = "| feature | without (M paths/s) | with (M paths/s) | cost |\n\
                   |---|---:|---:|---:|\n"
        .to_string();
    for c in costs {
        out += &format!(
            "| {} | {:.3} | {:.3} | {:+.0}% |\n",
            c.feature,
            c.without / 1e6,
            c.with / 1e6,
            c.cost() * 100.0
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
        let textured = with_textures();
        assert!(textured.features.textures);
        assert_eq!(textured.textures.len(), 1);
        assert_eq!(
            textured.features.names().len(),
            opaque.features.names().len() + 2
        );
    }

    #[test]
    fn every_feature_is_priced() {
        let costs = feature_costs((8, 8), 1).unwrap();
        assert_eq!(costs.len(), 4);
        assert!(costs.iter().all(|c| c.without > 0.0 && c.with > 0.0));
        assert!(table(&costs).contains("| motion blur"));
    }
}

//! Scene uploads: validated with the tracer's loader (a malformed scene is refused here,
//! never at a worker) and summarised for the client.

use proto::{AnimationInfo, CameraInfo, SceneInfo};
use tracer::loader::{load_glb, SceneError, SceneSummary};
use tracer::scene::Scene;

use crate::store::sha256_hex;

/// Loads `glb` and describes it; the error is the loader's, naming the glTF element.
pub fn inspect(glb: &[u8]) -> Result<(SceneInfo, Scene), SceneError> {
    let scene = load_glb(glb)?;
    let summary = SceneSummary::of(&scene);
    let cameras = scene
        .cameras
        .iter()
        .enumerate()
        .map(|(i, c)| CameraInfo {
            index: i as u32,
            name: c.name.clone(),
        })
        .collect();
    let animations: Vec<AnimationInfo> = summary
        .animations
        .iter()
        .enumerate()
        .map(|(i, a)| AnimationInfo {
            index: i as u32,
            name: a.name.clone(),
            start_seconds: a.start,
            end_seconds: a.end,
        })
        .collect();
    let duration = animations.iter().map(|a| a.end_seconds).fold(0.0, f64::max);
    let info = SceneInfo {
        digest: sha256_hex(glb),
        size: glb.len() as u64,
        cameras,
        animations,
        duration_seconds: duration,
        triangles: summary.triangles,
        lights: summary.lights as u64,
        meshes: summary.meshes as u64,
        instances: summary.instances as u64,
        materials: summary.materials as u64,
        textures: summary.textures as u64,
        features: summary
            .features
            .names()
            .iter()
            .map(|s| s.to_string())
            .collect(),
        warnings: scene.warnings.clone(),
    };
    Ok((info, scene))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The summary is stored as JSON and read back for every later upload of the same
    /// bytes and for every job on the scene: it must come back bit for bit. Found by
    /// `fuzz/scene_loader`: an animation starting at an f32 subnormal read back one ulp off.
    #[test]
    fn summary_reads_back_from_its_json_bit_for_bit() {
        let start = f32::from_bits(29) as f64; // 4.0637655465419695e-44
        let info = SceneInfo {
            digest: "ab".repeat(32),
            size: 100,
            animations: vec![AnimationInfo {
                index: 0,
                name: Some("Step Scale".into()),
                start_seconds: start,
                end_seconds: 1.0 / 0.6,
            }],
            duration_seconds: 1.0 / 0.6,
            triangles: 1,
            meshes: 1,
            instances: 1,
            materials: 1,
            ..Default::default()
        };
        let json = serde_json::to_string(&info).unwrap();
        let back: SceneInfo = serde_json::from_str(&json).unwrap();
        assert_eq!(back.animations[0].start_seconds.to_bits(), start.to_bits());
        assert_eq!(back, info);
    }
}

//! Tiles in, frames out. Each upload is checked before it is accepted (checksum, sample
//! count, EXR parses, frame size, data window, channels, finite values); when a frame's
//! last tile is in, its sample passes merge by sample-weighted average, the tiles are
//! pasted into the frame, and the frame is written atomically as a multi-layer EXR plus a
//! PNG preview. When a pass of a frame completes before the frame does, a progressive PNG
//! preview is written from the passes in so far.

use std::path::Path;

use glam::{Vec3, Vec4};
use proto::{JobSpec, OutputLayer, ResultMetadata};
use tracer::film::{Layers, SamplingSummary, TileRect, NO_HIT_DEPTH, NO_NOISE_ESTIMATE};
use tracer::output::{self, ExrMetadata, ImageLayer};

use crate::error::{Error, Result, StorageProblem};
use crate::scheduler::TaskRow;
use crate::store::{self, sha256_hex, Store};

/// Checks an uploaded tile against its task and returns its pixels.
pub fn check_tile(
    bytes: &[u8],
    meta: &ResultMetadata,
    task: &TaskRow,
    frame_size: (u32, u32),
) -> Result<Layers> {
    let actual = sha256_hex(bytes);
    if actual != meta.sha256 {
        return Err(Error::BadTile(format!(
            "checksum mismatch: header {} says {}, the {} bytes received hash to {actual}; \
             the upload was damaged, send it again",
            ResultMetadata::SHA256,
            meta.sha256,
            bytes.len()
        )));
    }
    if meta.samples != task.samples.len() {
        return Err(Error::Invalid {
            field: ResultMetadata::SAMPLES.into(),
            message: format!(
                "the task asks for samples {}..{} ({} per pixel) but the tile says {}",
                task.samples.start,
                task.samples.end,
                task.samples.len(),
                meta.samples
            ),
        });
    }
    output::validate_tile(bytes, task.rect, frame_size)
        .map_err(|e| Error::BadTile(format!("tile of task {}: {e}", task.id)))
}

/// Sample-weighted average of the passes of one tile, pixel by pixel (each pass's
/// `samples` layer says how many samples each of its pixels holds). Beauty and albedo
/// average by samples; normals are summed by weight and renormalised; depth averages over
/// the passes that hit something; samples add up. The noise estimates combine as the
/// standard errors of a weighted mean do: `sqrt(Σ (n_k e_k)²) / Σ n_k` over the passes
/// that have one (a pass of a single sample has none).
pub fn merge_passes(parts: &[Layers]) -> Layers {
    if let [only] = parts {
        return only.clone();
    }
    let rect = parts[0].rect;
    let mut out = Layers::new(rect);
    for i in 0..rect.area() {
        let mut beauty = Vec4::ZERO;
        let mut albedo = Vec3::ZERO;
        let mut normal = Vec3::ZERO;
        let (mut depth, mut depth_weight) = (0.0f32, 0.0f32);
        let (mut total, mut noise_sq, mut noise_weight) = (0.0f32, 0.0f64, 0.0f64);
        for layers in parts {
            let w = layers.samples[i];
            total += w;
            beauty += layers.beauty[i] * w;
            albedo += layers.albedo[i] * w;
            normal += layers.normal[i] * w;
            if layers.depth[i] < NO_HIT_DEPTH {
                depth += layers.depth[i] * w;
                depth_weight += w;
            }
            if layers.noise[i] < NO_NOISE_ESTIMATE {
                noise_sq += (f64::from(w) * f64::from(layers.noise[i])).powi(2);
                noise_weight += f64::from(w);
            }
        }
        let inv = if total > 0.0 { total.recip() } else { 0.0 };
        out.samples[i] = total;
        out.noise[i] = if noise_weight > 0.0 {
            (noise_sq.sqrt() / noise_weight) as f32
        } else {
            NO_NOISE_ESTIMATE
        };
        out.beauty[i] = beauty * inv;
        out.albedo[i] = albedo * inv;
        out.normal[i] = normal.normalize_or_zero();
        out.depth[i] = if depth_weight > 0.0 {
            depth / depth_weight
        } else {
            NO_HIT_DEPTH
        };
    }
    out
}

/// The accepted tile of a task, as stored.
pub fn read_tile(store: &Store, job: u64, task: u64) -> Result<Layers> {
    let image = output::read_exr(&store.tile(job, task))
        .map_err(|e| Error::Internal(format!("reading the accepted tile of task {task}: {e}")))?;
    Ok(image.layers)
}

/// A frame as built from its tiles.
pub struct BuiltFrame {
    /// Its layers.
    pub layers: Layers,
    /// Sample passes merged into it (the passes of its tiles are `0..passes`).
    pub passes: u32,
}

/// The header attribute of a merged frame that says how many passes it holds.
const MERGED_PASSES: &str = "tessera/passes";

/// Builds a frame (or, for a preview, as much of it as is in) from the accepted tiles of
/// `tasks` (one frame's done tasks, by tile then pass). A time-budget frame that was
/// assembled before starts from its merged frame, and only the passes it lacks are read.
pub fn build_frame(
    store: &Store,
    spec: &JobSpec,
    job: u64,
    frame_no: i32,
    tasks: &[TaskRow],
) -> Result<BuiltFrame> {
    let (mut frame, merged) = match read_merged(store, job, frame_no)? {
        Some(built) => (built.layers, built.passes),
        None => (Layers::new(TileRect::new(0, 0, spec.width, spec.height)), 0),
    };
    let fresh: Vec<&TaskRow> = tasks.iter().filter(|t| t.pass >= merged).collect();
    let mut passes = merged;
    for group in fresh.chunk_by(|a, b| a.tile == b.tile) {
        let mut parts = Vec::with_capacity(group.len() + 1);
        if merged > 0 {
            parts.push(frame.crop(group[0].rect));
        }
        for t in group {
            parts.push(read_tile(store, t.job_id, t.id)?);
            passes = passes.max(t.pass + 1);
        }
        frame.paste(&merge_passes(&parts));
    }
    Ok(BuiltFrame {
        layers: frame,
        passes,
    })
}

/// The merged frame of a time-budget job's frame, if it was assembled before.
fn read_merged(store: &Store, job: u64, frame_no: i32) -> Result<Option<BuiltFrame>> {
    let path = store.merged_frame(job, frame_no);
    if !path.exists() {
        return Ok(None);
    }
    let image = output::read_exr(&path)
        .map_err(|e| Error::Internal(format!("reading the merged frame {frame_no}: {e}")))?;
    let passes = image
        .attribute(MERGED_PASSES)
        .and_then(|p| p.parse().ok())
        .ok_or_else(|| {
            Error::Internal(format!(
                "the merged frame {frame_no} of job {job} does not say its passes"
            ))
        })?;
    Ok(Some(BuiltFrame {
        layers: image.layers,
        passes,
    }))
}

/// Keeps every layer of a time-budget frame, atomically, for its next pass to merge into.
pub fn write_merged(
    store: &Store,
    job: u64,
    frame_no: i32,
    spec: &JobSpec,
    frame: &BuiltFrame,
) -> Result<()> {
    let meta = ExrMetadata::new().with(MERGED_PASSES, frame.passes.to_string());
    let bytes = output::encode_exr((spec.width, spec.height), &frame.layers, &meta)
        .map_err(|e| Error::Internal(format!("encoding the merged frame {frame_no}: {e}")))?;
    store::write_atomic(&store.merged_frame(job, frame_no), &bytes)?;
    Ok(())
}

/// What a frame's EXR header says beyond its spec.
pub struct FrameFacts {
    /// What its samples reached.
    pub reached: SamplingSummary,
    /// Seconds the workers spent on its tiles.
    pub render_seconds: f64,
    /// What the scene needs from the tracer.
    pub features: Vec<String>,
}

/// Writes the final frame: `frame_NNNN.exr` with the job's layers and `frame_NNNN.png`,
/// both atomically. The EXR's header says how it was rendered: the settings, the samples
/// and estimated error reached, the render time and the scene's features.
pub fn write_frame(
    store: &Store,
    job: u64,
    frame_no: i32,
    spec: &JobSpec,
    frame: &Layers,
    facts: &FrameFacts,
) -> Result<()> {
    let size = (spec.width, spec.height);
    let meta = ExrMetadata::new()
        .with(ExrMetadata::VERSION, env!("CARGO_PKG_VERSION"))
        .with(ExrMetadata::SPP, spec.spp.to_string())
        .with_sampling(&facts.reached)
        .with(
            ExrMetadata::RENDER_SECONDS,
            format!("{:.3}", facts.render_seconds),
        )
        .with(ExrMetadata::FEATURES, facts.features.join(","))
        .with(ExrMetadata::SETTINGS, serde_json::to_string(spec)?)
        .with("tessera/job", job.to_string())
        .with("tessera/frame", frame_no.to_string());
    let bytes = encode_layers(size, frame, &spec.layers, &meta)?;
    store::write_atomic(&store.frame(job, frame_no, "exr"), &bytes)?;
    write_preview(store, job, frame_no, spec, frame)
}

/// Writes `frame_NNNN.png` atomically.
pub fn write_preview(
    store: &Store,
    job: u64,
    frame_no: i32,
    spec: &JobSpec,
    frame: &Layers,
) -> Result<()> {
    let path = store.frame(job, frame_no, "png");
    std::fs::create_dir_all(path.parent().unwrap_or(Path::new(".")))?;
    output::write_preview_png(&path, (spec.width, spec.height), frame, 0.0).map_err(|e| {
        // A full or read-only disk is the operator's to fix, not a bug: say so (507/503).
        let problem = match &e {
            output::OutputError::Io { source, .. } => StorageProblem::of_io(source),
            _ => None,
        };
        let detail = format!("writing preview: {e}");
        match problem {
            Some(problem) => Error::Storage { problem, detail },
            None => Error::Internal(detail),
        }
    })
}

/// The EXR bytes of `layers` with only the `wanted` layers (beauty always).
fn encode_layers(
    size: (u32, u32),
    layers: &Layers,
    wanted: &[OutputLayer],
    meta: &ExrMetadata,
) -> Result<Vec<u8>> {
    let wanted: Vec<ImageLayer> = wanted
        .iter()
        .map(|l| match l {
            OutputLayer::Beauty => ImageLayer::Beauty,
            OutputLayer::Albedo => ImageLayer::Albedo,
            OutputLayer::Normal => ImageLayer::Normal,
            OutputLayer::Depth => ImageLayer::Depth,
            OutputLayer::Samples => ImageLayer::Samples,
            OutputLayer::Noise => ImageLayer::Noise,
        })
        .collect();
    output::encode_exr_layers(size, layers, meta, &wanted, output::ExrCompression::Zip)
        .map_err(|e| Error::Internal(format!("encoding frame: {e}")))
}

#[cfg(test)]
mod tests {
    use super::*;
    use tracer::film::SampleRange;

    fn layers(rect: TileRect, v: f32, depth: f32, samples: f32) -> Layers {
        let mut l = Layers::new(rect);
        l.samples.iter_mut().for_each(|s| *s = samples);
        l.noise.iter_mut().for_each(|e| *e = 0.1);
        l.beauty
            .iter_mut()
            .for_each(|b| *b = Vec4::new(v, v * 2.0, v * 3.0, 1.0));
        l.albedo.iter_mut().for_each(|a| *a = Vec3::splat(v));
        l.normal.iter_mut().for_each(|n| *n = Vec3::Z);
        l.depth.iter_mut().for_each(|d| *d = depth);
        l
    }

    #[test]
    fn passes_merge_by_sample_weight() {
        let rect = TileRect::new(0, 0, 2, 1);
        // 1 sample of 1.0 and 3 samples of 3.0 average to 2.5.
        let merged = merge_passes(&[
            layers(rect, 1.0, 4.0, 1.0),
            layers(rect, 3.0, NO_HIT_DEPTH, 3.0),
        ]);
        assert_eq!(merged.beauty[0], Vec4::new(2.5, 5.0, 7.5, 1.0));
        assert_eq!(merged.albedo[1], Vec3::splat(2.5));
        assert_eq!(merged.normal[0], Vec3::Z);
        // Only the first pass hit: its depth stands.
        assert_eq!(merged.depth[0], 4.0);
        assert_eq!(merged.samples[0], 4.0);
        // Standard errors of 0.1 at 1 and 3 samples: sqrt(0.1² + 0.3²) / 4.
        assert!((merged.noise[1] - 0.1f32.hypot(0.3) / 4.0).abs() < 1e-7);
        let none = merge_passes(&[
            layers(rect, 1.0, NO_HIT_DEPTH, 2.0),
            layers(rect, 1.0, NO_HIT_DEPTH, 2.0),
        ]);
        assert_eq!(none.depth[1], NO_HIT_DEPTH);
        // Two halves of equal error make an error 1/√2 of it.
        assert!((none.noise[0] - 0.1 / 2f32.sqrt()).abs() < 1e-7);
    }

    /// A time-budget frame: its first pass is merged and kept, the tiles go, the next pass
    /// merges into it; assembling again after a crash (the merged frame written, the frame
    /// not yet marked) reads no tile and merges nothing twice.
    #[test]
    fn a_merged_frame_takes_only_the_passes_it_lacks() {
        let dir = tempfile::tempdir().unwrap();
        let store = Store::open(dir.path()).unwrap();
        let mut spec = JobSpec::new("s");
        (spec.width, spec.height) = (4, 2);
        let (left, right) = (TileRect::new(0, 0, 2, 2), TileRect::new(2, 0, 2, 2));
        let task = |id, tile, pass, rect| TaskRow {
            id,
            job_id: 1,
            frame: 3,
            tile,
            pass,
            rect,
            samples: SampleRange::new(0, 4),
            state: crate::state::TaskState::Done,
            attempt: 1,
            failures: 0,
            worker_id: Some(1),
            check_of: None,
        };
        let put = |t: &TaskRow, v: f32| {
            let bytes =
                output::encode_exr((4, 2), &layers(t.rect, v, 1.0, 4.0), &ExrMetadata::new())
                    .unwrap();
            std::fs::create_dir_all(store.tile_dir(1)).unwrap();
            std::fs::write(store.tile(1, t.id), bytes).unwrap();
        };
        let first = [task(10, 0, 0, left), task(11, 1, 0, right)];
        put(&first[0], 1.0);
        put(&first[1], 1.0);
        let built = build_frame(&store, &spec, 1, 3, &first).unwrap();
        assert_eq!(built.passes, 1);
        write_merged(&store, 1, 3, &spec, &built).unwrap();
        for t in &first {
            std::fs::remove_file(store.tile(1, t.id)).unwrap();
        }
        // The next pass covers the left tile: 4 samples of 3.0 join 4 of 1.0 there.
        let second = task(12, 0, 1, left);
        put(&second, 3.0);
        let all = [first[0].clone(), second.clone(), first[1].clone()];
        let built = build_frame(&store, &spec, 1, 3, &all).unwrap();
        assert_eq!(built.passes, 2);
        let at = |b: &BuiltFrame, x: usize| (b.layers.beauty[x].x, b.layers.samples[x]);
        assert_eq!((at(&built, 0), at(&built, 3)), ((2.0, 8.0), (1.0, 4.0)));
        write_merged(&store, 1, 3, &spec, &built).unwrap();
        std::fs::remove_file(store.tile(1, second.id)).unwrap();
        let again = build_frame(&store, &spec, 1, 3, &all).unwrap();
        assert_eq!((again.passes, again.layers), (2, built.layers));
    }

    #[test]
    fn one_pass_is_kept_bit_for_bit() {
        let rect = TileRect::new(4, 2, 3, 2);
        let l = layers(rect, 0.1234567, 9.87654, 7.0);
        assert_eq!(merge_passes(std::slice::from_ref(&l)), l);
    }

    #[test]
    fn layer_subset_writes_only_those_channels() {
        let rect = TileRect::new(0, 0, 4, 3);
        let l = layers(rect, 0.5, 2.0, 4.0);
        let bytes = encode_layers(
            (4, 3),
            &l,
            &[OutputLayer::Beauty, OutputLayer::Depth],
            &ExrMetadata::new().with("tessera/frame", "7"),
        )
        .unwrap();
        let image = output::decode_exr(&bytes).unwrap();
        assert_eq!(image.layers.beauty, l.beauty);
        assert_eq!(image.layers.depth, l.depth);
        // Albedo was not written: the decoder fills it with black.
        assert!(image.layers.albedo.iter().all(|a| *a == Vec3::ZERO));
        assert_eq!(image.attribute("tessera/frame"), Some("7"));
        let all = encode_layers((4, 3), &l, &OutputLayer::ALL, &ExrMetadata::new()).unwrap();
        assert_eq!(output::decode_exr(&all).unwrap().layers, l);
        assert!(bytes.len() < all.len());
    }
}

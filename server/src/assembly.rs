//! Tiles in, frames out. Each upload is checked before it is accepted (checksum, sample
//! count, EXR parses, frame size, data window, channels, finite values); when a frame's
//! last tile is in, its sample passes merge by sample-weighted average, the tiles are
//! pasted into the frame, and the frame is written atomically as a multi-layer EXR plus a
//! PNG preview. When a pass of a frame completes before the frame does, a progressive PNG
//! preview is written from the passes in so far.
//!
//! A frame is never held whole: it is made and written a band of rows at a time, reading
//! only those rows of each tile, so what assembly holds ([`assembly_bytes`]) grows with
//! the band's rows, the frame's width and the tile size but not with the frame's height.
//! Bands are as large as the server's assembly memory allows ([`band_rows`]); a job whose
//! frames would not fit even a block of rows at a time is refused when it is submitted.

use std::path::{Path, PathBuf};

use glam::{Vec2, Vec3, Vec4};
use proto::{JobSpec, OutputLayer, ResultMetadata};
use tracer::film::{
    Layers, SamplingSummary, SamplingTally, TileRect, NO_HIT_DEPTH, NO_NOISE_ESTIMATE,
};
use tracer::output::{self, ExrCompression, ExrMetadata, ExrTarget, ImageLayer, PreviewTarget};

use crate::db::tasks::TaskRow;
use crate::error::{Error, Result};
use crate::limits::MAX_TILE_SIZE;
use crate::store::{sha256_hex, Store};

/// Checks that an upload's bytes hash to the SHA-256 its header says.
pub fn check_checksum(bytes: &[u8], meta: &ResultMetadata) -> Result<()> {
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
    Ok(())
}

/// Checks the upload of a step after rendering (a denoise or encode task, which renders
/// no samples): its checksum, and that it says 0 samples.
pub fn check_step_upload(bytes: &[u8], meta: &ResultMetadata, task: &TaskRow) -> Result<()> {
    check_checksum(bytes, meta)?;
    if meta.samples != 0 {
        return Err(Error::Invalid {
            field: ResultMetadata::SAMPLES.into(),
            message: format!(
                "task {} is a {} step: it renders no samples, the upload says {}",
                task.id,
                task.kind.as_str(),
                meta.samples
            ),
        });
    }
    Ok(())
}

/// Checks an uploaded tile against its task and returns its pixels.
pub fn check_tile(
    bytes: &[u8],
    meta: &ResultMetadata,
    task: &TaskRow,
    frame_size: (u32, u32),
) -> Result<Layers> {
    check_checksum(bytes, meta)?;
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
/// average by samples, and so do motion vectors; normals are summed by weight and
/// renormalised; depth averages over the passes that hit something; samples add up. The
/// noise estimates combine as the standard errors of a weighted mean do:
/// `sqrt(Σ (n_k e_k)²) / Σ n_k` over the passes that have one (a pass of a single sample
/// has none), and the variances as its variance does: `Σ n_k² v_k / (Σ n_k)²`.
pub fn merge_passes(parts: &[Layers]) -> Layers {
    let mut merge = PassMerge::default();
    for part in parts {
        merge.add(part.clone());
    }
    merge.finish()
}

/// [`merge_passes`] one pass at a time, holding running sums instead of every pass: the
/// same sums in the same order, so the same bits. A single pass is kept as it is.
#[derive(Default)]
struct PassMerge {
    first: Option<Layers>,
    sums: Option<PassSums>,
}

/// Per-pixel running sums of [`PassMerge`].
struct PassSums {
    rect: TileRect,
    total: Vec<f32>,
    beauty: Vec<Vec4>,
    albedo: Vec<Vec3>,
    normal: Vec<Vec3>,
    depth: Vec<(f32, f32)>,
    noise: Vec<(f64, f64)>,
    motion: Vec<Vec2>,
    variance: Vec<(Vec3, f32)>,
}

impl PassMerge {
    /// Adds the next pass (the same rectangle as the others).
    fn add(&mut self, part: Layers) {
        if self.first.is_none() && self.sums.is_none() {
            self.first = Some(part);
            return;
        }
        let sums = self.sums.get_or_insert_with(|| PassSums::new(part.rect));
        if let Some(first) = self.first.take() {
            sums.add(&first);
        }
        sums.add(&part);
    }

    /// The merged layers (empty layers of no rectangle if nothing was added).
    fn finish(self) -> Layers {
        match (self.first, self.sums) {
            (Some(only), _) => only,
            (None, Some(sums)) => sums.finish(),
            (None, None) => Layers::new(TileRect::new(0, 0, 0, 0)),
        }
    }
}

impl PassSums {
    fn new(rect: TileRect) -> Self {
        let n = rect.area();
        PassSums {
            rect,
            total: vec![0.0; n],
            beauty: vec![Vec4::ZERO; n],
            albedo: vec![Vec3::ZERO; n],
            normal: vec![Vec3::ZERO; n],
            depth: vec![(0.0, 0.0); n],
            noise: vec![(0.0, 0.0); n],
            motion: vec![Vec2::ZERO; n],
            variance: vec![(Vec3::ZERO, 0.0); n],
        }
    }

    fn add(&mut self, layers: &Layers) {
        assert_eq!(
            layers.rect, self.rect,
            "passes of one tile cover one rectangle"
        );
        for i in 0..self.rect.area() {
            let w = layers.samples[i];
            self.total[i] += w;
            self.beauty[i] += layers.beauty[i] * w;
            self.albedo[i] += layers.albedo[i] * w;
            self.normal[i] += layers.normal[i] * w;
            self.motion[i] += layers.motion[i] * w;
            if layers.variance[i].x < NO_NOISE_ESTIMATE {
                self.variance[i].0 += layers.variance[i] * (w * w);
                self.variance[i].1 += w;
            }
            if layers.depth[i] < NO_HIT_DEPTH {
                self.depth[i].0 += layers.depth[i] * w;
                self.depth[i].1 += w;
            }
            if layers.noise[i] < NO_NOISE_ESTIMATE {
                self.noise[i].0 += (f64::from(w) * f64::from(layers.noise[i])).powi(2);
                self.noise[i].1 += f64::from(w);
            }
        }
    }

    fn finish(self) -> Layers {
        let mut out = Layers::new(self.rect);
        for i in 0..self.rect.area() {
            let total = self.total[i];
            let inv = if total > 0.0 { total.recip() } else { 0.0 };
            let (noise_sq, noise_weight) = self.noise[i];
            let (depth, depth_weight) = self.depth[i];
            out.samples[i] = total;
            out.noise[i] = if noise_weight > 0.0 {
                (noise_sq.sqrt() / noise_weight) as f32
            } else {
                NO_NOISE_ESTIMATE
            };
            out.beauty[i] = self.beauty[i] * inv;
            out.albedo[i] = self.albedo[i] * inv;
            out.motion[i] = self.motion[i] * inv;
            let (variance, variance_weight) = self.variance[i];
            out.variance[i] = if variance_weight > 0.0 {
                variance / (variance_weight * variance_weight)
            } else {
                Vec3::splat(NO_NOISE_ESTIMATE)
            };
            out.normal[i] = self.normal[i].normalize_or_zero();
            out.depth[i] = if depth_weight > 0.0 {
                depth / depth_weight
            } else {
                NO_HIT_DEPTH
            };
        }
        out
    }
}

/// The tile of a task's `attempt`, as stored.
pub fn read_tile(store: &Store, job: u64, task: u64, attempt: u32) -> Result<Layers> {
    let image = output::read_exr(&store.tile(job, task, attempt))
        .map_err(|e| Error::Internal(format!("reading the accepted tile of task {task}: {e}")))?;
    Ok(image.layers)
}

/// Pixels of a frame assembled at a time, at most: a band of whole rows. Enough ZIP
/// blocks per band that compressing them keeps every core busy (64-row bands of a
/// 2560-wide frame assembled 1.5x slower than the whole frame did); more buys nothing.
const BAND_PIXELS: u32 = 1 << 20;

/// Bytes of one pixel of [`Layers`]: 13 `f32` channels.
const LAYER_BYTES: u64 = 13 * 4;
/// Bytes of one pixel of the running sums of several passes.
const SUM_BYTES: u64 = 4 + 16 + 12 + 12 + 8 + 16;
/// Held besides the pixels: code, the database's cache, buffers of files and the PNG
/// encoder.
const ASSEMBLY_OVERHEAD_BYTES: u64 = 16 << 20;

/// The most memory that assembling a frame of `spec` takes with bands of `rows` rows, in
/// bytes: a band (its layers, its preview rows, its EXR blocks before and after
/// compression) and one tile's share of it being merged (a pass read, the first pass
/// kept, the sums, the merged result). It does not grow with the frame's height, the
/// number of tiles or of passes.
pub fn assembly_bytes(spec: &JobSpec, rows: u32) -> u64 {
    let band = u64::from(rows);
    let width = u64::from(spec.width);
    // A tile's rows are read in whole blocks: up to a block more at either end.
    let tile_rows = band + 2 * u64::from(output::BLOCK_ROWS);
    let tile = u64::from(spec.tile_size.unwrap_or(MAX_TILE_SIZE).min(spec.width));
    width * band * (3 * LAYER_BYTES + 4)
        + tile * tile_rows * (3 * LAYER_BYTES + SUM_BYTES)
        + ASSEMBLY_OVERHEAD_BYTES
}

/// Rows of a frame of `spec` assembled at a time within `budget` bytes: up to
/// `BAND_PIXELS`, in whole ZIP blocks, fewer where the budget is tight; `None` when
/// even one block of rows does not fit.
pub fn band_rows(spec: &JobSpec, budget: u64) -> Option<u32> {
    let block = output::BLOCK_ROWS;
    let blocks = (BAND_PIXELS / spec.width.max(1) / block).max(1);
    (1..=blocks)
        .rev()
        .map(|n| n * block)
        .find(|&rows| assembly_bytes(spec, rows) <= budget)
}

/// Refuses a spec whose frames this server cannot assemble within `budget` bytes, even a
/// block of rows at a time, naming the field that sets the size.
pub fn check_assembly_memory(spec: &JobSpec, budget: u64) -> Result<()> {
    if band_rows(spec, budget).is_some() {
        return Ok(());
    }
    let mib = |b: u64| b.div_ceil(1 << 20);
    Err(Error::Invalid {
        field: "width".into(),
        message: format!(
            "assembling a frame {} pixels wide (tiles of {}) takes at least {} MiB, over this \
             server's assembly memory of {} MiB (tessera server --assembly-memory); use a \
             smaller width or tile_size, or give the server more",
            spec.width,
            spec.tile_size.unwrap_or(MAX_TILE_SIZE),
            mib(assembly_bytes(spec, output::BLOCK_ROWS)),
            mib(budget)
        ),
    })
}

/// Where a frame's pixels come from: its accepted tiles, by tile then pass, and for a
/// time-budget frame assembled before, its merged frame (only the passes it lacks are
/// read from tiles). It makes the frame one band at a time.
pub struct FrameSource<'a> {
    store: &'a Store,
    spec: &'a JobSpec,
    job: u64,
    frame_no: i32,
    /// The merged frame and the passes it holds.
    merged: Option<(PathBuf, u32)>,
    /// The tasks whose tiles are read: those of passes the merged frame lacks.
    fresh: Vec<&'a TaskRow>,
    /// Passes the frame holds once made.
    passes: u32,
    /// Rows made at a time.
    band_rows: u32,
    /// Asked before each band: an error stops the assembly (the job went away).
    proceed: Box<dyn Fn() -> Result<()> + 'a>,
}

impl<'a> FrameSource<'a> {
    /// The source of frame `frame_no` of `job` from `tasks` (its done tasks, by tile then
    /// pass), making bands as large as `budget` bytes allow ([`band_rows`]); a frame that
    /// does not fit even a block of rows at a time is [`Error::BadFrame`].
    pub fn new(
        store: &'a Store,
        spec: &'a JobSpec,
        job: u64,
        frame_no: i32,
        tasks: &'a [TaskRow],
        budget: u64,
    ) -> Result<Self> {
        // The job was accepted within a budget, but the server may have been restarted
        // with a smaller one since.
        check_assembly_memory(spec, budget).map_err(|e| Error::BadFrame(e.to_string()))?;
        let band_rows = band_rows(spec, budget).unwrap_or(output::BLOCK_ROWS);
        let merged = merged_passes(store, job, frame_no)?;
        let held = merged.as_ref().map_or(0, |m| m.1);
        let fresh: Vec<&TaskRow> = tasks.iter().filter(|t| t.pass >= held).collect();
        let passes = fresh.iter().map(|t| t.pass + 1).fold(held, u32::max);
        Ok(FrameSource {
            store,
            spec,
            job,
            frame_no,
            merged,
            fresh,
            passes,
            band_rows,
            proceed: Box::new(|| Ok(())),
        })
    }

    /// `self`, asking `proceed` before each band.
    pub fn with_proceed(mut self, proceed: impl Fn() -> Result<()> + 'a) -> Self {
        self.proceed = Box::new(proceed);
        self
    }

    /// Sample passes merged into the frame (the passes of its tiles are `0..passes`).
    pub fn passes(&self) -> u32 {
        self.passes
    }

    /// The frame's size.
    fn size(&self) -> (u32, u32) {
        (self.spec.width, self.spec.height)
    }

    /// The frame's pixels in `band` (full-width rows).
    pub fn band(&self, band: TileRect) -> Result<Layers> {
        (self.proceed)()?;
        let rows = band.y..band.y + band.height;
        let mut out = match &self.merged {
            Some((path, _)) => read_rows(path, rows.clone(), self.frame_no)?,
            None => Layers::new(band),
        };
        for group in self.fresh.chunk_by(|a, b| a.tile == b.tile) {
            let rect = group[0].rect;
            let top = rect.y.max(band.y);
            let bottom = (rect.y + rect.height).min(band.y + band.height);
            if top >= bottom {
                continue;
            }
            let sub = TileRect::new(rect.x, top, rect.width, bottom - top);
            let mut merge = PassMerge::default();
            if self.merged.is_some() {
                merge.add(out.crop(sub));
            }
            for t in group {
                let path = self.store.tile(t.job_id, t.id, t.attempt);
                let part = output::read_exr_rows(&path, top..bottom)
                    .map_err(|e| {
                        Error::BadFrame(format!("reading the tile of task {}: {e}", t.id))
                    })?
                    .layers;
                if part.rect != sub {
                    return Err(Error::BadFrame(format!(
                        "the tile of task {} covers {:?}, not its task's {:?}",
                        t.id, part.rect, sub
                    )));
                }
                merge.add(part);
            }
            out.paste(&merge.finish());
        }
        Ok(out)
    }

    /// What the frame's samples reached, over all its pixels.
    pub fn sampling(&self) -> Result<SamplingSummary> {
        let mut tally = SamplingTally::default();
        for band in output::frame_bands(self.size(), self.band_rows) {
            tally.add(&self.band(band)?);
        }
        Ok(tally.summary())
    }
}

/// Rows of a merged frame.
fn read_rows(path: &Path, rows: std::ops::Range<u32>, frame_no: i32) -> Result<Layers> {
    output::read_exr_rows(path, rows)
        .map(|image| image.layers)
        .map_err(|e| Error::BadFrame(format!("reading the merged frame {frame_no}: {e}")))
}

/// The header attribute of a merged frame that says how many passes it holds.
const MERGED_PASSES: &str = "tessera/passes";

/// The merged frame of a time-budget job's frame and the passes it holds, if it was
/// assembled before.
fn merged_passes(store: &Store, job: u64, frame_no: i32) -> Result<Option<(PathBuf, u32)>> {
    let path = store.merged_frame(job, frame_no);
    if !path.exists() {
        return Ok(None);
    }
    // Reading no rows reads the header alone.
    let image = output::read_exr_rows(&path, 0..0)
        .map_err(|e| Error::BadFrame(format!("reading the merged frame {frame_no}: {e}")))?;
    let passes = image
        .attribute(MERGED_PASSES)
        .and_then(|p| p.parse().ok())
        .ok_or_else(|| {
            Error::BadFrame(format!(
                "the merged frame {frame_no} of job {job} does not say its passes"
            ))
        })?;
    Ok(Some((path, passes)))
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

impl FrameSource<'_> {
    /// Keeps every layer of a time-budget frame, atomically, for its next pass to merge
    /// into. A source made after this reads the merged frame alone.
    pub fn write_merged(&self) -> Result<()> {
        let meta = ExrMetadata::new().with(MERGED_PASSES, self.passes.to_string());
        let path = self.store.merged_frame(self.job, self.frame_no);
        let target = ExrTarget {
            path: &path,
            meta: &meta,
            layers: &ImageLayer::RENDERED,
            compression: ExrCompression::Zip,
        };
        self.write_bands(Some(target), false)
            .map_err(|e| e.context(format!("writing the merged frame {}", self.frame_no)))
    }

    /// The job's last frame, which sets how wide its frame numbers are written.
    fn last_frame(&self) -> i32 {
        self.spec.frames.map_or(self.frame_no, |f| f.last())
    }

    /// Writes the final frame: `frame_NNNN.exr` with the job's layers and
    /// `frame_NNNN.png`, both atomically, in one pass over the frame's bands. The EXR's
    /// header says how it was rendered: the settings, the samples and estimated error
    /// reached, the render time and the scene's features.
    pub fn write_frame(&self, facts: &FrameFacts) -> Result<()> {
        let (spec, job, frame_no) = (self.spec, self.job, self.frame_no);
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
        let exr = self.store.frame(job, frame_no, self.last_frame(), "exr");
        let layers = image_layers(&spec.layers);
        let target = ExrTarget {
            path: &exr,
            meta: &meta,
            layers: &layers,
            compression: ExrCompression::Zip,
        };
        self.write_bands(Some(target), true)
            .map_err(|e| e.context(format!("writing frame {frame_no}")))
    }

    /// Writes `frame_NNNN.png` alone, atomically: a progressive preview.
    pub fn write_preview(&self) -> Result<()> {
        self.write_bands(None, true)
            .map_err(|e| e.context(format!("writing the preview of frame {}", self.frame_no)))
    }

    /// [`output::write_frame_in_bands`] of this frame: `exr` if given, and the frame's
    /// PNG preview (in the job's output folder, with the final EXR) if `preview`.
    fn write_bands(&self, exr: Option<ExrTarget>, preview: bool) -> Result<()> {
        let png = self
            .store
            .frame(self.job, self.frame_no, self.last_frame(), "png");
        if preview {
            std::fs::create_dir_all(self.store.job_dir(self.job))?;
        }
        let preview = preview.then_some(PreviewTarget {
            path: &png,
            exposure: 0.0,
        });
        output::write_frame_in_bands(self.size(), self.band_rows, exr, preview, |band| {
            self.band(band)
        })
    }
}

/// The tracer's layers for the job's output layers.
pub fn image_layers(wanted: &[OutputLayer]) -> Vec<ImageLayer> {
    wanted
        .iter()
        .map(|l| match l {
            OutputLayer::Beauty => ImageLayer::Beauty,
            OutputLayer::Albedo => ImageLayer::Albedo,
            OutputLayer::Normal => ImageLayer::Normal,
            OutputLayer::Depth => ImageLayer::Depth,
            OutputLayer::Samples => ImageLayer::Samples,
            OutputLayer::Noise => ImageLayer::Noise,
            OutputLayer::Motion => ImageLayer::Motion,
            OutputLayer::Variance => ImageLayer::Variance,
        })
        .collect()
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
        l.motion.iter_mut().for_each(|m| *m = Vec2::new(v, -v));
        if samples >= 2.0 {
            l.variance.iter_mut().for_each(|e| *e = Vec3::splat(0.01));
        }
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
        assert_eq!(merged.motion[0], Vec2::new(2.5, -2.5));
        // Only the second pass (3 samples) has a variance: 3² · 0.01 / 3².
        assert_eq!(merged.variance[0], Vec3::splat(0.01));
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
        // And a variance of half of it: (2² · 0.01 + 2² · 0.01) / 4².
        assert_eq!(none.variance[1], Vec3::splat(0.005));
    }

    fn task(id: u64, tile: u32, pass: u32, rect: TileRect) -> TaskRow {
        TaskRow {
            id,
            kind: proto::TaskKind::Render,
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
        }
    }

    /// Stores `layers` as the accepted tile of `t`.
    fn put(store: &Store, size: (u32, u32), t: &TaskRow, layers: &Layers) {
        let bytes = output::encode_exr(size, layers, &ExrMetadata::new()).unwrap();
        std::fs::create_dir_all(store.tile_dir(1)).unwrap();
        std::fs::write(store.tile(1, t.id, t.attempt), bytes).unwrap();
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
        let whole = TileRect::new(0, 0, 4, 2);
        let (left, right) = (TileRect::new(0, 0, 2, 2), TileRect::new(2, 0, 2, 2));
        let first = [task(10, 0, 0, left), task(11, 1, 0, right)];
        put(&store, (4, 2), &first[0], &layers(left, 1.0, 1.0, 4.0));
        put(&store, (4, 2), &first[1], &layers(right, 1.0, 1.0, 4.0));
        let source = FrameSource::new(&store, &spec, 1, 3, &first, 1 << 30).unwrap();
        assert_eq!(source.passes(), 1);
        source.write_merged().unwrap();
        for t in &first {
            std::fs::remove_file(store.tile(1, t.id, t.attempt)).unwrap();
        }
        // The next pass covers the left tile: 4 samples of 3.0 join 4 of 1.0 there.
        let second = task(12, 0, 1, left);
        put(&store, (4, 2), &second, &layers(left, 3.0, 1.0, 4.0));
        let all = [first[0].clone(), second.clone(), first[1].clone()];
        let source = FrameSource::new(&store, &spec, 1, 3, &all, 1 << 30).unwrap();
        assert_eq!(source.passes(), 2);
        let built = source.band(whole).unwrap();
        let at = |b: &Layers, x: usize| (b.beauty[x].x, b.samples[x]);
        assert_eq!((at(&built, 0), at(&built, 3)), ((2.0, 8.0), (1.0, 4.0)));
        source.write_merged().unwrap();
        std::fs::remove_file(store.tile(1, second.id, second.attempt)).unwrap();
        let again = FrameSource::new(&store, &spec, 1, 3, &all, 1 << 30).unwrap();
        assert_eq!((again.passes(), again.band(whole).unwrap()), (2, built));
    }

    /// A frame taller than a band, in tiles that straddle the bands' edges, some of two
    /// passes: written band by band, its EXR holds the tiles merged and pasted as a whole
    /// frame would, only the spec's layers, and its PNG is the whole frame's preview byte
    /// for byte.
    #[test]
    fn a_frame_written_band_by_band_is_its_tiles_merged_and_pasted() {
        let dir = tempfile::tempdir().unwrap();
        let store = Store::open(dir.path()).unwrap();
        // Bands of 64 rows, not the million pixels of a real one, keep the test small.
        let size = (40, 64 + 30);
        let mut spec = JobSpec::new("s");
        (spec.width, spec.height) = size;
        spec.layers = vec![OutputLayer::Beauty, OutputLayer::Depth];
        let mut expected = Layers::new(TileRect::new(0, 0, size.0, size.1));
        let mut tasks = Vec::new();
        for (tile, rect) in expected.rect.tiles(24).into_iter().enumerate() {
            let tile = tile as u32;
            let passes = 1 + tile % 2;
            let parts: Vec<Layers> = (0..passes)
                .map(|p| {
                    let v = 0.01 * (tile * 7 + p * 3) as f32;
                    layers(rect, v, 1.0 + v, 1.0 + p as f32)
                })
                .collect();
            for (p, part) in parts.iter().enumerate() {
                let t = task(100 + tasks.len() as u64, tile, p as u32, rect);
                put(&store, size, &t, part);
                tasks.push(t);
            }
            expected.paste(&merge_passes(&parts));
        }
        let mut source = FrameSource::new(&store, &spec, 1, 3, &tasks, 1 << 30).unwrap();
        source.band_rows = 64;
        let facts = FrameFacts {
            reached: source.sampling().unwrap(),
            render_seconds: 1.5,
            features: vec![],
        };
        assert_eq!(facts.reached, expected.sampling());
        source.write_frame(&facts).unwrap();

        let image = output::read_exr(&store.frame(1, 3, 3, "exr")).unwrap();
        assert_eq!(image.layers.beauty, expected.beauty);
        assert_eq!(image.layers.depth, expected.depth);
        // Albedo was not asked for: the reader fills it with black.
        assert!(image.layers.albedo.iter().all(|a| *a == Vec3::ZERO));
        assert_eq!(image.attribute("tessera/frame"), Some("3"));
        let png = std::fs::read(store.frame(1, 3, 3, "png")).unwrap();
        assert_eq!(
            png,
            output::encode_preview_png(size, &expected, 0.0).unwrap()
        );
    }

    #[test]
    fn one_pass_is_kept_bit_for_bit() {
        let rect = TileRect::new(4, 2, 3, 2);
        let l = layers(rect, 0.1234567, 9.87654, 7.0);
        assert_eq!(merge_passes(std::slice::from_ref(&l)), l);
    }

    /// What assembly holds grows with the band's rows and the width, not the height;
    /// a tight budget gets narrower bands, and one that fits not even a block of rows
    /// refuses the job naming the width.
    #[test]
    fn bands_fit_the_assembly_memory() {
        let mut spec = JobSpec::new("s");
        (spec.width, spec.height, spec.tile_size) = (1920, 1080, Some(64));
        let hd = assembly_bytes(&spec, 64);
        spec.height = crate::limits::MAX_RESOLUTION;
        assert_eq!(assembly_bytes(&spec, 64), hd);
        // A million pixels a band: 544 rows of 1920, in whole blocks.
        assert_eq!(band_rows(&spec, 1 << 30), Some(544));
        assert_eq!(band_rows(&spec, assembly_bytes(&spec, 64)), Some(64));

        (spec.width, spec.tile_size) = (crate::limits::MAX_RESOLUTION, Some(MAX_TILE_SIZE));
        assert_eq!(
            band_rows(&spec, crate::limits::DEFAULT_ASSEMBLY_MEMORY),
            Some(64)
        );
        let largest = assembly_bytes(&spec, 64);
        assert!(largest < 512 << 20, "{largest} bytes");
        let least = assembly_bytes(&spec, output::BLOCK_ROWS);
        check_assembly_memory(&spec, least).unwrap();
        let err = check_assembly_memory(&spec, least - 1).unwrap_err();
        assert!(
            matches!(&err, Error::Invalid { field, .. } if field == "width"),
            "{err}"
        );
        assert!(err.to_string().contains("--assembly-memory"), "{err}");
    }
}

//! A worker's tile upload, body and metadata from the input, through
//! `server::assembly::check_tile` for a fixed task; a tile it accepts must then read back
//! from the store and paste into the frame as assembly does. A refusal is fine; a panic, a
//! hang or a large allocation is a finding.
//!
//! Input: `flags, samples (u32 LE), body`. The metadata's checksum is the body's own
//! unless flag 1 damages it (else almost nothing would pass the first check). With flag 2
//! the body is not sent as is but describes a tile that the worker's encoder writes, which
//! then gets byte edits: `fw fh x y w h n (offset_lo offset_hi xor)*n` then pixel values
//! as f32 LE. That reaches the EXR parser with well-formed files and near misses that
//! random bytes rarely make.
#![no_main]

use libfuzzer_sys::fuzz_target;
use proto::ResultMetadata;
use server::assembly::{check_tile, merge_passes};
use server::db::tasks::TaskRow;
use server::state::TaskState;
use tracer::film::{Layers, SampleRange, TileRect};
use tracer::output::{self, ExrMetadata};

const FRAME: (u32, u32) = (40, 24);
const RECT: TileRect = TileRect {
    x: 16,
    y: 8,
    width: 16,
    height: 12,
};

fn task() -> TaskRow {
    TaskRow {
        id: 7,
        kind: proto::TaskKind::Render,
        job_id: 3,
        frame: 1,
        tile: 2,
        pass: 1,
        rect: RECT,
        samples: SampleRange::new(8, 24),
        state: TaskState::Leased,
        attempt: 1,
        failures: 0,
        worker_id: Some(1),
        check_of: None,
    }
}

/// The tile a worker would encode from `spec`, with byte edits applied.
fn built(spec: &[u8]) -> Option<Vec<u8>> {
    let (&[fw, fh, x, y, w, h, n], rest) = spec.split_first_chunk::<7>()?;
    let frame = (1 + fw as u32 % 64, 1 + fh as u32 % 64);
    let rect = TileRect::new(
        x as u32 % 64,
        y as u32 % 64,
        1 + w as u32 % 32,
        1 + h as u32 % 32,
    );
    let edits_len = (n as usize % 8) * 3;
    let (edits, values) = rest.split_at(edits_len.min(rest.len()));
    let mut layers = Layers::new(rect);
    let mut values = values
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .cycle();
    for i in 0..rect.area() {
        let mut next = || values.next().unwrap_or(0.5);
        layers.beauty[i] = glam::Vec4::new(next(), next(), next(), next());
        layers.albedo[i] = glam::Vec3::new(next(), next(), next());
        layers.normal[i] = glam::Vec3::new(next(), next(), next());
        layers.depth[i] = next();
    }
    // The encoder refuses a tile outside its frame; that is the worker's side, not ours.
    let mut bytes = output::encode_exr(
        frame,
        &layers,
        &ExrMetadata::new().with(ExrMetadata::SPP, "16"),
    )
    .ok()?;
    for e in edits.chunks_exact(3) {
        let at = u16::from_le_bytes([e[0], e[1]]) as usize % bytes.len();
        bytes[at] ^= e[2];
    }
    Some(bytes)
}

fuzz_target!(|data: &[u8]| {
    let Some((&[flags, s0, s1, s2, s3], body)) = data.split_first_chunk::<5>() else {
        return;
    };
    let body = if flags & 2 != 0 {
        match built(body) {
            Some(b) => b,
            None => return,
        }
    } else {
        body.to_vec()
    };
    let mut sha256 = server::store::sha256_hex(&body);
    if flags & 1 != 0 {
        sha256.replace_range(0..1, if sha256.starts_with('0') { "1" } else { "0" });
    }
    let meta = ResultMetadata {
        attempt: 1,
        sha256,
        samples: u32::from_le_bytes([s0, s1, s2, s3]),
        rays: 0,
        render_ms: 0,
    };
    let task = task();
    let Ok(layers) = check_tile(&body, &meta, &task, FRAME) else {
        return;
    };
    assert_eq!(layers.rect, RECT);
    // Assembly reads the stored tile back (not pedantically) and pastes it into the frame.
    let stored = output::decode_exr(&body).expect("an accepted tile reads back");
    assert_eq!(stored.frame_size, FRAME);
    assert_eq!(
        stored.layers, layers,
        "an accepted tile reads back the same"
    );
    let mut frame = Layers::new(TileRect::new(0, 0, FRAME.0, FRAME.1));
    frame.paste(&merge_passes(&[layers]));
});

//! Parsers for argument values shared by several subcommands.

use anyhow::{bail, Context};

pub use proto::FrameRange;
use server::limits::MAX_FRAMES;
use tracer::animation::AnimationChoice;
use tracer::film::TileRect;
use tracer::limits::MAX_RESOLUTION;
use tracer::motion::Shutter;
use tracer::render::CameraChoice;

/// `WxH`, e.g. `1280x720`.
pub fn parse_size(s: &str) -> anyhow::Result<(u32, u32)> {
    let (w, h) = s
        .split_once(['x', 'X'])
        .context("expected WIDTHxHEIGHT, e.g. 640x360")?;
    let w: u32 = w.trim().parse().context("width is not a whole number")?;
    let h: u32 = h.trim().parse().context("height is not a whole number")?;
    if w == 0 || h == 0 || w > MAX_RESOLUTION || h > MAX_RESOLUTION {
        bail!("size {w}x{h}: each side must be 1..={MAX_RESOLUTION}");
    }
    Ok((w, h))
}

/// `X,Y,W,H`.
/// `--clamp-indirect`: a finite number above 0 (as the tracer checks it).
pub fn parse_clamp(s: &str) -> anyhow::Result<f32> {
    let limit: f32 = s.trim().parse().context("expected a number")?;
    tracer::settings::check_clamp(limit).map_err(anyhow::Error::msg)?;
    Ok(limit)
}

pub fn parse_region(s: &str) -> anyhow::Result<TileRect> {
    let v: Vec<u32> = s
        .split(',')
        .map(|p| p.trim().parse::<u32>())
        .collect::<Result<_, _>>()
        .context("expected X,Y,WIDTH,HEIGHT as whole numbers")?;
    let [x, y, w, h] = v[..] else {
        bail!("expected four numbers X,Y,WIDTH,HEIGHT")
    };
    if w == 0 || h == 0 {
        bail!("region {s}: width and height must be at least 1");
    }
    Ok(TileRect::new(x, y, w, h))
}

/// `A-B`, `A-B:STEP` or a single frame `A` (A may be negative: `-5-3`).
pub fn parse_frames(s: &str) -> anyhow::Result<FrameRange> {
    let (range, step) = match s.split_once(':') {
        Some((r, st)) => (
            r,
            st.trim()
                .parse::<u32>()
                .context("step is not a whole number")?,
        ),
        None => (s, 1),
    };
    if step == 0 {
        bail!("frames {s}: the step must be at least 1");
    }
    let range = range.trim();
    // The separating '-' is the first one after the start's own sign.
    let split = range
        .char_indices()
        .skip(1)
        .find(|&(_, c)| c == '-')
        .map(|(i, _)| i);
    let (start, end) = match split {
        Some(i) => (&range[..i], &range[i + 1..]),
        None => (range, range),
    };
    let number = |x: &str| {
        x.trim()
            .parse::<i32>()
            .with_context(|| format!("frames {s}: expected A-B, A-B:STEP or A"))
    };
    let (start, end) = (number(start)?, number(end)?);
    if end < start {
        bail!("frames {s}: the range ends before it starts");
    }
    let range = FrameRange { start, end, step };
    if range.count() > MAX_FRAMES {
        bail!("frames {s}: {} frames, at most {MAX_FRAMES}", range.count());
    }
    Ok(range)
}

/// Frame numbers picked one by one or by range (`--frames 12,40-42`).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FrameList(pub Vec<i32>);

/// Frames as a list of single frames and ranges, `12,40-42,100-200:10`, each once in the
/// order given (each item as [`parse_frames`] reads it).
pub fn parse_frame_list(s: &str) -> anyhow::Result<FrameList> {
    let mut frames = Vec::new();
    let mut seen = std::collections::HashSet::new();
    for item in s.split(',') {
        let range = parse_frames(item)?;
        for frame in (range.start..=range.end).step_by(range.step as usize) {
            if seen.insert(frame) {
                frames.push(frame);
            }
            if frames.len() as u64 > MAX_FRAMES {
                bail!("frames {s}: more than {MAX_FRAMES} frames");
            }
        }
    }
    Ok(FrameList(frames))
}

/// `OPEN,CLOSE` in frames relative to each frame's time, e.g. `-0.25,0.25`.
pub fn parse_shutter(s: &str) -> anyhow::Result<Shutter> {
    let v: Vec<f64> = s
        .split(',')
        .map(|p| p.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .context("expected OPEN,CLOSE in frames, e.g. -0.25,0.25")?;
    let [open, close] = v[..] else {
        bail!("expected two numbers OPEN,CLOSE")
    };
    let shutter = Shutter { open, close };
    shutter.validate().map_err(anyhow::Error::msg)?;
    Ok(shutter)
}

/// An animation by index or name.
pub fn parse_animation(s: &str) -> anyhow::Result<AnimationChoice> {
    Ok(match s.parse::<usize>() {
        Ok(i) => AnimationChoice::Index(i),
        Err(_) => AnimationChoice::Name(s.to_string()),
    })
}

/// A camera by index or name.
pub fn parse_camera(s: &str) -> anyhow::Result<CameraChoice> {
    Ok(match s.parse::<usize>() {
        Ok(i) => CameraChoice::Index(i),
        Err(_) => CameraChoice::Name(s.to_string()),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frame_lists_mix_frames_and_ranges_each_frame_once() {
        assert_eq!(parse_frame_list("12,40-42").unwrap().0, [12, 40, 41, 42]);
        assert_eq!(parse_frame_list("-2,1-5:2,3").unwrap().0, [-2, 1, 3, 5]);
        assert!(parse_frame_list("12,").is_err());
        assert!(parse_frame_list("5-1").is_err());
        assert!(parse_frame_list("0-100000,100001-200001").is_err());
    }

    #[test]
    fn sizes_and_regions_parse_with_limits() {
        assert_eq!(parse_size("640x360").unwrap(), (640, 360));
        assert!(parse_size("0x10").is_err());
        assert!(parse_size("16385x1").is_err());
        assert!(parse_size("12").is_err());
        assert_eq!(parse_region("1,2,3,4").unwrap(), TileRect::new(1, 2, 3, 4));
        assert!(parse_region("1,2,3").is_err());
        assert_eq!(parse_clamp("2.5").unwrap(), 2.5);
        for bad in ["0", "-1", "inf", "NaN", "x"] {
            assert!(parse_clamp(bad).is_err(), "{bad}");
        }
        assert!(parse_region("1,2,0,4").is_err());
        assert_eq!(parse_camera("2").unwrap(), CameraChoice::Index(2));
        assert_eq!(
            parse_camera("Main").unwrap(),
            CameraChoice::Name("Main".into())
        );
    }

    #[test]
    fn frame_ranges_and_shutters_parse_with_limits() {
        let r = parse_frames("1-48").unwrap();
        assert_eq!((r.start, r.end, r.step, r.count()), (1, 48, 1, 48));
        let r = parse_frames("0-10:5").unwrap();
        assert_eq!(r.frames().collect::<Vec<_>>(), [0, 5, 10]);
        let r = parse_frames("-5--3").unwrap();
        assert_eq!(r.frames().collect::<Vec<_>>(), [-5, -4, -3]);
        assert_eq!(parse_frames("7").unwrap().count(), 1);
        for bad in ["5-1", "1-4:0", "a-b", "1-200000", ""] {
            assert!(parse_frames(bad).is_err(), "{bad}");
        }
        let s = parse_shutter("-0.25,0.25").unwrap();
        assert_eq!((s.open, s.close), (-0.25, 0.25));
        for bad in ["0.5,0", "1", "nan,1", "0,1e9"] {
            assert!(parse_shutter(bad).is_err(), "{bad}");
        }
        assert_eq!(parse_animation("1").unwrap(), AnimationChoice::Index(1));
        assert_eq!(
            parse_animation("Walk").unwrap(),
            AnimationChoice::Name("Walk".into())
        );
    }
}

//! Parsers for argument values shared by several subcommands.

use anyhow::{bail, Context};

use tracer::film::TileRect;
use tracer::render::CameraChoice;

/// Largest image side we accept, as the farm does.
pub const MAX_SIDE: u32 = 16384;

/// `WxH`, e.g. `1280x720`.
pub fn parse_size(s: &str) -> anyhow::Result<(u32, u32)> {
    let (w, h) = s
        .split_once(['x', 'X'])
        .context("expected WIDTHxHEIGHT, e.g. 640x360")?;
    let w: u32 = w.trim().parse().context("width is not a whole number")?;
    let h: u32 = h.trim().parse().context("height is not a whole number")?;
    if w == 0 || h == 0 || w > MAX_SIDE || h > MAX_SIDE {
        bail!("size {w}x{h}: each side must be 1..={MAX_SIDE}");
    }
    Ok((w, h))
}

/// `X,Y,W,H`.
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
    fn sizes_and_regions_parse_with_limits() {
        assert_eq!(parse_size("640x360").unwrap(), (640, 360));
        assert!(parse_size("0x10").is_err());
        assert!(parse_size("16385x1").is_err());
        assert!(parse_size("12").is_err());
        assert_eq!(parse_region("1,2,3,4").unwrap(), TileRect::new(1, 2, 3, 4));
        assert!(parse_region("1,2,3").is_err());
        assert!(parse_region("1,2,0,4").is_err());
        assert_eq!(parse_camera("2").unwrap(), CameraChoice::Index(2));
        assert_eq!(
            parse_camera("Main").unwrap(),
            CameraChoice::Name("Main".into())
        );
    }
}

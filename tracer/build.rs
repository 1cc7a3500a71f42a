//! Fits the table that lifts linear Rec. 709 colours to smooth spectra (Jakob & Hanika
//! 2019, "A Low-Dimensional Function Space for Efficient Spectral Upsampling") at build
//! time, as pbrt-v4 and Mitsuba 3 do: 64³ colours per largest channel, each a
//! Gauss-Newton fit of three coefficients (about 40 s, once per build profile, and again
//! only when this file changes). `spectrum/upsample.rs` reads it.

use std::path::PathBuf;

use rgb2spec::optimize::{gamut::Gamut, optimize};

/// Colours per axis of the table: the resolution pbrt-v4 and Mitsuba 3 use (a round trip
/// through it is off by at most 0.003 in Rec. 709; 32 doubles that).
const RESOLUTION: usize = 64;

fn main() {
    println!("cargo::rerun-if-changed=build.rs");
    let out = PathBuf::from(std::env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    let model = optimize(Gamut::SRGB, RESOLUTION).expect("the fit converges at this resolution");
    model
        .save(out.join("rgb2spec_rec709.bin"))
        .expect("OUT_DIR is writable");
}

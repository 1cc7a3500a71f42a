//! After the render: what turns a job's noisy frames into what a shot is delivered as:
//! denoised frames and a video.
//!
//! | module | what it holds |
//! |---|---|
//! | `oidn.rs` | [`Oidn`]: Intel Open Image Denoise loaded at run time, its RT filter guided by albedo and normal |
//! | `denoise.rs` | [`denoise_layers`]: a frame's layers in, its denoised beauty out |
//! | `video.rs` | [`Ffmpeg`]: H.264 MP4s of a job's frames, and reading them back |
//! | `install.rs` | [`install`]: a pinned wheel from the Python package index, checked and unpacked |
//!
//! Nothing here is needed to render: `tessera` builds and runs without these libraries,
//! and says what to run to install them when a job asks for them.

#![warn(missing_docs)]

mod denoise;
mod install;
mod oidn;
mod video;

pub use self::denoise::denoise_layers;
pub use self::install::{install, sha256_hex, InstallError, Package, FFMPEG, OIDN};
pub use self::oidn::{
    install_dir as oidn_install_dir, NoisyImage, Oidn, OidnError, DENOISER_NAME, OIDN_VERSION,
};
pub use self::video::{
    install_dir as ffmpeg_install_dir, Ffmpeg, VideoError, VideoInfo, FFMPEG_VERSION,
};

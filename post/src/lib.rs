//! After the render: what turns a job's noisy frames into what a shot is delivered as.
//!
//! | module | what it holds |
//! |---|---|
//! | `oidn.rs` | [`Oidn`]: Intel Open Image Denoise loaded at run time, its RT filter guided by albedo and normal |
//! | `denoise.rs` | [`denoise_layers`]: a frame's layers in, its denoised beauty out |
//! | `install.rs` | [`install`]: a pinned wheel from the Python package index, checked and unpacked |
//!
//! Nothing here is needed to render: `tessera` builds and runs without these libraries,
//! and says what to run to install them when a job asks for them.

#![warn(missing_docs)]

mod denoise;
mod install;
mod oidn;

pub use self::denoise::denoise_layers;
pub use self::install::{install, sha256_hex, InstallError, Package, OIDN};
pub use self::oidn::{
    install_dir as oidn_install_dir, NoisyImage, Oidn, OidnError, DENOISER_NAME, OIDN_VERSION,
};

//! `tessera install oidn|ffmpeg`: the optional native parts, from the Python package index's
//! wheels, pinned by SHA-256, into the user's data folder (no root needed).

use std::path::PathBuf;

use anyhow::Context;
use clap::{Args, ValueEnum};

/// `tessera install`.
#[derive(Args, Debug)]
pub struct InstallArgs {
    /// What to install: `oidn`, Intel Open Image Denoise 2.5.1 (denoising: `tessera render
    /// --denoise`, and a worker that has it takes a job's denoise tasks); `ffmpeg`, FFmpeg
    /// 9.0.2 with libx264 (a job's MP4: a worker that has it takes encode tasks).
    pub what: Part,
    /// Install into this folder (default: the one the programs look in,
    /// `$XDG_DATA_HOME/tessera/...` or `~/.local/share/tessera/...`); point `--oidn` of
    /// `tessera worker` and `tessera render` at it.
    #[arg(long)]
    pub dir: Option<PathBuf>,
    /// Install from this wheel file instead of downloading it (for a machine without
    /// access to the package index: `pip download pyoidn==2.5.1 --no-deps` elsewhere).
    #[arg(long, value_name = "WHEEL")]
    pub from: Option<PathBuf>,
    /// Install again even where a working install is there.
    #[arg(long)]
    pub force: bool,
}

/// The parts `tessera install` knows.
#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum Part {
    /// Intel Open Image Denoise.
    Oidn,
    /// FFmpeg.
    Ffmpeg,
}

/// Runs `tessera install`.
pub fn run(args: InstallArgs) -> anyhow::Result<()> {
    let package = match args.what {
        Part::Oidn => &post::OIDN,
        Part::Ffmpeg => &post::FFMPEG,
    };
    let dest = args.dir.unwrap_or_else(package.default_dir);
    if !args.force && works(args.what, &dest).is_ok() {
        println!(
            "{} is installed in {} (--force installs it again)",
            package.name,
            dest.display()
        );
        return Ok(());
    }
    let wheel = match &args.from {
        Some(path) => std::fs::read(path).with_context(|| format!("reading {}", path.display()))?,
        None => {
            eprintln!("downloading {} from {}", package.name, package.url);
            download(package.url)?
        }
    };
    let files = post::install(package, &wheel, &dest)?;
    // Prove it loads and runs before saying it is installed.
    works(args.what, &dest)?;
    println!(
        "installed {} into {} ({} files)",
        package.name,
        dest.display(),
        files.len()
    );
    Ok(())
}

/// Checks that the part installed in `dir` loads and does its job.
fn works(part: Part, dir: &std::path::Path) -> anyhow::Result<()> {
    match part {
        Part::Oidn => check_denoises(&post::Oidn::load(Some(dir))?),
        Part::Ffmpeg => post::Ffmpeg::find(Some(dir)).map(drop).map_err(Into::into),
    }
}

fn download(url: &str) -> anyhow::Result<Vec<u8>> {
    let http = worker::http_client(concat!("tessera/", env!("CARGO_PKG_VERSION")), None)?;
    tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .context("starting the async runtime")?
        .block_on(async {
            let answer = http
                .get(url)
                .send()
                .await
                .and_then(|r| r.error_for_status())
                .with_context(|| format!("downloading {url}"))?;
            let bytes = answer
                .bytes()
                .await
                .with_context(|| format!("downloading {url}"))?;
            Ok(bytes.to_vec())
        })
}

/// Denoises a small flat image and checks that the result is finite and near its value.
fn check_denoises(oidn: &post::Oidn) -> anyhow::Result<()> {
    use glam::{Vec3, Vec4};
    let (w, h) = (16, 16);
    let beauty = vec![Vec4::new(0.5, 0.25, 0.125, 1.0); w * h];
    let albedo = vec![Vec3::splat(0.5); w * h];
    let normal = vec![Vec3::Z; w * h];
    let out = oidn.denoise(
        &post::NoisyImage {
            width: w,
            height: h,
            beauty: &beauty,
            albedo: &albedo,
            normal: &normal,
        },
        1,
    )?;
    let centre = out[(h / 2) * w + w / 2];
    anyhow::ensure!(
        (centre - Vec3::new(0.5, 0.25, 0.125)).abs().max_element() < 0.05,
        "{}: denoising a flat image gave {centre}, not its colour",
        oidn.path().display()
    );
    Ok(())
}

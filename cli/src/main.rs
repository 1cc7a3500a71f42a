//! The `tessera` binary: thin command-line glue over the tracer, server and worker crates.

mod args;
mod bench;
mod client;
mod control;
mod demo;
mod history;
mod install;
mod logs;
mod manage;
mod progress;
mod render;
mod scale;
mod server;
mod settings;
mod signal;
mod submit;
mod worker;

use clap::{Parser, Subcommand};

/// Tessera: a render farm with its own path tracer.
#[derive(Parser)]
#[command(name = "tessera", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run a whole farm on this machine and render a short animation with it.
    Demo(demo::DemoArgs),
    /// Render a frame or a sequence of a glTF scene (or the built-in demo) on this machine,
    /// to multi-layer EXRs.
    Render(render::RenderArgs),
    /// Measure the tracer and the farm: a report (markdown and JSON) of rays per second, error
    /// against time, the presets, what each feature costs and the farm against a direct render
    /// (`bench farm`: load-test the farm server).
    Bench(bench::BenchArgs),
    /// Run the farm server: REST API, scheduler, tile assembly, dashboard.
    Server(server::ServerArgs),
    /// Run a worker: lease tiles from a farm server, render them, upload them.
    Worker(worker::WorkerArgs),
    /// Start workers as jobs of a cluster engine (`slurm`) as the farm's queue wants them,
    /// and cancel the pending ones it no longer wants.
    Scale(scale::ScaleArgs),
    /// Pack a scene, upload it to the farm and create a render job (--wait: follow it and
    /// download the frames).
    Submit(submit::SubmitArgs),
    /// Show the farm's jobs, or one job in detail.
    Status(control::StatusArgs),
    /// Cancel a job: its unfinished tasks will not run.
    Cancel(control::ControlArgs),
    /// Pause a job: nothing more is leased until it resumes.
    Pause(control::ControlArgs),
    /// Resume a paused job.
    Resume(control::ControlArgs),
    /// Queue a job's failed tasks again, with fresh attempts, and assemble again the
    /// frames whose assembly failed.
    Retry(control::ControlArgs),
    /// Render some frames of a job again from scratch, in the same job.
    Rerender(manage::RerenderArgs),
    /// Change a job's priority (higher runs first).
    Priority(manage::PriorityArgs),
    /// Download a job's finished frames; run again, it fetches only what is missing.
    Download(manage::DownloadArgs),
    /// Submit a job again with the same scene and settings, the given ones changed.
    Clone(manage::CloneArgs),
    /// Delete a job with every file it made.
    Delete(manage::DeleteArgs),
    /// Remove finished jobs past the server's retention, unused scenes and old events
    /// (`--dry-run`: say what would go).
    Gc(manage::GcArgs),
    /// List the farm's workers.
    Workers(control::WorkersArgs),
    /// A job's event log, or what the workers logged for one of its tasks (`--task N`).
    Logs(history::LogsArgs),
    /// Install an optional part: `oidn` (Intel Open Image Denoise, for denoising) or
    /// `ffmpeg` (FFmpeg, for a job's video).
    Install(install::InstallArgs),
}

/// Runs the command; an error is printed as one line, its causes after colons, and never
/// with a stack backtrace (many users have `RUST_BACKTRACE` set, and a user's mistake is
/// not a crash).
fn main() -> std::process::ExitCode {
    match run() {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}

fn run() -> anyhow::Result<()> {
    // `server` and `worker` settings also come from TESSERA_* variables and a --config file.
    let (cli, layers) = settings::parse::<Cli>()?;
    match cli.command {
        Command::Render(args) => render::run(args),
        Command::Bench(args) => match args.command {
            Some(bench::BenchCommand::Farm(farm)) => bench::farm::run(farm),
            Some(bench::BenchCommand::Overhead(o)) => bench::scaling::run(o),
            Some(bench::BenchCommand::Cornell(c)) => bench::cornell::run_cornell(c),
            Some(bench::BenchCommand::Rays(r)) => bench::rays::run(r),
            Some(bench::BenchCommand::Features(f)) => bench::features::run(f),
            Some(bench::BenchCommand::Spectral(s)) => bench::spectral::run(s),
            Some(bench::BenchCommand::Denoise(d)) => bench::denoise::run(d),
            Some(bench::BenchCommand::Clamp(c)) => bench::clamp::run(c),
            None => bench::run(args),
        },
        Command::Server(args) => server::run(args, layers),
        Command::Worker(args) => worker::run(args, layers),
        Command::Scale(args) => scale::run(args, layers),
        Command::Submit(args) => submit::run(args),
        Command::Status(args) => control::status(args),
        Command::Cancel(args) => control::control(args, client::Control::Cancel),
        Command::Pause(args) => control::control(args, client::Control::Pause),
        Command::Resume(args) => control::control(args, client::Control::Resume),
        Command::Retry(args) => control::control(args, client::Control::Retry),
        Command::Priority(args) => manage::priority(args),
        Command::Rerender(args) => manage::rerender(args),
        Command::Download(args) => manage::download(args),
        Command::Clone(args) => manage::clone(args),
        Command::Delete(args) => manage::delete(args),
        Command::Workers(args) => control::workers(args),
        Command::Logs(args) => history::run(args),
        Command::Gc(args) => manage::gc(args),
        Command::Demo(args) => demo::run(args),
        Command::Install(args) => install::run(args),
    }
}

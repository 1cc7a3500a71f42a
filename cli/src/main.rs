//! The `tessera` binary: thin command-line glue over the tracer, server and worker crates.

mod args;
mod bench;
mod render;
mod server;

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
    /// Render one frame of a glTF scene (or the built-in demo) to a multi-layer EXR.
    Render(render::RenderArgs),
    /// Measure the tracer: rays per second, and time and error against samples per pixel.
    Bench(bench::BenchArgs),
    /// Run the farm server: REST API, scheduler, tile assembly, dashboard.
    Server(server::ServerArgs),
}

fn main() -> anyhow::Result<()> {
    match Cli::parse().command {
        Command::Render(args) => render::run(args),
        Command::Bench(args) => bench::run(args),
        Command::Server(args) => server::run(args),
    }
}

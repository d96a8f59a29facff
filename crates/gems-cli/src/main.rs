//! `gems`: motion-blurred photos (and events) to a sharp 3D Gaussian-splat scene.
//!
//! Each subcommand lives in its own module under `commands/` and is a thin layer over the library
//! crates: argument parsing here, the work in `gems-*`.

mod commands;

use clap::{Parser, Subcommand};
use tracing_subscriber::EnvFilter;

#[derive(Parser)]
#[command(name = "gems", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Make a small extreme-blur scene, initialise, train and write a report (no downloads).
    Demo(commands::demo::Args),
    /// Render a Gaussian-splat PLY to PNG from one or more cameras.
    Render(commands::render::Args),
    /// Describe what a scene folder holds (layout, views, split, poses, SfM model, events).
    Info(commands::info::Args),
    /// Generate a procedural extreme-blur scene with perfect ground truth.
    Synth(commands::synth::Args),
    /// Event-stream tools (simulation from sharp frames).
    #[command(subcommand)]
    Events(commands::events::EventsCommand),
    /// Deblur blurry images with their events (EDI) into a scene folder for initialisation.
    Edi(commands::edi::Args),
    /// Structure from motion on blurry images: poses, intrinsics and sparse points (COLMAP model).
    Sfm(commands::sfm::Args),
    /// Train a GeMS scene: Gaussians and per-image exposure trajectories from blurry images.
    Train(commands::train::Args),
    /// Re-run evaluation on a trained output folder.
    Eval(commands::eval::Args),
    /// Export a trained result's Gaussians as PLY or web `.splat` for other viewers.
    Export(commands::export::Args),
    /// Quality benchmark: GeMS from the built-in SfM and from ground-truth poses against the
    /// blurry input and the sharp-input ceiling, on generated scenes of several seeds.
    BenchQuality(commands::bench_quality::Args),
    /// Real-data benchmark on a scene folder under a published protocol: naive 3DGS and gems
    /// from the dataset's poses, gems from the built-in SfM (and GeMS-E with events), held-out
    /// views at the dataset's pose and refined, wall time, peak memory.
    BenchReal(commands::bench_real::Args),
}

fn main() -> std::process::ExitCode {
    tracing_subscriber::fmt()
        .with_env_filter(
            EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new("info")),
        )
        .with_writer(std::io::stderr)
        // Escape codes only for a person at a terminal, never into a log file or pipe.
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .init();
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Demo(a) => commands::demo::run(a),
        Command::BenchQuality(a) => commands::bench_quality::run(a),
        Command::BenchReal(a) => commands::bench_real::run(a),
        Command::Render(a) => commands::render::run(a),
        Command::Info(a) => commands::info::run(a),
        Command::Synth(a) => commands::synth::run(a),
        Command::Events(a) => commands::events::run(a),
        Command::Edi(a) => commands::edi::run(a),
        Command::Sfm(a) => commands::sfm::run(a),
        Command::Train(a) => commands::train::run(a),
        Command::Eval(a) => commands::eval::run(a),
        Command::Export(a) => commands::export::run(a),
    };
    match result {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {}", error_chain(&e));
            std::process::ExitCode::FAILURE
        }
    }
}

/// The error and its causes joined by ": ", each cause once: many library errors already show
/// their source in their own message (`"{path}: {source}"`), and `{:#}` would repeat it.
fn error_chain(e: &anyhow::Error) -> String {
    let mut out = String::new();
    for cause in e.chain() {
        let msg = cause.to_string();
        if out.contains(&msg) {
            continue;
        }
        if !out.is_empty() {
            out.push_str(": ");
        }
        out.push_str(&msg);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::error_chain;

    #[derive(Debug, thiserror::Error)]
    #[error("a.png: {source}")]
    struct Embeds {
        source: std::io::Error,
    }

    #[test]
    fn each_cause_is_printed_once() {
        let io = std::io::Error::new(std::io::ErrorKind::UnexpectedEof, "unexpected end of file");
        let e = anyhow::Error::new(Embeds { source: io }).context("cannot open scene s");
        assert_eq!(
            format!("{e:#}").matches("unexpected end of file").count(),
            2
        );
        assert_eq!(
            error_chain(&e),
            "cannot open scene s: a.png: unexpected end of file"
        );
    }
}

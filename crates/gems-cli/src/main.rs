//! `gems`: motion-blurred photos (and events) to a sharp 3D Gaussian-splat scene.
//!
//! Each subcommand lives in its own module under `commands/` and is a thin layer over the library
//! crates: argument parsing here, the work in `gems-*`.

mod commands;
mod console;

use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(name = "gems", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
    /// More detail on the console: -v adds DEBUG lines with timestamps and module paths, -vv
    /// everything. Each run's full log is in `gems.log` in its output folder either way.
    #[arg(short, long, action = clap::ArgAction::Count, global = true)]
    verbose: u8,
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
    quiet_vulkan_device_select();
    let cli = Cli::parse();
    console::init(cli.verbose);
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
            tracing::error!("{}", error_chain(&e));
            std::process::ExitCode::FAILURE
        }
    }
}

/// Turns Mesa's Vulkan device-selection layer off when there is no desktop session to select a
/// device for. Probing for a GPU loads that implicit layer, and with `XDG_RUNTIME_DIR` unset
/// (a server, a container, CI) it asks Wayland for the display's GPU and prints "error:
/// XDG_RUNTIME_DIR is invalid or not set in the environment." twice, though nothing failed.
/// wgpu chooses the adapter itself, so the layer has nothing to add there; `NODEVICE_SELECT=1`
/// is the layer's own off switch (Mesa's `VkLayer_MESA_device_select.json`,
/// `disable_environment`). A user who sets `NODEVICE_SELECT` keeps their value.
fn quiet_vulkan_device_select() {
    let runtime_dir_ok = std::env::var_os("XDG_RUNTIME_DIR")
        .is_some_and(|d| !d.is_empty() && std::path::Path::new(&d).is_dir());
    if runtime_dir_ok || std::env::var_os("NODEVICE_SELECT").is_some() {
        return;
    }
    // SAFETY: called first thing in `main`, before any thread exists, so no other thread can
    // read or write the environment concurrently (`std::env::set_var`'s safety condition).
    #[allow(unsafe_code)]
    unsafe {
        std::env::set_var("NODEVICE_SELECT", "1");
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

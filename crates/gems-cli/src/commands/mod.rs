//! One module per subcommand; each exposes `Args` (clap) and `run`. A command parses its
//! arguments, calls the libraries (a whole run: gems-pipeline), and prints. The two helpers here
//! are what several commands print the same way.
pub mod bench_quality;
pub mod demo;
pub mod edi;
pub mod eval;
pub mod events;
pub mod export;
pub mod info;
pub mod render;
pub mod sfm;
pub mod synth;
pub mod train;

use anyhow::Context;
use gems_gpu::DeviceChoice;
use gems_gpu::Engine;

/// The splatting engine for `--device`, announced on stdout; `--device gpu` without an
/// adapter is an error.
pub fn open_engine(device: DeviceChoice) -> anyhow::Result<Engine> {
    let engine = Engine::select(device).context("--device")?;
    println!("device: {}", engine.describe());
    Ok(engine)
}

/// One line per split a run evaluated (PSNR and SSIM), and the camera-centre APE of the initial
/// and the trained poses when the scene has ground truth.
pub fn print_splits(m: &gems_eval::MetricsReport) {
    for (label, split) in [
        ("blurry input", &m.input),
        ("deblur (trajectory midpoint)", &m.deblur),
        ("deblur (pose refined, GeMS protocol)", &m.deblur_refined),
        ("novel views (pose refined)", &m.nvs),
        ("novel views (initial pose)", &m.nvs_no_pose_opt),
    ] {
        if let Some(s) = split {
            println!("{label}: PSNR {:.2} dB, SSIM {:.4}", s.psnr, s.ssim);
        }
    }
    if let Some(a) = &m.ape {
        let init = m
            .ape_init
            .map_or(String::new(), |i| format!(" (initial poses {:.4})", i.rmse));
        println!("APE RMSE of the trajectory midpoints: {:.4}{init}", a.rmse);
    }
    if let Some(line) = rotation_error_line(m) {
        println!("{line}");
    }
}

/// The relative rotation error of the trajectory midpoints (and of the initial poses), when the
/// run had ground-truth poses.
pub fn rotation_error_line(m: &gems_eval::MetricsReport) -> Option<String> {
    let r = m.rotation_error?;
    let init = m.rotation_error_init.map_or(String::new(), |i| {
        format!(" (initial poses {:.3}°)", i.rmse_deg)
    });
    Some(format!(
        "relative rotation error RMSE of the trajectory midpoints: {:.3}°{init}",
        r.rmse_deg
    ))
}

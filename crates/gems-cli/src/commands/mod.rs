//! One module per subcommand; each exposes `Args` (clap) and `run`. A command parses its
//! arguments, calls the libraries (a whole run: gems-pipeline), and prints. The two helpers here
//! are what several commands print the same way.
pub mod bench_quality;
pub mod bench_real;
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

/// How a video given instead of a scene folder is read (`gems train`, `sfm`, `info`).
#[derive(clap::Args, Clone, Debug)]
pub struct VideoArgs {
    /// For a video: frames taken per second of the clip (default: about 40 frames from the
    /// whole clip, at most its own rate).
    #[arg(long)]
    pub fps: Option<f64>,
    /// The ffmpeg executable that decodes a video (ffprobe is taken from beside it).
    #[arg(long, default_value = "ffmpeg")]
    pub ffmpeg: std::path::PathBuf,
}

impl VideoArgs {
    pub fn ffmpeg(&self) -> gems_data::video::Ffmpeg {
        gems_data::video::Ffmpeg {
            binary: self.ffmpeg.clone(),
        }
    }

    /// `input` itself when it is a scene folder; for a video, its frames extracted into
    /// `<work>/frames` (see [`gems_pipeline::video_frames`]).
    pub fn scene(
        &self,
        input: &std::path::Path,
        work: &std::path::Path,
    ) -> anyhow::Result<std::path::PathBuf> {
        if !gems_data::video::is_video(input) {
            return Ok(input.to_path_buf());
        }
        println!(
            "video: {} → frames in {}",
            input.display(),
            work.join("frames").display()
        );
        Ok(gems_pipeline::video_frames(
            input,
            work,
            self.fps,
            &self.ffmpeg(),
        )?)
    }
}
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
    if let Some(r) = &m.run {
        println!(
            "protocol: {}; ×{}, {} training and {} held-out views; {}; {} steps; {}",
            r.protocol.as_deref().unwrap_or("gems defaults"),
            r.downscale,
            r.train_views,
            r.held_out_views,
            r.init,
            r.steps,
            r.device
        );
    }
    let reference = m
        .held_out_pose
        .as_ref()
        .map_or("initial pose".to_owned(), |p| {
            p.source.trim_start_matches("the ").to_owned()
        });
    for (label, split) in [
        ("blurry input", &m.input),
        ("deblur, at the trajectory midpoint", &m.deblur),
        ("deblur, pose refined (GeMS protocol)", &m.deblur_refined),
        (
            &format!("novel views, at {reference}") as &str,
            &m.nvs_no_pose_opt,
        ),
        ("novel views, pose refined from there", &m.nvs),
    ] {
        if let Some(s) = split {
            let lpips = s.lpips.map_or(String::new(), |l| format!(", LPIPS {l:.4}"));
            println!("{label}: PSNR {:.2} dB, SSIM {:.4}{lpips}", s.psnr, s.ssim);
        }
    }
    if let Some(p) = &m.held_out_pose {
        println!("held-out views posed at {}", p.describe());
    }
    if let Some(c) = &m.camera_shift {
        println!(
            "trained cameras vs that source's: centres {:.2} % of their extent, rotations {:.3}° \
             (initial cameras {:.2} %, {:.3}°)",
            c.centre_pct, c.rotation_deg, c.initial_centre_pct, c.initial_rotation_deg
        );
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
    if let Some(f) = &m.focal {
        println!("focal length (x): {}", f.describe());
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

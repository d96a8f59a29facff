//! `gems demo`: the whole pipeline on a scene it makes itself — no downloads, no weights.
//!
//! 1. `gems synth` (small preset with 24 views, so neighbouring views overlap enough for SfM
//!    under 30 px of blur): an extreme-blur procedural scene with ground truth;
//! 2. the built-in blur-robust SfM on the blurry images (poses and points; the focal length is the
//!    camera's, as EXIF would give it for a real photo, unless `--estimate-focal`) — with
//!    `--events`, on the images the scene's events deblur by EDI (GeMS-E) — falling back to noisy
//!    ground-truth poses, labelled as such, only if SfM fails outright;
//! 3. GeMS training (blur model, Bézier trajectories, MCMC) with a short schedule;
//! 4. evaluation and `report.html`.

use std::path::PathBuf;

use anyhow::Context;
use gems_pipeline::{InitMode, TrainJob, train_and_report};
use gems_synth::SynthConfig;
use gems_train::TrainConfig;

/// Arguments of `gems demo`.
#[derive(clap::Args)]
pub struct Args {
    /// Output folder; holds `scene/`, `sfm/` and `train/` (with `report.html`).
    #[arg(short, long, default_value = "gems-demo")]
    pub output: PathBuf,
    /// Training steps (the paper's full schedule is 7000).
    #[arg(long, default_value_t = 1000)]
    pub steps: usize,
    /// Cap on the number of Gaussians (MCMC cap_max).
    #[arg(long, default_value_t = 30_000)]
    pub cap_max: usize,
    /// Seed of the scene, the SfM and the training.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Initialise from noisy ground-truth poses instead of the built-in SfM.
    #[arg(long)]
    pub gt_noisy: bool,
    /// Let the SfM estimate the focal length too (by default the camera's focal is given, as a
    /// photo's EXIF would).
    #[arg(long)]
    pub estimate_focal: bool,
    /// GeMS-E: deblur the blurry images with the scene's simulated events (EDI) and run the SfM
    /// on those; training still fits the blurry images. The report gains an EDI column.
    #[arg(long, conflicts_with = "gt_noisy")]
    pub events: bool,
    /// Replace the output folder of an earlier demo.
    #[arg(long)]
    pub force: bool,
    /// Where the splatting runs: `auto` takes a hardware GPU when there is one and the CPU
    /// otherwise; `gpu` any GPU adapter (software ones such as Mesa lavapipe included), an error
    /// when there is none; `cpu` the CPU.
    #[arg(long, default_value = "auto")]
    pub device: gems_gpu::DeviceChoice,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let out = &args.output;
    let scene = out.join("scene");
    if out.exists() && std::fs::read_dir(out)?.next().is_some() {
        let is_demo = scene.join("synth.json").is_file();
        if !(args.force && is_demo) {
            anyhow::bail!(
                "{} exists and is not empty{}",
                out.display(),
                if is_demo {
                    " (an earlier demo: pass --force to replace it)"
                } else {
                    ""
                }
            );
        }
        std::fs::remove_dir_all(out).with_context(|| format!("removing {}", out.display()))?;
    }
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    crate::console::log_to(out)?;

    let synth = SynthConfig {
        seed: args.seed,
        views: 24,
        ..SynthConfig::small()
    };
    tracing::info!(
        width = synth.width,
        height = synth.height,
        views = synth.views,
        blur_px = synth.blur_px,
        "1/3 generating an extreme-blur scene"
    );
    let summary = gems_synth::generate(&synth, &scene)?;
    tracing::info!(
        events = summary.events,
        "scene written to {}",
        scene.display()
    );

    let started = std::time::Instant::now();
    let mode = if args.gt_noisy {
        gt_noisy()
    } else {
        let focal = (!args.estimate_focal).then_some(summary.intrinsics.fx);
        let sfm_images = if args.events {
            tracing::info!("2/3 EDI deblurring with the events, then structure from motion");
            let threshold = synth.events.as_ref().map_or(0.2, |e| e.threshold_pos);
            // gems synth blurs by averaging sRGB-encoded frames; its events see linear light.
            gems_pipeline::edi_images(
                &scene,
                &out.join("train"),
                &gems_pipeline::EventInit {
                    threshold,
                    linearisation: gems_init::edi::Linearisation::SrgbEncodedAverage,
                    time_unit: None,
                },
            )?
        } else {
            tracing::info!("2/3 structure from motion on the blurry images");
            scene.clone()
        };
        match gems_pipeline::run_sfm(&sfm_images, &out.join("sfm"), args.seed, focal, None, None) {
            Ok(model) => InitMode::Colmap(Some(model)),
            Err(e) => {
                tracing::warn!(
                    "built-in SfM failed ({e:#}); initialising from NOISY GROUND-TRUTH poses instead"
                );
                gt_noisy()
            }
        }
    };

    let mut cfg = TrainConfig {
        steps: args.steps,
        seed: args.seed,
        ..TrainConfig::default()
    };
    cfg.mcmc.cap_max = args.cap_max;
    cfg.validate()
        .map_err(|e| anyhow::anyhow!("invalid demo configuration: {e}"))?;
    let init = match &mode {
        InitMode::Colmap(_) if args.events => "built-in SfM on the EDI-deblurred images (events)",
        InitMode::Colmap(_) => "built-in SfM on the blurry photos",
        _ => "ground-truth poses with noise (the built-in SfM was not used)",
    };
    tracing::info!(steps = cfg.steps, init, "3/3 training and evaluation");
    let engine = super::open_engine(args.device)?;
    let opened = gems_data::open_scene(&scene, &gems_data::OpenOptions::default())?;
    let description = gems_pipeline::describe_run(&opened, None, init.into(), &cfg, &engine);
    let run = train_and_report(TrainJob {
        scene: &scene,
        output: &out.join("train"),
        mode,
        cfg,
        open: gems_data::OpenOptions::default(),
        resume: false,
        evaluate: true,
        lpips: &[],
        engine,
        progress: true,
        run: Some(description),
        started,
    })?;
    let (Some(report), Some(metrics)) = (run.report, run.metrics) else {
        anyhow::bail!("evaluation produced no report");
    };
    super::print_splits(&metrics);
    println!("report: {}", report.display());
    Ok(())
}

fn gt_noisy() -> InitMode {
    InitMode::GtNoisy {
        translation_std: 0.01,
        rotation_std: 0.01,
    }
}

//! `gems train`: joint optimisation of Gaussians and per-image exposure trajectories from blurry
//! images (gems-train), with periodic atomic checkpoints and `--resume`, then `point_cloud.ply`
//! (input frame), the trained model, and gems-eval's metrics, trajectories and report.

use std::io::Write;
use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, bail};
use gems_train::TrainConfig;
use gems_train::io::{TrainOutput, has_checkpoint, load_checkpoint, save_checkpoint};
use gems_train::prepare::{InitMode, prepare_input};
use gems_train::trainer::Trainer;

/// Initialisation of poses and points.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Init {
    /// The scene's COLMAP sparse model (or the one given with --colmap-model).
    Colmap,
    /// Ground-truth poses.
    Gt,
    /// Ground-truth poses perturbed by seeded noise (labelled as such in the outputs).
    GtNoisy,
    /// Built-in SfM on the blurry images.
    Sfm,
}

/// Arguments of `gems train`.
#[derive(clap::Args)]
pub struct Args {
    /// Scene folder (GeMS/PRISM3D, LLFF or nerfstudio layout).
    pub scene: PathBuf,
    /// Output folder.
    #[arg(short, long)]
    pub output: PathBuf,
    /// TOML configuration (missing fields take the defaults; see gems-train's TrainConfig).
    #[arg(long)]
    pub config: Option<PathBuf>,
    #[arg(long, value_enum, default_value_t = Init::Colmap)]
    pub init: Init,
    /// COLMAP model folder for --init colmap (default: the scene's sparse/0).
    #[arg(long)]
    pub colmap_model: Option<PathBuf>,
    /// Translation noise σ (normalised units) for --init gt-noisy.
    #[arg(long, default_value_t = 0.01)]
    pub noise_translation: f64,
    /// Rotation noise σ (radians) for --init gt-noisy.
    #[arg(long, default_value_t = 0.01)]
    pub noise_rotation: f64,
    /// Override the number of steps.
    #[arg(long)]
    pub steps: Option<usize>,
    /// Override the seed.
    #[arg(long)]
    pub seed: Option<u64>,
    /// Image downscale factor (PRISM3D: 2).
    #[arg(long, default_value_t = 1)]
    pub downscale: u32,
    /// Continue from the checkpoint in the output folder.
    #[arg(long)]
    pub resume: bool,
    /// Use the scene's events: EDI-deblurred images for initialisation.
    #[arg(long)]
    pub events: bool,
    /// Skip evaluation and report (train and export only).
    #[arg(long)]
    pub no_eval: bool,
    /// LPIPS weights for the evaluation (see `gems eval --help`).
    #[arg(long, num_args = 1..)]
    pub lpips: Vec<PathBuf>,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    if args.events {
        bail!(
            "--events (EDI initialisation) is not wired into `gems train` yet: run `gems edi` and train on its output"
        );
    }
    let mode = match args.init {
        Init::Colmap => InitMode::Colmap(args.colmap_model.clone()),
        Init::Gt => InitMode::Gt,
        Init::GtNoisy => InitMode::GtNoisy {
            translation_std: args.noise_translation,
            rotation_std: args.noise_rotation,
        },
        Init::Sfm => bail!(
            "--init sfm: run `gems sfm {}` first (it writes sparse/0), then use --init colmap",
            args.scene.display()
        ),
    };
    let mut cfg = match &args.config {
        Some(p) => TrainConfig::from_toml_file(p)?,
        None => TrainConfig::default(),
    };
    if let Some(s) = args.steps {
        cfg.steps = s;
    }
    if let Some(s) = args.seed {
        cfg.seed = s;
    }
    cfg.validate()
        .map_err(|e| anyhow::anyhow!("invalid configuration: {e}"))?;
    let opts = gems_data::OpenOptions {
        downscale: args.downscale,
        ..Default::default()
    };
    let scene = gems_data::open_scene(&args.scene, &opts)
        .with_context(|| format!("opening scene {}", args.scene.display()))?;
    std::fs::create_dir_all(&args.output)
        .with_context(|| format!("creating {}", args.output.display()))?;

    let mut trainer = if args.resume && has_checkpoint(&args.output) {
        let (ckpt_cfg, state) = load_checkpoint(&args.output)?;
        let input = prepare_input(&scene, &mode, &ckpt_cfg)?;
        tracing::info!(step = state.step, "resuming from checkpoint");
        Trainer::from_state(
            ckpt_cfg,
            input.views,
            input.normalization,
            input.scene_scale,
            input.init_label,
            state,
        )?
    } else {
        if args.resume {
            tracing::warn!(
                "--resume: no checkpoint in {}, starting fresh",
                args.output.display()
            );
        }
        let input = prepare_input(&scene, &mode, &cfg)?;
        tracing::info!(views = input.views.len(), gaussians = input.gaussians.len(), init = %input.init_label, "training");
        Trainer::new(cfg, input)?
    };
    gems_train::io::write_atomic(
        &args.output.join("config.toml"),
        trainer.cfg.to_toml().as_bytes(),
    )?;

    let start = Instant::now();
    let first = trainer.state.step;
    let out_dir = args.output.clone();
    trainer.run(|t, r| {
        let done = r.step - first;
        let rate = done as f64 / start.elapsed().as_secs_f64().max(1e-9);
        let eta = (t.cfg.steps - r.step) as f64 / rate.max(1e-9);
        eprint!(
            "\rstep {}/{}  loss {:.4}  PSNR {:.2}  Gaussians {}  {:.2} steps/s  ETA {:.0}s   ",
            r.step, t.cfg.steps, r.loss, r.psnr, r.gaussians, rate, eta
        );
        let _ = std::io::stderr().flush();
        let every = t.cfg.checkpoint_every;
        if every > 0 && r.step % every == 0 && r.step < t.cfg.steps {
            save_checkpoint(&out_dir, t)?;
        }
        Ok(())
    })?;
    eprintln!();
    save_checkpoint(&args.output, &trainer)?;
    let output = TrainOutput::from_trainer(&trainer);
    output.save(&args.output)?;
    let ply = args.output.join("point_cloud.ply");
    let g_input = output
        .normalization
        .gaussians_to_input_frame(&output.gaussians);
    gems_splat::ply::write_ply(&ply, &g_input)?;
    tracing::info!(path = %ply.display(), seconds = output.seconds, steps = output.steps, "trained");

    if args.no_eval {
        return Ok(());
    }
    let scene = gems_eval::trainer_eval::open_scene_for(&output, &args.scene, None)?;
    let data = gems_eval::eval_data_from_scene(&output, &scene)?;
    let lpips = if args.lpips.is_empty() {
        tracing::warn!("no --lpips weights given: LPIPS will be reported as absent");
        None
    } else {
        Some(gems_metrics::Lpips::load(&args.lpips)?)
    };
    let eval = gems_eval::evaluate_output(
        &output,
        &data,
        &gems_eval::PoseRefineConfig::default(),
        lpips.as_ref(),
    )?;
    gems_eval::write_metrics_json(&args.output.join("metrics.json"), &eval.metrics)?;
    gems_eval::write_trajectories(&args.output, &output)?;
    let report = gems_eval::write_report(
        &args.output,
        &gems_eval::report_input(&output, &data, &eval, 4),
    )?;
    println!("report: {}", report.display());
    Ok(())
}

//! The train → export → evaluate → report sequence shared by `gems train` and `gems demo`.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;
use gems_gpu::DeviceChoice;
use gems_train::TrainConfig;
use gems_train::engine::Engine;
use gems_train::io::{TrainOutput, has_checkpoint, load_checkpoint, save_checkpoint};
use gems_train::prepare::{InitMode, prepare_input};
use gems_train::trainer::Trainer;
use indicatif::{ProgressBar, ProgressStyle};

/// One training run and what to do after it.
pub struct TrainJob<'a> {
    pub scene: &'a Path,
    pub output: &'a Path,
    pub mode: InitMode,
    pub cfg: TrainConfig,
    /// How to open the scene (downscale, cache folder for copies, time unit).
    pub open: gems_data::OpenOptions,
    pub resume: bool,
    pub evaluate: bool,
    pub lpips: &'a [PathBuf],
    pub device: DeviceChoice,
}

/// The splatting engine for `--device`, announced on stdout; `--device gpu` without an
/// adapter is an error.
pub fn open_engine(device: DeviceChoice) -> anyhow::Result<Engine> {
    let engine = Engine::select(device).context("--device")?;
    println!("device: {}", engine.describe());
    Ok(engine)
}

/// Trains, writes `point_cloud.ply` (input frame), the model, and — unless disabled — metrics,
/// trajectories and `report.html`. Returns the report path when one was written.
pub fn train_and_report(job: TrainJob<'_>) -> anyhow::Result<Option<PathBuf>> {
    let scene = gems_data::open_scene(job.scene, &job.open)
        .with_context(|| format!("opening scene {}", job.scene.display()))?;
    std::fs::create_dir_all(job.output)
        .with_context(|| format!("creating {}", job.output.display()))?;
    let pose_model = match &job.mode {
        InitMode::Colmap(Some(dir)) => Some(std::fs::canonicalize(dir).unwrap_or(dir.clone())),
        InitMode::Colmap(None) => scene
            .sfm_dir
            .as_ref()
            .map(|d| std::fs::canonicalize(d).unwrap_or(d.clone())),
        InitMode::Gt | InitMode::GtNoisy { .. } => None,
    };

    let engine = open_engine(job.device)?;
    let mut trainer = if job.resume && has_checkpoint(job.output) {
        let (ckpt_cfg, state) = load_checkpoint(job.output)?;
        let input = prepare_input(&scene, &job.mode, &ckpt_cfg)?;
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
        if job.resume {
            tracing::warn!(
                "--resume: no checkpoint in {}, starting fresh",
                job.output.display()
            );
        }
        let input = prepare_input(&scene, &job.mode, &job.cfg)?;
        tracing::info!(views = input.views.len(), gaussians = input.gaussians.len(), init = %input.init_label, "training");
        Trainer::new(job.cfg, input)?
    };
    trainer.set_engine(engine);
    gems_train::io::write_atomic(
        &job.output.join("config.toml"),
        trainer.cfg.to_toml().as_bytes(),
    )?;

    let bar = ProgressBar::new(trainer.cfg.steps as u64);
    bar.set_style(
        ProgressStyle::with_template("{bar:30} {pos}/{len} steps  {msg}  {per_sec}  ETA {eta}")
            .expect("static progress template"),
    );
    bar.set_position(trainer.state.step as u64);
    let start = Instant::now();
    let out_dir = job.output.to_path_buf();
    trainer.run(|t, r| {
        bar.set_position(r.step as u64);
        bar.set_message(format!(
            "loss {:.4}  PSNR {:.2}  Gaussians {}",
            r.loss, r.psnr, r.gaussians
        ));
        let every = t.cfg.checkpoint_every;
        if every > 0 && r.step % every == 0 && r.step < t.cfg.steps {
            save_checkpoint(&out_dir, t)?;
        }
        Ok(())
    })?;
    bar.finish();
    save_checkpoint(job.output, &trainer)?;
    let mut output = TrainOutput::from_trainer(&trainer);
    output.pose_model = pose_model;
    output.save(job.output)?;
    let ply = job.output.join("point_cloud.ply");
    let g_input = output
        .normalization
        .gaussians_to_input_frame(&output.gaussians);
    gems_splat::ply::write_ply(&ply, &g_input)?;
    tracing::info!(
        path = %ply.display(),
        seconds = output.seconds,
        wall = start.elapsed().as_secs_f64(),
        steps = output.steps,
        "trained"
    );

    if !job.evaluate {
        return Ok(None);
    }
    let scene = gems_eval::trainer_eval::open_scene_for(&output, job.scene, &job.open)?;
    let mut data = gems_eval::eval_data_from_scene(&output, &scene)?;
    attach_edi(&mut data, &output, job.output)?;
    let lpips = if job.lpips.is_empty() {
        tracing::warn!("no --lpips weights given: LPIPS is reported as absent");
        None
    } else {
        Some(gems_metrics::Lpips::load(job.lpips)?)
    };
    let units = gems_eval::evaluation_units(&data);
    let bar = ProgressBar::new(units as u64);
    bar.set_style(
        ProgressStyle::with_template("evaluating {bar:30} {pos}/{len} views  ETA {eta}")
            .expect("static progress template"),
    );
    let mut engine = trainer.set_engine(Engine::cpu());
    let eval = gems_eval::evaluate_output_on(
        &mut engine,
        &output,
        &data,
        &gems_eval::PoseRefineConfig::default(),
        lpips.as_ref(),
        &mut |_view| bar.inc(1),
    )?;
    bar.finish();
    let m = &eval.metrics;
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
    gems_eval::write_metrics_json(&job.output.join("metrics.json"), &eval.metrics)?;
    gems_eval::write_trajectories(job.output, &output)?;
    gems_eval::write_renders_on(&mut engine, job.output, &output, &data, &eval)?;
    let report = gems_eval::write_report(
        job.output,
        &gems_eval::report_input(&output, &data, &eval, 4),
    )?;
    Ok(Some(report))
}

/// Puts the EDI images of a `--events` run (`<output>/edi/images`) into the report's grid.
pub fn attach_edi(
    data: &mut gems_eval::EvalData,
    output: &TrainOutput,
    dir: &Path,
) -> anyhow::Result<()> {
    let edi = dir.join("edi").join("images");
    if edi.is_dir() {
        let n = gems_eval::attach_edi_images(data, output, &edi)?;
        tracing::info!(views = n, dir = %edi.display(), "EDI images added to the report");
    }
    Ok(())
}

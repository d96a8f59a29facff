//! Training, exports, evaluation and report: one run from a resolved initialisation
//! ([`train_and_report`]), or from a scene and an initialisation request ([`train_scene`]).

use std::path::{Path, PathBuf};
use std::time::Instant;

use gems_eval::MetricsReport;
use gems_gpu::Engine;
use gems_train::TrainConfig;
use gems_train::Trainer;
use gems_train::{InitMode, prepare_input};
use gems_train::{TrainOutput, has_checkpoint, load_checkpoint, save_checkpoint};
use indicatif::{ProgressBar, ProgressStyle};

use crate::PipelineError;
use crate::init::{InitRequest, resolve_init};

/// A whole run: a scene, where its initialisation comes from, and what to do after training.
pub struct TrainRequest {
    /// Scene folder (any layout gems-data reads).
    pub scene: PathBuf,
    /// Output folder (created if missing).
    pub output: PathBuf,
    pub init: InitRequest,
    pub cfg: TrainConfig,
    /// How to open the scene (downscale, cache folder for copies, time unit, hold-out).
    pub open: gems_data::OpenOptions,
    /// Continue from the checkpoint in `output` when there is one.
    pub resume: bool,
    /// Evaluate and write the report after training.
    pub evaluate: bool,
    /// LPIPS weights for the evaluation; empty: LPIPS is reported as absent.
    pub lpips: Vec<PathBuf>,
    /// The splatting engine training (and evaluation) runs on.
    pub engine: Engine,
    /// Draw indicatif progress bars on stderr.
    pub progress: bool,
}

/// One training run from an already resolved initialisation, and what to do after it.
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
    /// The splatting engine training (and evaluation) runs on.
    pub engine: Engine,
    /// Draw indicatif progress bars on stderr.
    pub progress: bool,
}

/// What a run wrote.
#[derive(Debug)]
pub struct RunOutcome {
    /// `<output>/point_cloud.ply`, the Gaussians in the input frame.
    pub point_cloud: PathBuf,
    /// `<output>/report.html`, when the run evaluated.
    pub report: Option<PathBuf>,
    /// The metrics (also in `<output>/metrics.json`), when the run evaluated.
    pub metrics: Option<MetricsReport>,
}

/// Validates the scene (every image decoded, poses, events) before any long work, resolves the
/// initialisation (the focal for the SfM or COLMAP from the request, else from the photos'
/// EXIF), then trains, exports, evaluates and reports ([`train_and_report`]).
pub fn train_scene(req: TrainRequest) -> Result<RunOutcome, PipelineError> {
    req.cfg.validate().map_err(PipelineError::Config)?;
    let scene = gems_data::open_scene(&req.scene, &req.open).map_err(|source| {
        PipelineError::OpenScene {
            path: req.scene.clone(),
            source,
        }
    })?;
    let problems = gems_data::check::check_scene(&scene);
    if !problems.is_empty() {
        return Err(PipelineError::SceneProblems {
            problems: problems.iter().map(ToString::to_string).collect(),
        });
    }
    let mut init = req.init;
    init.focal_px = init.focal_px.or_else(|| {
        gems_data::exif::scene_focal(&scene).map(|f| {
            tracing::info!(focal_px = f.focal_px, source = %f.source, image = %f.image.display(), "focal for the SfM");
            f.focal_px
        })
    });
    let mode = resolve_init(&req.scene, &req.output, &init, req.cfg.seed, req.resume)?;
    train_and_report(TrainJob {
        scene: &req.scene,
        output: &req.output,
        mode,
        cfg: req.cfg,
        open: req.open,
        resume: req.resume,
        evaluate: req.evaluate,
        lpips: &req.lpips,
        engine: req.engine,
        progress: req.progress,
    })
}

/// A progress bar of `len` units drawn with `template`, or a hidden one.
fn progress_bar(show: bool, len: usize, template: &'static str) -> ProgressBar {
    if !show {
        return ProgressBar::hidden();
    }
    let bar = ProgressBar::new(len as u64);
    bar.set_style(ProgressStyle::with_template(template).expect("static progress template"));
    bar
}

/// Trains, writes `point_cloud.ply` (input frame), the model, and — unless disabled — metrics,
/// trajectories and `report.html`.
pub fn train_and_report(job: TrainJob<'_>) -> Result<RunOutcome, PipelineError> {
    let scene =
        gems_data::open_scene(job.scene, &job.open).map_err(|source| PipelineError::OpenScene {
            path: job.scene.to_path_buf(),
            source,
        })?;
    std::fs::create_dir_all(job.output).map_err(|source| PipelineError::CreateDir {
        path: job.output.to_path_buf(),
        source,
    })?;
    let pose_model = pose_model_of(&job.mode, &scene);
    let mut trainer = start_trainer(&scene, &job.mode, job.cfg, job.resume, job.output)?;
    trainer.set_engine(job.engine);
    gems_fs::write_atomic(
        &job.output.join("config.toml"),
        trainer.config().to_toml().as_bytes(),
    )?;
    let start = Instant::now();
    train_with_checkpoints(&mut trainer, job.output, job.progress)?;
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
        return Ok(RunOutcome {
            point_cloud: ply,
            report: None,
            metrics: None,
        });
    }
    let mut engine = trainer.set_engine(Engine::cpu());
    let reporting = Reporting {
        scene: job.scene,
        open: &job.open,
        output: job.output,
        lpips: job.lpips,
        progress: job.progress,
    };
    let (report, metrics) = evaluate_and_report(&reporting, &output, &mut engine)?;
    Ok(RunOutcome {
        point_cloud: ply,
        report: Some(report),
        metrics: Some(metrics),
    })
}

/// The COLMAP model the initial poses come from, if any (held-out views are evaluated from its
/// poses).
fn pose_model_of(mode: &InitMode, scene: &gems_data::Scene) -> Option<PathBuf> {
    match mode {
        InitMode::Colmap(Some(dir)) => Some(std::fs::canonicalize(dir).unwrap_or(dir.clone())),
        InitMode::Colmap(None) => scene
            .sfm_dir
            .as_ref()
            .map(|d| std::fs::canonicalize(d).unwrap_or(d.clone())),
        InitMode::Gt | InitMode::GtNoisy { .. } => None,
    }
}

/// A trainer resumed from the checkpoint in `output` (with the configuration it was written
/// with) when asked and there is one, else a fresh one with `cfg`.
fn start_trainer(
    scene: &gems_data::Scene,
    mode: &InitMode,
    cfg: TrainConfig,
    resume: bool,
    output: &Path,
) -> Result<Trainer, PipelineError> {
    if resume && has_checkpoint(output) {
        let (ckpt_cfg, state) = load_checkpoint(output)?;
        let input = prepare_input(scene, mode, &ckpt_cfg)?;
        tracing::info!(step = state.step, "resuming from checkpoint");
        return Ok(Trainer::from_state(
            ckpt_cfg,
            input.views,
            input.normalization,
            input.scene_scale,
            input.init_label,
            state,
        )?);
    }
    if resume {
        tracing::warn!(
            "--resume: no checkpoint in {}, starting fresh",
            output.display()
        );
    }
    let input = prepare_input(scene, mode, &cfg)?;
    tracing::info!(views = input.views.len(), gaussians = input.gaussians.len(), init = %input.init_label, "training");
    Ok(Trainer::new(cfg, input)?)
}

/// Runs the remaining steps with a checkpoint every `checkpoint_every` steps and one at the end.
fn train_with_checkpoints(
    trainer: &mut Trainer,
    output: &Path,
    progress: bool,
) -> Result<(), PipelineError> {
    let bar = progress_bar(
        progress,
        trainer.config().steps,
        "{bar:30} {pos}/{len} steps  {msg}  {per_sec}  ETA {eta}",
    );
    bar.set_position(trainer.steps_done() as u64);
    trainer.run(|t, r| {
        bar.set_position(r.step as u64);
        bar.set_message(format!(
            "loss {:.4}  PSNR {:.2}  Gaussians {}",
            r.loss, r.psnr, r.gaussians
        ));
        let every = t.config().checkpoint_every;
        if every > 0 && r.step % every == 0 && r.step < t.config().steps {
            save_checkpoint(output, t)?;
        }
        Ok(())
    })?;
    bar.finish();
    save_checkpoint(output, trainer)?;
    Ok(())
}

/// Where [`evaluate_and_report`] reads ground truth from and writes to.
struct Reporting<'a> {
    scene: &'a Path,
    open: &'a gems_data::OpenOptions,
    output: &'a Path,
    lpips: &'a [PathBuf],
    progress: bool,
}

/// The evaluation protocol on the trained result, then `metrics.json`, trajectories, renders
/// and `report.html` in the output folder; returns the report's path and the metrics.
fn evaluate_and_report(
    job: &Reporting<'_>,
    output: &TrainOutput,
    engine: &mut Engine,
) -> Result<(PathBuf, MetricsReport), PipelineError> {
    let scene = gems_eval::open_scene_for(output, job.scene, job.open)?;
    let mut data = gems_eval::eval_data_from_scene(output, &scene)?;
    attach_edi(&mut data, output, job.output)?;
    let lpips = if job.lpips.is_empty() {
        tracing::warn!("no --lpips weights given: LPIPS is reported as absent");
        None
    } else {
        Some(gems_metrics::Lpips::load(job.lpips)?)
    };
    let bar = progress_bar(
        job.progress,
        gems_eval::evaluation_units(&data),
        "evaluating {bar:30} {pos}/{len} views  ETA {eta}",
    );
    let eval = gems_eval::evaluate_output_on(
        engine,
        output,
        &data,
        &gems_eval::PoseRefineConfig::default(),
        lpips.as_ref(),
        &mut |_view| bar.inc(1),
    )?;
    bar.finish();
    gems_eval::write_metrics_json(&job.output.join("metrics.json"), &eval.metrics)?;
    gems_eval::write_trajectories(job.output, output)?;
    gems_eval::write_renders_on(engine, job.output, output, &data, &eval)?;
    let report = gems_eval::write_report(
        job.output,
        &gems_eval::report_input(output, &data, &eval, 4),
    )?;
    Ok((report, eval.metrics))
}

/// Puts the EDI images of an events run (`<dir>/edi/images`) into the report's grid.
pub fn attach_edi(
    data: &mut gems_eval::EvalData,
    output: &TrainOutput,
    dir: &Path,
) -> Result<(), PipelineError> {
    let edi = dir.join("edi").join("images");
    if edi.is_dir() {
        let n = gems_eval::attach_edi_images(data, output, &edi)?;
        tracing::info!(views = n, dir = %edi.display(), "EDI images added to the report");
    }
    Ok(())
}

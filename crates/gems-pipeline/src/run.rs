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

use crate::PipelineError;
use crate::dense;
use crate::init::{
    Init, InitRequest, checked_on_renders, init_images, place_missing_views, rerun_init_on_renders,
    reruns_on_renders, resolve_init,
};
use crate::probe::{
    ConfirmRule, RerunChoice, confirms_first_model, continue_from, probe, remove_probe,
    renders_change, renders_shift,
};

/// The file a training pass on a [profiled](gems_gpu::Engine::profiled) engine writes into its
/// output folder: where its steps' time went, per kernel ([`gems_train::GpuProfile::report`]).
pub const GPU_PROFILE: &str = "gpu_profile.txt";

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
    /// The published protocol the request was made for (recorded in the outputs; its settings
    /// are the caller's to apply, [`crate::Protocol::settings`]).
    pub protocol: Option<crate::Protocol>,
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
    /// What the user ran, recorded in the result with the wall time since `started` and the
    /// peak memory filled in when training ends (`None`: not recorded).
    pub run: Option<gems_train::RunDescription>,
    /// When the whole run began (initialisation included).
    pub started: Instant,
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
    let started = Instant::now();
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
    if init.focal_px.is_none()
        && let Some(f) = gems_data::exif::scene_focal(&scene)
    {
        tracing::info!(focal_px = f.focal_px, source = %f.source, image = %f.image.display(), "focal for the SfM");
        init.focal_px = Some(f.focal_px);
        let width = req.cfg.init.exif_focal_prior;
        init.focal_prior = init.focal_prior.or((width > 0.0).then_some(width));
    }
    let mut mode = resolve_init(&req.scene, &req.output, &init, req.cfg.seed, req.resume)?;
    let mut cfg = req.cfg;
    if cfg.pose.focal_lr > 0.0
        && let Some(why) = focal_is_known(&init)
    {
        tracing::info!("the focal is not learned ({why}): pose.focal_lr applies to estimated ones");
        cfg.pose.focal_lr = 0.0;
    }
    if init.init == Init::Gt {
        // Exact initial poses: straight paths first (`init.accurate_poses_straight_fraction`).
        cfg.pose.straight_fraction = cfg.init.accurate_poses_straight_fraction;
    }
    let mut engine = req.engine;
    let mut description = describe_run(
        &scene,
        req.protocol,
        describe_init(&init, &scene),
        &cfg,
        &engine,
    );
    // The run proper continues the kept model's probe (its checkpoint is in the output folder).
    let mut continues_probe = false;
    if let Some((first_steps, rest)) = cfg
        .sfm_rerun_split()
        .filter(|_| checked_on_renders(init.init))
        // A model whose cameras training does not move needs no check.
        .filter(|_| reruns_on_renders(init.init) || cfg.pose.optimize)
    {
        // An imported model is only measured by the SfM on the renders, never replaced.
        let imported = !reruns_on_renders(init.init);
        let rerun = req.output.join("sfm_rerun");
        let renders_model = rerun.join("sparse").join("0");
        // A resumed run keeps the choice an earlier one made (and the model it kept).
        let earlier = if req.resume {
            RerunChoice::read(&rerun)?
                .filter(|c| !c.kept || renders_model.join("images.bin").is_file())
        } else {
            None
        };
        let choice = if let Some(choice) = earlier {
            tracing::info!(kept = choice.kept, reason = %choice.reason, "reusing the choice between the first model and the renders' model");
            choice
        } else {
            tracing::info!(
                steps = first_steps,
                "first pass: training from the initial model, to initialise again on its renders"
            );
            let mut first_cfg = cfg.clone();
            first_cfg.steps = first_steps;
            first_cfg.init.sfm_rerun_fraction = 0.0;
            let first_dir = req.output.join("first_pass");
            let (first, back) = train_and_export(
                &TrainJob {
                    scene: &req.scene,
                    output: &first_dir,
                    mode: mode.clone(),
                    cfg: first_cfg,
                    open: req.open.clone(),
                    resume: req.resume,
                    evaluate: false,
                    lpips: &[],
                    engine: Engine::default(),
                    progress: req.progress,
                    run: Some(gems_train::RunDescription {
                        steps: first_steps,
                        ..description.clone()
                    }),
                    started,
                },
                engine,
            )?;
            engine = back;
            let source = init_images(&req.scene, &req.output, &init)?;
            let second = rerun_init_on_renders(
                &mut engine,
                &first,
                &source,
                &rerun,
                &init,
                cfg.seed,
                cfg.init.exif_focal_prior,
            );
            let rendered: Vec<String> = first.views.iter().map(|v| v.name.clone()).collect();
            let first_model = match &mode {
                InitMode::Colmap(Some(dir)) if !imported => Some(dir.as_path()),
                _ => None,
            };
            let accepted = accept_rerun(second, first_model, &rerun, &rendered)?;
            let (change, shift) = if accepted {
                let renders = gems_data::colmap::read_model(&renders_model)?;
                (
                    renders_change(&first, &renders),
                    renders_shift(&first, &renders),
                )
            } else {
                (None, None)
            };
            // The bound's name and value: an imported model has its own (never replaced, it
            // would otherwise train with free paths from its own cameras).
            let (bound_name, confirm_pct) = if imported {
                (
                    "init.sfm_rerun_confirm_imported_pct",
                    cfg.init.sfm_rerun_confirm_imported_pct,
                )
            } else {
                ("init.sfm_rerun_confirm_pct", cfg.init.sfm_rerun_confirm_pct)
            };
            let rule = ConfirmRule {
                confirm_pct,
                max_systematic: cfg.init.sfm_rerun_confirm_max_systematic,
                min_shift_pct: cfg.init.sfm_rerun_min_shift_pct,
            };
            let measure = |d: Option<gems_math::CameraDiscrepancy>| {
                d.map_or_else(
                    || "undetermined".to_owned(),
                    |d| {
                        format!(
                            "{:.2} % of the extent, {:.2}°",
                            d.centre_pct, d.rotation_deg
                        )
                    },
                )
            };
            let systematic = change.map_or_else(
                || "undetermined".to_owned(),
                |d| format!("{:.0} %", 100.0 * d.systematic_share),
            );
            let words = format!(
                "its cameras lie {} from the first model's ({bound_name} = {}), \
                 {systematic} of it a smooth change along the path \
                 (init.sfm_rerun_confirm_max_systematic = {}), and {} from the first pass's \
                 trained ones (init.sfm_rerun_min_shift_pct = {})",
                measure(change),
                rule.confirm_pct,
                rule.max_systematic,
                measure(shift),
                rule.min_shift_pct
            );
            let choice = if !accepted {
                RerunChoice::without_probes(
                    false,
                    "the initialiser failed on the renders or left a trained view out".into(),
                )
            } else if confirms_first_model(change, shift, rule) {
                RerunChoice {
                    first_model_confirmed: true,
                    ..RerunChoice::without_probes(
                        false,
                        if imported {
                            format!(
                                "{words}: it confirms the imported model, whose cameras the run \
                                 proper holds"
                            )
                        } else {
                            format!(
                                "{words}: it confirms the first model and brings nothing beyond it"
                            )
                        },
                    )
                }
            } else if imported {
                RerunChoice::without_probes(
                    false,
                    format!(
                        "{words}: it does not confirm the imported model, which is trained from \
                         as it is"
                    ),
                )
            } else if let Some(probe_steps) = cfg.sfm_rerun_probe_steps(rest) {
                // Each candidate trains as its run proper would, and the kept one's run proper
                // continues from its probe.
                tracing::info!(
                    steps = probe_steps,
                    "probing the first model and the renders' model against the blurry photos"
                );
                // The first model, then the renders' model.
                let candidates = [
                    (false, mode.clone(), rerun.join("probe_first")),
                    (
                        true,
                        InitMode::Colmap(Some(renders_model.clone())),
                        rerun.join("probe_renders"),
                    ),
                ];
                let mut losses = [0.0; 2];
                for ((renders, candidate, dir), loss) in candidates.iter().zip(&mut losses) {
                    let model = RunProperModel::of(*renders, false, false);
                    let cfg = run_proper_config(&cfg, model, rest);
                    (*loss, engine) = probe(&scene, candidate, &cfg, probe_steps, engine, dir)?;
                }
                let choice = RerunChoice::from_probes(probe_steps, losses[0], losses[1]);
                let kept = usize::from(choice.kept);
                continue_from(&candidates[kept].2, &req.output)?;
                remove_probe(&candidates[1 - kept].2)?;
                continues_probe = true;
                choice
            } else {
                RerunChoice::without_probes(
                    true,
                    format!(
                        "it registered every trained view and {words} \
                         (init.sfm_rerun_probe_fraction = 0)"
                    ),
                )
            }
            .with_measures(change, shift);
            // Written (with its folder) also when the initialiser failed before making one.
            choice.write(&rerun)?;
            if choice.kept {
                tracing::info!(reason = %choice.reason, "training from the model initialised on the renders");
            } else if imported {
                tracing::info!(reason = %choice.reason, confirmed = choice.first_model_confirmed, "the imported model checked on the first pass's renders");
            } else {
                tracing::warn!(
                    "the model initialised on the first pass's renders is not kept ({}); \
                     training from the first model with all the steps",
                    choice.reason
                );
            }
            choice
        };
        let keep_rerun = choice.kept;
        description.init = if keep_rerun {
            format!(
                "{}, then again on the first pass's sharp renders ({first_steps} + {rest} steps; {})",
                description.init, choice.reason
            )
        } else if imported {
            format!(
                "{} (checked by the built-in SfM on the first pass's renders, {first_steps} steps: \
                 {})",
                description.init, choice.reason
            )
        } else {
            format!(
                "{} (initialising again on the first pass's renders was tried and not kept: {})",
                description.init, choice.reason
            )
        };
        if keep_rerun {
            mode = InitMode::Colmap(Some(rerun.join("sparse").join("0")));
        }
        // Dense points from the first pass's depth maps, attached to the cameras the run
        // proper starts from: the confirmed first model's, or the renders' model's own (its
        // images are the first pass's renders). Not after probes: the kept one's run proper
        // continues from its checkpoint, which started from the sparse points.
        let dense_from = if keep_rerun {
            (cfg.init.renders_dense_points && choice.probe_steps == 0)
                .then_some((dense::ModelCameras::Own, "init.renders_dense_points"))
        } else {
            (choice.first_model_confirmed && cfg.init.confirmed_dense_points).then_some((
                dense::ModelCameras::FirstPass,
                "init.confirmed_dense_points",
            ))
        };
        if let Some((cameras, field)) = dense_from
            && let Some(start_model) = pose_model_of(&mode, &scene)
        {
            let dense = rerun.join("dense").join("sparse").join("0");
            let added = add_dense_points(
                &req.output.join("first_pass"),
                (&start_model, cameras),
                &dense,
                &cfg,
                req.resume,
            )?;
            description.init = format!(
                "{}, with {} dense points from the first pass's depth maps ({field})",
                description.init,
                added.map_or_else(|| "the earlier run's".to_owned(), |n| n.to_string())
            );
            mode = InitMode::Colmap(Some(dense));
        }
        let held = holds_confirmed_cameras(imported, &req.output, &cfg);
        if choice.first_model_confirmed && !keep_rerun && !held {
            description.init = format!(
                "{}; its cameras are not held: the SfM estimated its focal under heavy blur, \
                 which the check on renders made with that focal cannot measure \
                 (init.confirmed_hold_blurred_focal = false)",
                description.init
            );
            tracing::info!(
                "the confirmed first model's focal was estimated under heavy blur: its cameras \
                 train free (init.confirmed_hold_blurred_focal = false)"
            );
        }
        let model = RunProperModel::of(keep_rerun, choice.first_model_confirmed, held);
        cfg = run_proper_config(&cfg, model, rest);
    }
    train_and_report(TrainJob {
        scene: &req.scene,
        output: &req.output,
        mode,
        cfg,
        open: req.open,
        resume: req.resume || continues_probe,
        evaluate: req.evaluate,
        lpips: &req.lpips,
        engine,
        progress: req.progress,
        run: Some(description),
        started,
    })
}

/// Writes into `dense` the model at `start_model.0` (the run proper's start, whose cameras are
/// picked by `start_model.1`) with dense points from the first pass in `first_pass`
/// ([`dense::with_dense_points`]), up to `init.min_points` points in all, and returns how many
/// it added; a resumed run reuses the model an earlier one wrote (`None`).
fn add_dense_points(
    first_pass: &Path,
    start_model: (&Path, dense::ModelCameras),
    dense: &Path,
    cfg: &TrainConfig,
    resume: bool,
) -> Result<Option<usize>, PipelineError> {
    if resume && dense.join("points3D.bin").is_file() {
        return Ok(None);
    }
    let first = TrainOutput::load(first_pass)?;
    let model = gems_data::colmap::read_model(start_model.0)?;
    let target = cfg
        .init
        .min_points
        .min(cfg.mcmc.cap_max)
        .saturating_sub(model.points.len());
    let (with_dense, added) = dense::with_dense_points(&first, &model, start_model.1, target)?;
    gems_data::colmap::write_model(dense, &with_dense, gems_data::colmap::ModelFormat::Binary)?;
    tracing::info!(
        added,
        sparse = model.points.len(),
        model = %dense.display(),
        "dense points from the first pass's depth maps"
    );
    Ok(Some(added))
}

/// Why the initialisation's focal is to be kept as it is (`pose.focal_lr` then does not apply),
/// or `None` when it was estimated: by the built-in SfM or COLMAP without a focal, or from an
/// EXIF focal under its prior.
fn focal_is_known(init: &InitRequest) -> Option<&'static str> {
    match init.init {
        Init::Gt | Init::GtNoisy => Some("ground-truth cameras"),
        Init::Colmap => Some("a COLMAP model's camera"),
        Init::Sfm | Init::ColmapCli if init.focal_px.is_some() && init.focal_prior.is_none() => {
            Some("given on the command line")
        }
        Init::Sfm | Init::ColmapCli => None,
    }
}

/// The model the run proper after a first pass starts from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum RunProperModel {
    /// The first model, not confirmed by the SfM on the first pass's renders.
    First,
    /// The first model, confirmed by that SfM ([`RerunChoice::first_model_confirmed`]): its
    /// cameras are measured accurate, and `held` on them unless its focal was barely determined
    /// ([`holds_confirmed_cameras`]).
    ConfirmedFirst { held: bool },
    /// The model the SfM made on the first pass's renders.
    Renders,
}

impl RunProperModel {
    /// From whether the renders' model is kept, whether it confirmed the first model, and
    /// whether the confirmed cameras are held.
    fn of(renders_kept: bool, first_model_confirmed: bool, held: bool) -> Self {
        match (renders_kept, first_model_confirmed) {
            (true, _) => Self::Renders,
            (false, true) => Self::ConfirmedFirst { held },
            (false, false) => Self::First,
        }
    }
}

/// Whether the run proper holds a confirmed first model's cameras: always for an `imported`
/// model, and for the built-in SfM's unless the SfM estimated its focal from photos blurred
/// beyond [`gems_init::sfm::FOCAL_ADVICE_BLUR`] of their long side (its report in
/// `<output>/sfm`, [`gems_init::sfm::SfmStats::focal_barely_determined`]) and
/// `init.confirmed_hold_blurred_focal` is off. The check cannot measure such a model: the first
/// pass renders it with its own focal, so the SfM on the renders inherits the focal's error and
/// confirms it (BENCHMARKS.md, "A confirmed model whose focal blur left undetermined"). A report
/// that cannot be read, or that an earlier version wrote without the field, holds as before.
fn holds_confirmed_cameras(imported: bool, output: &Path, cfg: &TrainConfig) -> bool {
    imported
        || cfg.init.confirmed_hold_blurred_focal
        || !gems_eval::report::read_registration(output).is_some_and(|r| r.focal_barely_determined)
}

/// The configuration of the run proper after a first pass, from the run's `cfg`: from the
/// renders' model it has the `rest` of the steps, from the first model all of them; where its
/// initial poses are accurate (the renders' model's, or the confirmed first model's) it has
/// straight paths first (`init.accurate_poses_straight_fraction`), otherwise `cfg`'s own paths;
/// from the confirmed first model, where it is held, its exposures are held on their initial
/// cameras: their midpoints exactly with `init.confirmed_hold_midpoint`, otherwise their mean
/// poses by `init.confirmed_anchor_weight` (when above `cfg`'s `pose.anchor_weight`).
/// Either is one pass.
fn run_proper_config(cfg: &TrainConfig, model: RunProperModel, rest: usize) -> TrainConfig {
    let mut run = cfg.clone();
    if model == RunProperModel::Renders {
        run.steps = rest;
    }
    if model != RunProperModel::First {
        run.pose.straight_fraction = cfg.init.accurate_poses_straight_fraction;
    }
    if model == (RunProperModel::ConfirmedFirst { held: true }) {
        if cfg.init.confirmed_hold_midpoint {
            // The hold supersedes the soft anchor (measured without it).
            run.pose.hold_midpoint = true;
        } else {
            run.pose.anchor_weight = cfg.pose.anchor_weight.max(cfg.init.confirmed_anchor_weight);
        }
    }
    run.init.sfm_rerun_fraction = 0.0;
    run
}

/// What a run on `scene` is, for its report and `metrics.json` ([`TrainJob::run`]); the wall
/// time and peak memory are filled in when training ends.
pub fn describe_run(
    scene: &gems_data::Scene,
    protocol: Option<crate::Protocol>,
    init: String,
    cfg: &TrainConfig,
    engine: &Engine,
) -> gems_train::RunDescription {
    gems_train::RunDescription {
        protocol: protocol.map(|p| p.name().to_owned()),
        scene: scene.root.clone(),
        dataset: format!("{}, {}", scene.dataset, scene.layout.describe()),
        downscale: scene.downscale,
        hold: scene.hold,
        train_views: scene.train_views().count(),
        held_out_views: scene.nvs_eval_views().count(),
        init,
        steps: cfg.steps,
        virtual_views: cfg.num_virtual_views,
        mean_virtual_views: None,
        device: engine.describe(),
        wall_seconds: 0.0,
        peak_memory_bytes: None,
    }
}

/// The initialisation as the user asked for it, in words: the report's "what ran" line.
fn describe_init(init: &InitRequest, scene: &gems_data::Scene) -> String {
    let images = if init.events.is_some() {
        "the EDI-deblurred images (events)"
    } else {
        "the blurry photos"
    };
    match init.init {
        Init::Sfm => format!("built-in SfM on {images}"),
        Init::ColmapCli => format!("COLMAP ({}) on {images}", init.colmap_binary.display()),
        Init::Colmap => match (&init.colmap_model, &scene.sfm_dir, scene.sfm_match) {
            (Some(dir), _, _) if gems_init::sfm::is_builtin_model(dir) => {
                format!("the built-in SfM's model {}", dir.display())
            }
            (Some(dir), _, _) => format!("the COLMAP model {}", dir.display()),
            (None, Some(dir), Some(m)) => format!(
                "the dataset's COLMAP model {} ({} of {} views, images matched {})",
                dir.display(),
                m.matched,
                m.views,
                m.rule.describe()
            ),
            _ => match scene.pose_source {
                gems_data::PoseSource::Llff => "the dataset's poses file".into(),
                gems_data::PoseSource::Nerfstudio => "the dataset's transforms file".into(),
                _ => "the dataset's poses".into(),
            },
        },
        Init::Gt => "ground-truth poses".into(),
        Init::GtNoisy => format!(
            "ground-truth poses with noise (σ {} translation, {} rad rotation)",
            init.noise_translation, init.noise_rotation
        ),
    }
}

/// The process's peak resident memory (Linux `/proc/self/status` `VmHWM`), bytes; `None`
/// elsewhere.
fn peak_memory_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024)
}

/// Whether the model initialised on the first pass's renders may replace the first one or
/// measure it: when the initialiser registered every `rendered` view (the views the first pass
/// trained on; the confirmation and the probes then decide, [`crate::probe`]). With the first
/// model's folder `first_model`, views it has and the renders' model lacks (held-out photos that
/// did not register among the renders) are then placed by the similarity between the models
/// ([`place_missing_views`]) and the model is rewritten. A rejected model's `sparse` folder is
/// removed; its images stay for inspection.
fn accept_rerun(
    second: Result<PathBuf, PipelineError>,
    first_model: Option<&Path>,
    rerun: &Path,
    rendered: &[String],
) -> Result<bool, PipelineError> {
    let reason = match second {
        Ok(dir) => {
            let mut model = gems_data::colmap::read_model(&dir)?;
            let views = rendered
                .iter()
                .filter(|n| model.image_by_name(n).is_some())
                .count();
            if views >= rendered.len() {
                let placed = match first_model {
                    Some(first) => {
                        place_missing_views(&gems_data::colmap::read_model(first)?, &mut model)
                    }
                    None => Vec::new(),
                };
                if !placed.is_empty() {
                    tracing::warn!(
                        "{} did not register among the renders; placed from the first model",
                        placed.join(", ")
                    );
                    gems_data::colmap::write_model(
                        &dir,
                        &model,
                        gems_data::colmap::ModelFormat::Binary,
                    )
                    .map_err(PipelineError::WriteColmapModel)?;
                }
                tracing::info!(
                    views,
                    "the model initialised on the renders registered every trained view"
                );
                return Ok(true);
            }
            format!(
                "it registered {views} of the {} trained views",
                rendered.len()
            )
        }
        Err(PipelineError::Sfm(e)) => format!("the initialiser failed on them: {e}"),
        Err(e) => return Err(e),
    };
    tracing::warn!("initialising again on the first pass's renders did not work ({reason})");
    let sparse = rerun.join("sparse");
    if sparse.is_dir() {
        std::fs::remove_dir_all(&sparse).map_err(|source| gems_fs::FsError {
            path: sparse,
            source,
        })?;
    }
    Ok(false)
}

/// Trains, writes `point_cloud.ply` (input frame), the model, and — unless disabled — metrics,
/// trajectories and `report.html`.
pub fn train_and_report(mut job: TrainJob<'_>) -> Result<RunOutcome, PipelineError> {
    let engine = std::mem::take(&mut job.engine);
    let (output, mut engine) = train_and_export(&job, engine)?;
    let ply = job.output.join("point_cloud.ply");
    if !job.evaluate {
        return Ok(RunOutcome {
            point_cloud: ply,
            report: None,
            metrics: None,
        });
    }
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

/// Trains `job` on `engine` (its own `engine` field is not used), then writes `config.toml`,
/// the model and `point_cloud.ply` (input frame); returns the result and the engine.
fn train_and_export(
    job: &TrainJob<'_>,
    engine: Engine,
) -> Result<(TrainOutput, Engine), PipelineError> {
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
    let described_init = job.run.as_ref().map(|r| r.init.as_str());
    let mut trainer = start_trainer(
        &scene,
        &job.mode,
        described_init,
        job.cfg.clone(),
        job.resume,
        job.output,
    )?;
    trainer.set_engine(engine);
    gems_fs::write_atomic(
        &job.output.join("config.toml"),
        trainer.config().to_toml().as_bytes(),
    )?;
    let start = Instant::now();
    train_with_checkpoints(&mut trainer, job.output, job.progress)?;
    let memory = trainer.gpu_memory();
    if let Some(m) = memory {
        tracing::info!("GPU memory held by gems's buffers after training: {m}");
    }
    if let Some(profile) = trainer.gpu_profile() {
        let mut report = profile.report();
        if let Some(m) = memory {
            report.push_str(&format!("\nGPU memory held by gems's buffers: {m}\n"));
        }
        let path = job.output.join(GPU_PROFILE);
        gems_fs::write_atomic(&path, report.as_bytes())?;
        tracing::info!(path = %path.display(), "where the GPU steps' time went:\n{report}");
    }
    let mut output = TrainOutput::from_trainer(&trainer);
    output.pose_model = pose_model;
    output.run = job.run.clone().map(|mut run| {
        run.wall_seconds = job.started.elapsed().as_secs_f64();
        run.peak_memory_bytes = peak_memory_bytes();
        let counts = &output.history.virtual_views;
        run.mean_virtual_views = (!counts.is_empty())
            .then(|| counts.iter().map(|&n| f64::from(n)).sum::<f64>() / counts.len() as f64);
        run
    });
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
    let engine = trainer.set_engine(Engine::cpu());
    Ok((output, engine))
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
/// with) when asked and there is one, else a fresh one with `cfg`. `described_init` is the
/// initialisation as the run's description words it, logged instead of `mode`'s label (which
/// says "colmap" for the built-in SfM's model too).
fn start_trainer(
    scene: &gems_data::Scene,
    mode: &InitMode,
    described_init: Option<&str>,
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
    tracing::info!(
        views = input.views.len(),
        gaussians = input.gaussians.len(),
        init = described_init.unwrap_or(&input.init_label),
        "training"
    );
    Ok(Trainer::new(cfg, input)?)
}

/// Runs the remaining steps with a checkpoint every `checkpoint_every` steps and one at the end.
fn train_with_checkpoints(
    trainer: &mut Trainer,
    output: &Path,
    progress: bool,
) -> Result<(), PipelineError> {
    let bar = crate::progress::bar(
        progress,
        trainer.config().steps,
        "training {wide_bar} {pos}/{len} steps  {msg}  {rate}  ETA {eta}",
    );
    bar.set_position(trainer.steps_done() as u64);
    trainer.run(|t, r| {
        bar.set_position(r.step as u64);
        bar.set_message(format!(
            "loss {:.3}  PSNR {:.1}  {} Gaussians",
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
    let eval_started = Instant::now();
    let bar = crate::progress::bar(
        job.progress,
        gems_eval::evaluation_units(&data),
        "evaluating {wide_bar} {pos}/{len} views  ETA {eta}",
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
    let mut eval = eval;
    eval.metrics.eval_seconds = Some(eval_started.elapsed().as_secs_f64());
    gems_eval::write_metrics_json(&job.output.join("metrics.json"), &eval.metrics)?;
    gems_eval::write_trajectories(job.output, output)?;
    gems_eval::write_renders_on(engine, job.output, output, &data, &eval)?;
    let mut input = gems_eval::report_input(output, &data, &eval, 4);
    input.registration = gems_eval::report::read_registration(job.output);
    let report = gems_eval::write_report(job.output, &input)?;
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

#[cfg(test)]
mod tests {
    use super::*;
    use gems_data::colmap::{Camera, CameraModel, Image, ModelFormat, SparseModel, write_model};

    /// A model of the named images, image `i` at centre (i, i², 0) looking down +z; one camera,
    /// no points.
    fn model_with(dir: &Path, names: &[&str]) -> PathBuf {
        let images = names
            .iter()
            .enumerate()
            .map(|(i, name)| {
                let x = i as f64;
                Image {
                    id: i as u32 + 1,
                    qvec: [1.0, 0.0, 0.0, 0.0],
                    tvec: [-x, -x * x, 0.0],
                    camera_id: 1,
                    name: (*name).to_owned(),
                    points2d: Vec::new(),
                }
            })
            .collect();
        let model = SparseModel {
            cameras: vec![Camera {
                id: 1,
                model: CameraModel::SimplePinhole,
                width: 96,
                height: 64,
                params: vec![80.0, 48.0, 32.0],
            }],
            images,
            points: Vec::new(),
        };
        write_model(dir, &model, ModelFormat::Binary).unwrap();
        dir.to_path_buf()
    }

    #[test]
    fn the_rerun_model_is_kept_only_when_it_registers_every_trained_view() {
        let tmp = tempfile::tempdir().unwrap();
        let all = ["a.png", "b.png", "c.png"];
        let first = model_with(&tmp.path().join("first"), &all);
        let first = Some(first.as_path());
        let rerun = tmp.path().join("rerun");
        let sparse = rerun.join("sparse").join("0");
        let trained: Vec<String> = all.iter().map(|n| (*n).to_owned()).collect();

        let second = model_with(&sparse, &all);
        assert!(accept_rerun(Ok(second), first, &rerun, &trained).unwrap());
        assert!(sparse.is_dir(), "an accepted model stays");

        // "c.png" held out: the second model lacks it and gets it placed from the first.
        let second = model_with(&sparse, &all[..2]);
        assert!(accept_rerun(Ok(second), first, &rerun, &trained[..2]).unwrap());
        let placed = gems_data::colmap::read_model(&sparse).unwrap();
        assert!(placed.image_by_name("c.png").is_some());

        // Without the first model's folder (an imported model, only measured) nothing is placed.
        let second = model_with(&sparse, &all[..2]);
        assert!(accept_rerun(Ok(second), None, &rerun, &trained[..2]).unwrap());
        let unplaced = gems_data::colmap::read_model(&sparse).unwrap();
        assert!(unplaced.image_by_name("c.png").is_none());

        // "c.png" trained but lost: rejected, and the model removed.
        let second = model_with(&sparse, &all[..2]);
        assert!(!accept_rerun(Ok(second), first, &rerun, &trained).unwrap());
        assert!(
            !rerun.join("sparse").exists(),
            "a rejected model is removed, so a resumed run decides again"
        );

        let failed = Err(PipelineError::Sfm(gems_init::sfm::SfmError::TooFewImages(
            1,
        )));
        assert!(!accept_rerun(failed, first, &rerun, &trained).unwrap());
        let other = Err(PipelineError::Config("bad".into()));
        assert!(
            accept_rerun(other, first, &rerun, &trained).is_err(),
            "errors other than the initialiser's own stop the run"
        );
    }

    #[test]
    fn a_confirmed_model_is_held_unless_blur_left_its_estimated_focal_undetermined() {
        let dir = tempfile::tempdir().unwrap();
        // A run's output folder with the SfM's report.
        let report = |name: &str, json: &str| {
            let out = dir.path().join(name);
            std::fs::create_dir_all(out.join("sfm")).unwrap();
            std::fs::write(out.join("sfm").join(gems_init::sfm::REPORT_FILE), json).unwrap();
            out
        };
        let barely = report(
            "barely",
            r#"{"views": [], "focal": 228.0, "focal_barely_determined": true}"#,
        );
        let known = report(
            "known",
            r#"{"views": [], "focal": 228.0, "focal_barely_determined": false}"#,
        );
        // Written before the field existed, and unreadable: held, as they were.
        let older = report(
            "older",
            r#"{"views": [], "focal": 228.0, "focal_from_metadata": false}"#,
        );
        let broken = report("broken", "{");
        let missing = dir.path().join("missing");
        let mut cfg = TrainConfig::default();
        assert!(!cfg.init.confirmed_hold_blurred_focal, "the default");
        assert!(!holds_confirmed_cameras(false, &barely, &cfg));
        for sfm in [&known, &older, &broken, &missing] {
            assert!(
                holds_confirmed_cameras(false, sfm, &cfg),
                "{}",
                sfm.display()
            );
        }
        // An imported model's focal is its own camera's: held.
        assert!(holds_confirmed_cameras(true, &barely, &cfg));
        cfg.init.confirmed_hold_blurred_focal = true;
        assert!(holds_confirmed_cameras(false, &barely, &cfg));
    }

    #[test]
    fn the_run_propers_paths_and_anchor_follow_where_it_starts() {
        let mut cfg = TrainConfig {
            steps: 300,
            ..TrainConfig::default()
        };
        cfg.pose.straight_fraction = 0.05;
        cfg.pose.anchor_weight = 3.0;
        cfg.init.accurate_poses_straight_fraction = 0.2;
        cfg.init.confirmed_anchor_weight = 50.0;
        cfg.init.confirmed_hold_midpoint = true;
        let paths = |c: &TrainConfig| {
            (
                c.steps,
                c.pose.straight_fraction,
                c.pose.anchor_weight,
                c.pose.hold_midpoint,
                c.init.sfm_rerun_fraction,
            )
        };
        // The renders' model: the rest of the steps, accurate poses, the run's own anchor.
        assert_eq!(
            paths(&run_proper_config(&cfg, RunProperModel::Renders, 200)),
            (200, 0.2, 3.0, false, 0.0)
        );
        // The first model confirmed by its renders: all the steps, accurate poses, held.
        let held = RunProperModel::ConfirmedFirst { held: true };
        assert_eq!(
            paths(&run_proper_config(&cfg, held, 200)),
            (300, 0.2, 3.0, true, 0.0)
        );
        // Confirmed but not held (its focal barely determined): accurate poses, free.
        assert_eq!(
            paths(&run_proper_config(
                &cfg,
                RunProperModel::ConfirmedFirst { held: false },
                200
            )),
            (300, 0.2, 3.0, false, 0.0)
        );
        // Without the hold, the confirmed anchor, unless the run holds every start itself.
        cfg.init.confirmed_hold_midpoint = false;
        assert_eq!(
            paths(&run_proper_config(&cfg, held, 200)),
            (300, 0.2, 50.0, false, 0.0)
        );
        cfg.pose.hold_midpoint = true;
        assert!(
            run_proper_config(&cfg, RunProperModel::Renders, 200)
                .pose
                .hold_midpoint
        );
        cfg.pose.hold_midpoint = false;
        // A run's own heavier anchor is kept.
        cfg.pose.anchor_weight = 80.0;
        assert_eq!(run_proper_config(&cfg, held, 200).pose.anchor_weight, 80.0);
        // The first model because the renders' failed: all the steps, the run's own paths.
        assert_eq!(
            paths(&run_proper_config(&cfg, RunProperModel::First, 200)),
            (300, 0.05, 80.0, false, 0.0)
        );
    }
}

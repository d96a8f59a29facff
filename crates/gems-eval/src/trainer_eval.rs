//! The evaluation protocol on a trained [`Trainer`], and trajectory export.

use std::path::Path;

use gems_math::Se3;
use gems_metrics::Lpips;
use gems_splat::Renderer;
use gems_train::blur::Intrinsics;
use gems_train::trainer::Trainer;

use crate::EvalError;
use crate::evaluate::{
    EvalView, MetricsReport, PoseMode, SplitResult, ape_of_centres, evaluate_views,
};
use crate::refine::PoseRefineConfig;
use crate::tum::write_tum;

/// A held-out (novel) view: never trained on; its pose is the initial (SfM) one.
#[derive(Clone, Debug)]
pub struct HeldOutView {
    pub name: String,
    pub intrinsics: Intrinsics,
    /// Initial camera-to-world pose in the trainer's normalised frame.
    pub c2w_init: Se3,
    /// Sharp ground truth `[H,W,3]`.
    pub gt: Vec<f32>,
}

/// Ground truth for evaluation.
#[derive(Clone, Debug, Default)]
pub struct EvalData {
    /// Sharp ground truth per training view (same order as `trainer.views`), `None` where
    /// unknown. Empty means none known.
    pub train_gt: Vec<Option<Vec<f32>>>,
    pub held_out: Vec<HeldOutView>,
}

/// Everything one evaluation produced.
#[derive(Clone, Debug)]
pub struct Evaluation {
    pub metrics: MetricsReport,
    /// Indices (into `trainer.views`) of the views in `deblur`.
    pub deblur_views: Vec<usize>,
    pub deblur: SplitResult,
    pub nvs: SplitResult,
    pub nvs_no_pose_opt: SplitResult,
}

/// Runs the protocol (see the crate docs). APE needs ground-truth poses on at least three
/// training views (non-collinear centres); otherwise `ape` is `None`.
pub fn evaluate_trainer(
    trainer: &Trainer,
    data: &EvalData,
    refine: &PoseRefineConfig,
    lpips: Option<&Lpips>,
) -> Result<Evaluation, EvalError> {
    if !data.train_gt.is_empty() && data.train_gt.len() != trainer.views.len() {
        return Err(EvalError::Input(format!(
            "{} training ground-truth entries for {} training views",
            data.train_gt.len(),
            trainer.views.len()
        )));
    }
    let gaussians = &trainer.state.gaussians;
    let mut renderer = Renderer::new();
    let mut deblur_views = Vec::new();
    let mut train_views = Vec::new();
    for (i, (view, gt)) in trainer.views.iter().zip(&data.train_gt).enumerate() {
        if let Some(gt) = gt {
            deblur_views.push(i);
            train_views.push(EvalView {
                name: view.name.clone(),
                intrinsics: view.intrinsics,
                c2w_init: view.c2w_init,
                c2w_eval: trainer.mid_pose(i),
                gt: gt.clone(),
            });
        }
    }
    let held: Vec<EvalView> = data
        .held_out
        .iter()
        .map(|h| EvalView {
            name: h.name.clone(),
            intrinsics: h.intrinsics,
            c2w_init: h.c2w_init,
            c2w_eval: h.c2w_init,
            gt: h.gt.clone(),
        })
        .collect();
    let deblur = evaluate_views(
        &mut renderer,
        gaussians,
        &train_views,
        PoseMode::AsGiven,
        lpips,
    )?;
    let nvs_no_pose_opt =
        evaluate_views(&mut renderer, gaussians, &held, PoseMode::AsGiven, lpips)?;
    let nvs = evaluate_views(
        &mut renderer,
        gaussians,
        &held,
        PoseMode::Refine(*refine),
        lpips,
    )?;
    let ape = trainer_ape(trainer);
    let metrics = MetricsReport {
        deblur: deblur.scores.clone(),
        nvs: nvs.scores.clone(),
        nvs_no_pose_opt: nvs_no_pose_opt.scores.clone(),
        ape,
        steps: trainer.state.step,
        seconds: trainer.state.seconds,
        gaussians: gaussians.len(),
        init: trainer.init_label.clone(),
    };
    Ok(Evaluation {
        metrics,
        deblur_views,
        deblur,
        nvs,
        nvs_no_pose_opt,
    })
}

/// Midpoint camera centres and ground-truth centres (input frame) of the views with ground truth.
pub fn midpoint_and_gt_centres(trainer: &Trainer) -> (Vec<[f64; 3]>, Vec<[f64; 3]>) {
    let norm = &trainer.normalization;
    trainer
        .views
        .iter()
        .enumerate()
        .filter_map(|(i, v)| {
            let gt = v.c2w_gt?;
            let est = norm.invert_point(&trainer.mid_pose(i).trans);
            let gt_centre: [f64; 3] = norm.invert_point(&gt.trans).into();
            Some((<[f64; 3]>::from(est), gt_centre))
        })
        .unzip()
}

fn trainer_ape(trainer: &Trainer) -> Option<crate::ApeSummary> {
    let (est, gt) = midpoint_and_gt_centres(trainer);
    if est.len() < 3 {
        return None;
    }
    match ape_of_centres(&est, &gt) {
        Ok(a) => Some(a),
        Err(e) => {
            tracing::warn!("APE not computed: {e}");
            None
        }
    }
}

/// A file-name-safe stem of a view name ("images/0001.png" → "0001").
pub fn file_stem(name: &str) -> String {
    let base = Path::new(name)
        .file_stem()
        .and_then(|s| s.to_str())
        .unwrap_or(name);
    base.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || "._-".contains(c) {
                c
            } else {
                '_'
            }
        })
        .collect()
}

fn to_input_frame(trainer: &Trainer, c2w: &Se3) -> Se3 {
    let (r, t) = trainer.normalization.invert_c2w(&c2w.rot, &c2w.trans);
    Se3::new(r, t)
}

/// Writes, in the input frame: `trajectories/<view>.txt` (the n virtual camera-to-world poses,
/// timestamps u ∈ [0, 1]), `trajectories/mid.txt` (midpoints, timestamp = view index) and, when
/// known, `trajectories/gt.txt` (same timestamps, so evo associates them 1:1).
pub fn write_trajectories(dir: &Path, trainer: &Trainer) -> Result<(), EvalError> {
    let tdir = dir.join("trajectories");
    let n = trainer.cfg.num_virtual_views;
    let times: Vec<f64> = (0..n)
        .map(|k| {
            if n == 1 {
                0.5
            } else {
                k as f64 / (n - 1) as f64
            }
        })
        .collect();
    let mut mids = Vec::new();
    let mut gts = Vec::new();
    for (i, v) in trainer.views.iter().enumerate() {
        let poses: Vec<(f64, Se3)> = trainer
            .virtual_poses(i)
            .iter()
            .zip(&times)
            .map(|(p, &u)| (u, to_input_frame(trainer, p)))
            .collect();
        write_tum(&tdir.join(format!("{}.txt", file_stem(&v.name))), &poses)?;
        mids.push((i as f64, to_input_frame(trainer, &trainer.mid_pose(i))));
        if let Some(gt) = v.c2w_gt {
            gts.push((i as f64, to_input_frame(trainer, &gt)));
        }
    }
    write_tum(&tdir.join("mid.txt"), &mids)?;
    if !gts.is_empty() {
        write_tum(&tdir.join("gt.txt"), &gts)?;
    }
    Ok(())
}

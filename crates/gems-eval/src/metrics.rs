//! Per-image metrics, split summaries, APE and the metrics.json document.

use gems_gpu::Engine;
use gems_math::{Alignment, Intrinsics, Matrix3, Se3, So3, ape_translation, error_stats};
use gems_metrics::Lpips;
use gems_splat::Gaussians;
use serde::{Deserialize, Serialize};

use crate::EvalError;
use crate::refine::{PoseRefineConfig, refine_pose, render};

/// JSON has no infinity: serde_json writes the PSNR of a perfect render as `null`; read it back
/// as +∞.
fn null_as_infinity<'de, D: serde::Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::INFINITY))
}

/// Metrics of one image.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ImageScore {
    pub name: String,
    /// dB; +∞ (`null` in JSON) for a perfect render.
    #[serde(deserialize_with = "null_as_infinity")]
    pub psnr: f64,
    pub ssim: f64,
    /// Absent (null) when no LPIPS weights were given.
    pub lpips: Option<f64>,
}

/// Mean metrics of a split plus the per-image values.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SplitScores {
    #[serde(deserialize_with = "null_as_infinity")]
    pub psnr: f64,
    pub ssim: f64,
    /// Mean LPIPS, or null when any image lacks it (no weights given).
    pub lpips: Option<f64>,
    pub per_image: Vec<ImageScore>,
}

impl SplitScores {
    /// Means over `per_image` (per-image average, as PRISM3D and BAD-Gaussians report). `None`
    /// for an empty split.
    pub fn from_images(per_image: Vec<ImageScore>) -> Option<Self> {
        if per_image.is_empty() {
            return None;
        }
        let n = per_image.len() as f64;
        let psnr = per_image.iter().map(|s| s.psnr).sum::<f64>() / n;
        let ssim = per_image.iter().map(|s| s.ssim).sum::<f64>() / n;
        let lpips = per_image
            .iter()
            .map(|s| s.lpips)
            .sum::<Option<f64>>()
            .map(|s| s / n);
        Some(SplitScores {
            psnr,
            ssim,
            lpips,
            per_image,
        })
    }
}

/// APE translation statistics (evo definitions) after Sim(3) Umeyama alignment of the estimated
/// camera centres to the ground truth; units of the ground truth.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ApeSummary {
    pub rmse: f64,
    pub mean: f64,
    pub median: f64,
    pub std: f64,
    pub max: f64,
}

/// The cameras' focal length (x, first training view, pixels at its training size): where
/// training started, where it ended (`pose.focal_lr`; the same when not learned), and the
/// scene's own camera when it has one (generated scenes: the truth; real datasets: their
/// calibration).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct FocalSummary {
    pub initial_px: f64,
    pub trained_px: f64,
    pub scene_px: Option<f64>,
}

impl FocalSummary {
    /// Relative error of the trained and the initial focal against the scene's, in %.
    pub fn errors_percent(&self) -> Option<(f64, f64)> {
        let s = self.scene_px?;
        Some((
            100.0 * (self.trained_px - s) / s,
            100.0 * (self.initial_px - s) / s,
        ))
    }

    /// One line for the report and the console, e.g. "146.5 px at the start, 157.2 px trained;
    /// the scene's camera has 173.2 px: -15.42 % at the start, -9.23 % trained".
    pub fn describe(&self) -> String {
        let learned = if self.trained_px == self.initial_px {
            format!("{:.1} px, kept (not learned)", self.trained_px)
        } else {
            format!(
                "{:.1} px at the start, {:.1} px trained",
                self.initial_px, self.trained_px
            )
        };
        match (self.scene_px, self.errors_percent()) {
            (Some(s), Some((trained, initial))) => format!(
                "{learned}; the scene's camera has {s:.1} px: {initial:+.2} % at the start, \
                 {trained:+.2} % trained"
            ),
            _ => learned,
        }
    }
}

/// Relative rotation error over every pair of views, in degrees: for views i and j the angle of
/// (R̂ᵢᵀ R̂ⱼ)ᵀ (Rᵢᵀ Rⱼ), the estimated camera-to-camera rotation against the ground truth's. It
/// needs no alignment (a global rotation of either set cancels) and sees what APE, which aligns
/// camera centres only, cannot: cameras in the right places looking the wrong way. This is the
/// pairwise rotation error of SfM evaluations (e.g. the Image Matching Challenge's mAA over
/// relative poses); all pairs rather than consecutive ones, because views need not be ordered.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct RotationErrorSummary {
    pub rmse_deg: f64,
    pub mean_deg: f64,
    pub median_deg: f64,
    pub max_deg: f64,
}

/// Which of the result's frames held-out views are carried into.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum HeldOutFrame {
    /// The frame the Gaussians started in: the similarity between the reference's training
    /// cameras and the result's initial ones (the identity when the run started from the
    /// dataset's own poses, so the held-out views are rendered exactly at the dataset's poses, as
    /// the published tables do).
    #[default]
    Initial,
    /// The trained cameras' frame: the similarity to the trained mid-exposure cameras. On
    /// Deblur-NeRF's blurball (×8, 3000 steps, from its COLMAP model) it scores 2.5 dB below
    /// `Initial`: the trained cameras share a shift (the exposure paths' common offset) that
    /// the Gaussians do not (BENCHMARKS.md).
    Trained,
}

/// How the held-out views were posed for the novel-view figures: at a source's poses, carried
/// into one of the result's frames ([`HeldOutFrame`]) by the similarity between that source's
/// training cameras and the result's. Refinement starts there too.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct HeldOutPosing {
    /// Where the poses come from ("the dataset's poses (its COLMAP model)", …).
    pub source: String,
    /// The frame they were carried into.
    #[serde(default)]
    pub frame: HeldOutFrame,
    /// Training cameras the similarity was fitted on; 0 when too few: the poses were then used
    /// as they are.
    pub similarity_cameras: usize,
}

impl HeldOutPosing {
    /// One line: "the dataset's poses (its COLMAP model), carried into the result's initial
    /// frame by the similarity of 23 training cameras".
    pub fn describe(&self) -> String {
        let frame = match self.frame {
            HeldOutFrame::Initial => "the result's initial frame",
            HeldOutFrame::Trained => "the trained cameras' frame",
        };
        if self.similarity_cameras > 0 {
            format!(
                "{}, carried into {frame} by the similarity of {} training cameras",
                self.source, self.similarity_cameras
            )
        } else {
            format!(
                "{}, as they are (too few training cameras for a similarity)",
                self.source
            )
        }
    }
}

/// How far the trained mid-exposure cameras lie from the held-out views' pose source's cameras
/// of the same training views (and how far the initial cameras lay), each after its own best
/// similarity: centres as RMSE in % of the largest distance between two of the result's
/// cameras, rotations as RMSE in degrees. From a dataset's COLMAP model the initial figures are
/// 0 and the trained ones say how far training changed the cameras' shape.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct CameraShift {
    pub views: usize,
    pub centre_pct: f64,
    pub rotation_deg: f64,
    pub initial_centre_pct: f64,
    pub initial_rotation_deg: f64,
}

/// What each split of [`MetricsReport`] measures, by its JSON key (also in `metrics.json` under
/// `labels`, and the words the console and the report use).
pub fn split_labels() -> [(&'static str, &'static str); 5] {
    [
        (
            "input",
            "blurry input: each blurry training photo against its sharp image",
        ),
        (
            "deblur",
            "deblurring: training views rendered at their trajectory midpoint",
        ),
        (
            "deblur_refined",
            "deblurring, refined: training views after test-time pose refinement from their \
             initial pose (the GeMS authors' protocol)",
        ),
        (
            "nvs_no_pose_opt",
            "novel views, unrefined: held-out views rendered at their reference pose (the \
             dataset's when it has poses; see held_out_pose) carried into the result's frame (the \
             published tables' protocol)",
        ),
        (
            "nvs",
            "novel views, refined: held-out views after test-time pose refinement from that pose \
             (BAD-Gaussians' and GeMS's protocol)",
        ),
    ]
}

/// The `metrics.json` document.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MetricsReport {
    /// Training views rendered at their trajectory midpoint vs their sharp ground truth.
    pub deblur: Option<SplitScores>,
    /// Training views after test-time pose refinement from their initial pose, Gaussians frozen
    /// (the GeMS authors' protocol: `GopiRajuMatta/PRISM3D:prism3d_trainer.py`,
    /// `eval_with_pose_opt`); `deblur` is our stricter figure at the trajectory midpoint.
    #[serde(default)]
    pub deblur_refined: Option<SplitScores>,
    /// Each blurry training input against its sharp ground truth: where the user started.
    #[serde(default)]
    pub input: Option<SplitScores>,
    /// Held-out views after test-time pose refinement.
    pub nvs: Option<SplitScores>,
    /// Held-out views at their initial poses.
    pub nvs_no_pose_opt: Option<SplitScores>,
    /// APE of the training views' trajectory midpoints (the poses gems reports).
    pub ape: Option<ApeSummary>,
    /// APE of the training views' initial poses (the initialisation's, before training), so
    /// `ape` reads as how far training moved the cameras toward the truth.
    #[serde(default)]
    pub ape_init: Option<ApeSummary>,
    /// Relative rotation error of the training views' trajectory midpoints.
    #[serde(default)]
    pub rotation_error: Option<RotationErrorSummary>,
    /// The same for the initial poses.
    #[serde(default)]
    pub rotation_error_init: Option<RotationErrorSummary>,
    /// The focal length before and after training, beside the scene's camera.
    #[serde(default)]
    pub focal: Option<FocalSummary>,
    pub steps: usize,
    pub seconds: f64,
    pub gaussians: usize,
    /// How poses and points were initialised (e.g. "gt-noisy (σ …)"), shown in the report.
    pub init: String,
    /// What each split measures, by key ([`split_labels`]).
    #[serde(default)]
    pub labels: std::collections::BTreeMap<String, String>,
    /// How the held-out views were posed (`nvs_no_pose_opt`, and where `nvs` starts).
    #[serde(default)]
    pub held_out_pose: Option<HeldOutPosing>,
    /// How far training moved the cameras from the held-out views' pose source's.
    #[serde(default)]
    pub camera_shift: Option<CameraShift>,
    /// What the user ran: protocol, data, initialisation, schedule, device, cost.
    #[serde(default)]
    pub run: Option<gems_train::RunDescription>,
    /// Wall time of the evaluation, s.
    #[serde(default)]
    pub eval_seconds: Option<f64>,
}

/// Scores a render against its ground truth. The render is clamped to [0, 1] first (PRISM3D
/// clamps its renders before every metric).
pub fn score_image(
    name: &str,
    render: &[f32],
    gt: &[f32],
    height: usize,
    width: usize,
    lpips: Option<&Lpips>,
) -> Result<ImageScore, EvalError> {
    let clamped: Vec<f32> = render.iter().map(|v| v.clamp(0.0, 1.0)).collect();
    Ok(ImageScore {
        name: name.to_owned(),
        psnr: gems_metrics::psnr(&clamped, gt, height, width)?,
        ssim: gems_metrics::ssim(&clamped, gt, height, width)?,
        lpips: lpips
            .map(|net| net.distance(&clamped, gt, height, width))
            .transpose()?,
    })
}

/// One view to evaluate.
#[derive(Clone, Debug)]
pub struct EvalView {
    pub name: String,
    pub intrinsics: Intrinsics,
    /// Where test-time refinement starts (the initial/SfM pose).
    pub c2w_init: Se3,
    /// The pose rendered without refinement (training views: the trajectory midpoint; held-out
    /// views: the initial pose).
    pub c2w_eval: Se3,
    /// Sharp ground truth `[H,W,3]` in [0, 1].
    pub gt: Vec<f32>,
}

/// How the evaluation pose of each view is chosen.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum PoseMode {
    /// Render at `c2w_eval`.
    AsGiven,
    /// Refine from `c2w_init` against the ground truth first.
    Refine(PoseRefineConfig),
}

/// Renders, poses and scores of a split.
#[derive(Clone, Debug)]
pub struct SplitResult {
    pub scores: Option<SplitScores>,
    /// Unclamped renders `[H,W,3]`, one per view.
    pub renders: Vec<Vec<f32>>,
    /// The camera-to-world pose each render used.
    pub poses: Vec<Se3>,
}

/// Renders every view (black background, Gaussians frozen) and scores it.
pub fn evaluate_views(
    renderer: &mut Engine,
    gaussians: &Gaussians,
    views: &[EvalView],
    mode: PoseMode,
    lpips: Option<&Lpips>,
) -> Result<SplitResult, EvalError> {
    evaluate_views_with_progress(renderer, gaussians, views, mode, lpips, &mut |_| {})
}

/// [`evaluate_views`], calling `on_view` with each view's name after it is scored.
pub fn evaluate_views_with_progress(
    renderer: &mut Engine,
    gaussians: &Gaussians,
    views: &[EvalView],
    mode: PoseMode,
    lpips: Option<&Lpips>,
    on_view: &mut dyn FnMut(&str),
) -> Result<SplitResult, EvalError> {
    let mut per_image = Vec::with_capacity(views.len());
    let mut renders = Vec::with_capacity(views.len());
    let mut poses = Vec::with_capacity(views.len());
    let mut scene = renderer.freeze(gaussians)?;
    for (i, v) in views.iter().enumerate() {
        tracing::debug!(view = %v.name, "evaluating view {}/{}", i + 1, views.len());
        let k = &v.intrinsics;
        let (h, w) = (k.height as usize, k.width as usize);
        if v.gt.len() != h * w * 3 {
            return Err(EvalError::Input(format!(
                "view {}: ground truth has {} values, intrinsics say {w}x{h}x3",
                v.name,
                v.gt.len()
            )));
        }
        let pose = match mode {
            PoseMode::AsGiven => v.c2w_eval,
            PoseMode::Refine(cfg) => {
                let r = refine_pose(&mut scene, &v.c2w_init, k, &v.gt, &cfg)?;
                tracing::debug!(view = %v.name, l1_before = r.l1_before, l1_after = r.l1_after, "pose refined");
                r.c2w
            }
        };
        let rgb = render(&mut scene, &pose, k)?;
        per_image.push(score_image(&v.name, &rgb, &v.gt, h, w, lpips)?);
        renders.push(rgb);
        poses.push(pose);
        on_view(&v.name);
    }
    Ok(SplitResult {
        scores: SplitScores::from_images(per_image),
        renders,
        poses,
    })
}

/// [`RotationErrorSummary`] of estimated against ground-truth camera-to-world rotations (same
/// order); at least two views.
pub fn relative_rotation_error(
    est: &[Matrix3<f64>],
    gt: &[Matrix3<f64>],
) -> Result<RotationErrorSummary, EvalError> {
    if est.len() != gt.len() || est.len() < 2 {
        return Err(EvalError::Input(format!(
            "relative rotation error needs two or more views with ground truth, got {} estimated \
             and {} ground-truth rotations",
            est.len(),
            gt.len()
        )));
    }
    // Each input made exactly orthonormal once, so the O(n²) pair products need no SVD.
    let clean = |rs: &[Matrix3<f64>]| -> Vec<Matrix3<f64>> {
        rs.iter()
            .map(|r| So3::from_matrix_orthonormalized(r).0)
            .collect()
    };
    let (est, gt) = (clean(est), clean(gt));
    let mut angles = Vec::with_capacity(est.len() * (est.len() - 1) / 2);
    for i in 0..est.len() {
        for j in i + 1..est.len() {
            let rel_est = est[i].transpose() * est[j];
            let rel_gt = gt[i].transpose() * gt[j];
            let diff = So3::from_matrix_unchecked(rel_est.transpose() * rel_gt);
            angles.push(diff.log().norm().to_degrees());
        }
    }
    let s = error_stats(&angles)?;
    Ok(RotationErrorSummary {
        rmse_deg: s.rmse,
        mean_deg: s.mean,
        median_deg: s.median,
        max_deg: s.max,
    })
}

/// APE of estimated vs ground-truth camera centres with Sim(3) Umeyama alignment (evo `-as`).
pub fn ape_of_centres(est: &[[f64; 3]], gt: &[[f64; 3]]) -> Result<ApeSummary, EvalError> {
    let (s, _) = ape_translation(est, gt, Alignment::Sim3)?;
    Ok(ApeSummary {
        rmse: s.rmse,
        mean: s.mean,
        median: s.median,
        std: s.std,
        max: s.max,
    })
}

//! Evaluation and export for gems (the protocol behind the GeMS numbers, as in
//! `GopiRajuMatta/PRISM3D:prism3d_trainer.py` `eval_with_pose_opt` and `train.sh`).
//!
//! - [`evaluate_views`]: render views with frozen Gaussians, either at a given pose or after
//!   test-time pose refinement ([`refine::refine_pose`]: one SE(3) correction per view, 100 Adam
//!   steps, lr 1e-3, L1 vs the ground truth), and score them ([`score_image`]: PSNR, SSIM
//!   (torchmetrics), LPIPS-Alex when weights are given — otherwise `None`, never a number).
//! - [`evaluate_output`]: the whole protocol on a trained [`gems_train::TrainOutput`]
//!   (ground truth from the scene folder via [`eval_data_from_scene`]):
//!   `input` (the blurry training images vs sharp GT: where the user started), `deblur`
//!   (training views at their trajectory midpoint vs sharp GT), `deblur_refined` (training views
//!   after refinement from their initial pose, the GeMS authors' figure), `nvs` (held-out views
//!   refined from their reference pose), `nvs_no_pose_opt` (held-out views at their reference
//!   pose: the dataset's own when the scene has poses, as the published tables render, else the
//!   initialisation's; carried into the result's initial frame by the similarity between the
//!   same source's training cameras and the result's, [`HeldOutPosing`], [`HeldOutFrame`];
//!   [`CameraShift`] says how far training moved the cameras from that source's) and APE
//!   ([`ape_of_centres`]: Sim(3) Umeyama of midpoint camera centres to the ground truth, evo's
//!   statistics, in the input frame's units; `ape_init` the same for the initial poses, so the
//!   pair shows what training did to the cameras), and the relative rotation error over every
//!   pair of views (`rotation_error`, `rotation_error_init`; [`relative_rotation_error`],
//!   degrees, no alignment needed), which sees the cameras' orientation that APE's centres do
//!   not. The result serialises to `metrics.json`
//!   ([`MetricsReport`], [`write_metrics_json`]).
//! - [`export`]: the trained cameras out, as a COLMAP model (with the Gaussians' centres as
//!   points) or a nerfstudio `transforms.json` with the sharp renders, in the input frame.
//! - [`flythrough`]: camera paths for a video of the result (the training path smoothed, or
//!   an orbit).
//! - [`tum`]: TUM trajectory files; [`write_trajectories`] writes every view's n virtual poses
//!   plus the midpoints (and ground truth when known), in the input frame.
//! - [`report`]: `report.html` with loss/PSNR curves, a trajectory plot and a
//!   blurry | ours | ground-truth grid, with an EDI column between blurry and ours when the run
//!   used events ([`attach_edi_images`]), and per-row PSNRs (PNG via plotters, no text in the
//!   images) and the interactive WebGL2 view of [`viewer`] (also written alone as `viewer.html`);
//!   its inputs come from [`report_input`].
//!
//! Typical use after training (what `gems train` and `gems eval` do):
//! ```text
//! let data = gems_eval::eval_data_from_scene(&output, &scene)?;
//! let eval = gems_eval::evaluate_output(&output, &data, &PoseRefineConfig::default(), lpips.as_ref())?;
//! gems_eval::write_metrics_json(&dir.join("metrics.json"), &eval.metrics)?;
//! gems_eval::write_trajectories(&dir, &output)?;
//! gems_eval::write_report(&dir, &gems_eval::report_input(&output, &data, &eval, 4))?;
//! ```

pub mod browser;
pub mod export;
pub mod flythrough;
mod metrics;
mod protocol;
pub mod refine;
pub mod report;
pub mod tum;
pub mod viewer;

use std::path::{Path, PathBuf};

pub use metrics::{
    ApeSummary, CameraShift, EvalView, FocalSummary, HeldOutFrame, HeldOutPosing, ImageScore,
    MetricsReport, PoseMode, RotationErrorSummary, SplitResult, SplitScores, ape_of_centres,
    evaluate_views, evaluate_views_with_progress, relative_rotation_error, score_image,
    split_labels,
};
pub use protocol::{
    EvalData, Evaluation, HeldOutView, attach_edi_images, eval_data_from_scene,
    eval_data_from_scene_in, evaluate_output, evaluate_output_on, evaluation_units, open_scene_for,
    render_mid_exposure, report_input, write_renders, write_renders_on, write_trajectories,
};
pub use refine::{PoseRefineConfig, Refined, refine_pose};
pub use report::{GridRow, ReportInput, write_report};

/// Errors of evaluation and export. Every file error names the file.
#[derive(Debug, thiserror::Error)]
pub enum EvalError {
    #[error("I/O error on {path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("file {path}: {reason}")]
    Format { path: PathBuf, reason: String },
    #[error("invalid input: {0}")]
    Input(String),
    #[error("plotting {path}: {reason}")]
    Plot { path: PathBuf, reason: String },
    #[error(transparent)]
    Data(#[from] gems_data::DataError),
    #[error(transparent)]
    Splat(#[from] gems_splat::SplatError),
    /// The splatting engine (CPU or GPU) failed.
    #[error(transparent)]
    Engine(#[from] gems_gpu::GpuError),
    #[error(transparent)]
    Metrics(#[from] gems_metrics::MetricsError),
    #[error(transparent)]
    Lpips(#[from] gems_metrics::LpipsError),
    #[error(transparent)]
    Math(#[from] gems_math::MathError),
    #[error(transparent)]
    Train(#[from] gems_train::TrainError),
}

/// A failed atomic write (gems-fs) is an I/O error on the path it names.
impl From<gems_fs::FsError> for EvalError {
    fn from(e: gems_fs::FsError) -> Self {
        EvalError::Io {
            path: e.path,
            source: e.source,
        }
    }
}

/// Writes `metrics.json` atomically (pretty-printed).
pub fn write_metrics_json(path: &Path, report: &MetricsReport) -> Result<(), EvalError> {
    let text = serde_json::to_string_pretty(report).map_err(|e| EvalError::Format {
        path: path.to_path_buf(),
        reason: e.to_string(),
    })?;
    gems_fs::write_atomic(path, text.as_bytes())?;
    Ok(())
}

/// Reads a `metrics.json`.
pub fn read_metrics_json(path: &Path) -> Result<MetricsReport, EvalError> {
    let text = std::fs::read_to_string(path).map_err(|source| EvalError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    serde_json::from_str(&text).map_err(|e| EvalError::Format {
        path: path.to_path_buf(),
        reason: e.to_string(),
    })
}

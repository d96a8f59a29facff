//! GeMS training: per-image exposure trajectories, the physical blur model, losses, Adam and
//! 3DGS-MCMC densification, jointly optimised.
//!
//! The crate root is the API; the modules behind it are private except [`adam`] and [`mcmc`],
//! the CPU reference that gems-gpu's optimiser kernels are tested against.
//! * [`TrainConfig`]: every constant of the method (TOML, defaults = paper/PRISM3D).
//! * The blur model ([`render_blurred`], [`backward_blurred`] over an [`Exposure`]): n virtual
//!   cameras in one render call, their mean, and the gradient chain to Gaussians and knots.
//! * [`Trainer`]: the joint optimisation loop and its checkpointable [`TrainState`] (on the GPU
//!   engine the Gaussians stay resident on the GPU; `Trainer::sync` downloads them, and
//!   `Trainer::run` syncs at checkpoint steps and at the end).
//! * [`save_checkpoint`] / [`load_checkpoint`] (safetensors + JSON) and [`TrainOutput`], the
//!   trained result that gems-eval consumes.
//! * [`prepare_input`]: scene folder + [`InitMode`] (colmap / gt / gt-noisy) → [`TrainInput`],
//!   with Gaussians from SfM points ([`from_points`], 3-NN scales) or random points in the
//!   camera frustums, and the PRISM3D scene [`Normalization`].
//!
//! Typical use (what `gems train` does):
//! ```ignore
//! let input = gems_train::prepare_input(&scene, &InitMode::Gt, &cfg)?;
//! let mut trainer = Trainer::new(cfg, input)?;
//! trainer.run(|t, report| { /* progress; save_checkpoint(dir, t) periodically */ Ok(()) })?;
//! let output = TrainOutput::from_trainer(&trainer);
//! output.save(dir)?; // model.safetensors + model.json, read back with TrainOutput::load
//! let ply_gaussians = output.normalization.gaussians_to_input_frame(&output.gaussians);
//! ```
//! Resume: `load_checkpoint(dir)` → `Trainer::from_state(cfg, views, …, state)` continues
//! bit-identically (same seed → same result; results do not depend on the thread count; on the
//! GPU engine, on the same adapter and driver).
// The CPU reference of gems-gpu's optimiser kernels (tested against it), hence public.
pub mod adam;
pub(crate) mod blur;
mod checkpoint;
mod config;
mod init;
pub mod mcmc;
mod normalize;
mod output;
mod prepare;
mod tensors;
mod trainer;

pub use blur::{
    BlurWorkspace, Exposure, Rasterizer, accumulate_knot_gradients, backward_blurred,
    backward_view_weights, blur_depths, blur_length_px, exposure_times, render_blurred,
    virtual_c2w, virtual_cameras, virtual_view_count,
};
pub use checkpoint::{
    CHECKPOINT_JSON, CHECKPOINT_TENSORS, has_checkpoint, load_checkpoint, save_checkpoint,
};
pub use config::{
    CoarseToFineConfig, InitConfig, LearningRates, MAX_COARSE_LEVELS, McmcConfig, NormalizeConfig,
    PoseConfig, REFERENCE_STEPS, TopUp, TrainConfig,
};
pub use init::{PointCloud, from_points, random_in_frustums};
pub use normalize::Normalization;
pub use output::{MODEL_JSON, MODEL_TENSORS, RunDescription, TrainOutput, ViewResult};
pub use prepare::{InitMode, prepare_input};
pub use trainer::{
    FocalState, GpuMemory, GpuProfile, History, StepReport, TrainInput, TrainState, TrainView,
    Trainer, trajectory_of,
};

use std::path::{Path, PathBuf};

/// Errors of training, checkpointing and output I/O.
#[derive(Debug, thiserror::Error)]
pub enum TrainError {
    #[error("I/O error on {path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("invalid configuration: {0}")]
    Config(String),
    #[error("invalid input: {0}")]
    Input(String),
    #[error("file {path}: {reason}")]
    Format { path: PathBuf, reason: String },
    #[error(transparent)]
    Splat(#[from] gems_splat::SplatError),
    #[error(transparent)]
    Gpu(#[from] gems_gpu::GpuError),
}

/// A failed atomic write (gems-fs) is an I/O error on the path it names.
impl From<gems_fs::FsError> for TrainError {
    fn from(e: gems_fs::FsError) -> Self {
        TrainError::Io {
            path: e.path,
            source: e.source,
        }
    }
}

impl TrainError {
    pub(crate) fn io(path: &Path, source: std::io::Error) -> Self {
        TrainError::Io {
            path: path.to_path_buf(),
            source,
        }
    }
}

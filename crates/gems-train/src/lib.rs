//! GeMS training: per-image exposure trajectories, the physical blur model, losses, Adam and
//! 3DGS-MCMC densification, jointly optimised.
//!
//! Modules:
//! * [`config`] — [`TrainConfig`]: every constant of the method (TOML, defaults = paper/PRISM3D).
//! * [`adam`] — torch-semantics Adam on flat SoA parameter groups.
//! * [`mcmc`] — gsplat `MCMCStrategy`: relocation, growth, SGLD noise.
//! * [`normalize`] — PRISM3D scene normalisation (orient up, centre, scale) and its inverse.
//! * [`blur`] — the blur model: n virtual cameras in one render call, mean, and the gradient
//!   chain to Gaussians and trajectory knots.
//! * [`trainer`] — [`trainer::Trainer`]: the joint optimisation loop and its checkpointable state
//!   (on the GPU engine the Gaussians stay resident on the GPU; `Trainer::sync` downloads them,
//!   and `Trainer::run` syncs at checkpoint steps and at the end).
//! * [`io`] — atomic files, checkpoints (safetensors + JSON) and [`io::TrainOutput`], the
//!   trained result that gems-eval consumes.
//! * [`prepare`] — scene folder + init mode (colmap / gt / gt-noisy) → [`trainer::TrainInput`].
//! * [`init`] — Gaussians from SfM points (3-NN scales) or random points in the camera frustums.
//!
//! Typical use (what `gems train` does):
//! ```ignore
//! let input = prepare::prepare_input(&scene, &prepare::InitMode::Gt, &cfg)?;
//! let mut trainer = trainer::Trainer::new(cfg, input)?;
//! trainer.run(|t, report| { /* progress; io::save_checkpoint(dir, t) periodically */ Ok(()) })?;
//! let output = io::TrainOutput::from_trainer(&trainer);
//! output.save(dir)?; // model.safetensors + model.json, read back with TrainOutput::load
//! let ply_gaussians = output.normalization.gaussians_to_input_frame(&output.gaussians);
//! ```
//! Resume: `io::load_checkpoint(dir)` → `Trainer::from_state(cfg, views, …, state)` continues
//! bit-identically (same seed → same result; results do not depend on the thread count; on the
//! GPU engine, on the same adapter and driver).
pub mod adam;
pub mod blur;
pub mod config;
pub mod init;
pub mod io;
pub mod mcmc;
pub mod normalize;
pub mod prepare;
pub mod trainer;

pub use config::TrainConfig;

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

impl TrainError {
    pub(crate) fn io(path: &Path, source: std::io::Error) -> Self {
        TrainError::Io {
            path: path.to_path_buf(),
            source,
        }
    }
}

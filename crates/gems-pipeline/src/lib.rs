//! A whole gems run put together, for the `gems` command line and for library users alike.
//!
//! The flow, one step per function:
//! 1. **initialisation** ([`resolve_init`]): where poses and points come from — the built-in
//!    blur-robust SfM on the blurry images ([`run_sfm`]), a COLMAP model the scene carries or a
//!    user gives, a user-installed COLMAP run as a subprocess ([`run_colmap`]), the scene's events
//!    deblurring the images by EDI for either initialiser ([`edi_images`], GeMS-E), or ground
//!    truth (optionally perturbed); with `init.sfm_rerun_fraction` > 0, a first training from
//!    that model whose sharp renders the image initialiser reconstructs again
//!    ([`rerun_init_on_renders`]), the run proper starting from the second model unless it
//!    confirms the first one — its cameras within `init.sfm_rerun_confirm_pct` of their extent
//!    of the first model's, the change not mostly a smooth bend of the path
//!    (`init.sfm_rerun_confirm_max_systematic`; [`probe::renders_change`],
//!    [`probe::confirms_first_model`]) — and,
//!    with
//!    `init.sfm_rerun_probe_fraction` > 0, when a short probe of each fits the blurry photos
//!    better from it ([`probe`]); trainings
//!    from accurate poses (that second model, the first one when the renders' model confirmed
//!    it, or ground truth) take
//!    `init.accurate_poses_straight_fraction` as their `pose.straight_fraction`, and the run
//!    proper from a confirmed first model holds its cameras (`init.confirmed_hold_midpoint`)
//!    and, with `init.confirmed_dense_points`, starts from dense points fused from the first
//!    pass's depth maps ([`dense`]); with `init.renders_dense_points` the run proper from the
//!    renders' model does too, attached to that model's cameras.
//!    An imported COLMAP model gets the same first pass, and the built-in SfM on its renders
//!    only measures it ([`checked_on_renders`]), with a bound of its own
//!    (`init.sfm_rerun_confirm_imported_pct`): confirmed, the model's cameras are held;
//!    otherwise it is trained from as it is, never replaced;
//! 2. **training** (gems-train), with periodic atomic checkpoints and resume;
//! 3. **exports**: `point_cloud.ply` (input frame), `model.json`, `config.toml`;
//! 4. **evaluation and report** (gems-eval): `metrics.json`, trajectories, renders,
//!    `report.html`.
//!
//! [`train_scene`] runs all four from a [`TrainRequest`]; [`train_and_report`] runs 2–4 from an
//! already resolved [`InitMode`].
//!
//! Logs go through `tracing`: what each stage does and its figures at INFO, per-item detail
//! (each training report, each evaluated view) at DEBUG. Progress bars (indicatif, on stderr,
//! one [`progress`] group a log writer can lift out of the way) are drawn only when the request
//! asks for them (`progress: true`, what the command line does); a library user leaves them off
//! and reads the step reports from the DEBUG logs.

pub mod dense;
mod error;
mod init;
pub mod probe;
pub mod progress;
mod protocol;
mod run;

pub use error::PipelineError;
pub use gems_train::InitMode;
pub use init::{
    EventInit, Init, InitRequest, checked_on_renders, edi_images, rerun_init_on_renders,
    reruns_on_renders, resolve_init, run_colmap, run_sfm, video_frames,
};
pub use protocol::{Headline, Protocol, ProtocolSettings};
pub use run::{
    GPU_PROFILE, RunOutcome, TrainJob, TrainRequest, attach_edi, describe_run, train_and_report,
    train_scene,
};

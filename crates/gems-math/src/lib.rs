//! SE(3)/SO(3)/Sim(3) maths and camera trajectories for gems (all f64: poses are few).
//!
//! Conventions: the camera frame is OpenCV (x right, y down, z forward). Tangent vectors of se(3)
//! are ordered translation first, then rotation: ξ = [ρ; φ]. Quaternions are (w, x, y, z).
//!
//! - [`Pose`], [`Intrinsics`] ([`camera`]): the one camera vocabulary of gems — a rigid transform
//!   in plain arrays (what files store; scenes hold world-to-camera) and f64 pinhole intrinsics.
//! - [`So3`], [`Se3`]: compose (`*`), inverse, act on points, `exp`/`log`, adjoint; left/right
//!   Jacobians and their inverses ([`so3_left_jacobian`], [`se3_right_jacobian`], …), with Taylor
//!   branches near zero. Left: Exp(ξ+dξ) ≈ Exp(𝒥_l dξ)·Exp(ξ); right: Exp(ξ+dξ) ≈ Exp(ξ)·Exp(𝒥_r dξ).
//! - Conversions ([`convert`]): quaternion ↔ rotation, axis-angle, [`look_at_c2w`], w2c ↔ c2w,
//!   camera centre, and [`Se3::to_f32_arrays`]/[`Se3::from_f32_arrays`] (row-major f32 rotation
//!   + translation, the renderer's world-to-camera layout).
//! - [`Trajectory`]: exposure trajectories Δ(u), u ∈ [0, 1] (Bézier, linear, cubic B-spline) with
//!   knot Jacobians of the right perturbation; the virtual camera is c2w(u) = c2w_init·Δ(u);
//!   the gauge energies and [`straighten_knots`] act on the knots.
//! - [`posegrad`]: renderer gradients dL/dR, dL/dt of world-to-camera → Lie gradients.
//!   Training chain for knot j of a view rendered at u:
//!   `g = c2w_right_perturbation_gradient(&w2c_u, &dl_dr, &dl_dt)` then
//!   `traj.accumulate_knot_gradients(u, &g, &mut knot_grads)`.
//! - [`align`]: Umeyama Sim(3)/SE(3) alignment and evo's APE translation statistics.

pub mod align;
pub mod camera;
pub mod convert;
pub mod posegrad;
pub mod se3;
pub mod so3;
pub mod trajectory;

pub use align::{
    Alignment, ApeStats, CameraDiscrepancy, Sim3, ape_translation, camera_discrepancy,
    camera_similarity, error_stats, umeyama,
};
pub use camera::{Intrinsics, Pose, rotation_error};
pub use convert::{
    axis_angle_to_rotation, c2w_to_w2c, camera_center_from_w2c, look_at_c2w, quat_wxyz_to_rotation,
    rotation_to_axis_angle, rotation_to_quat_wxyz, w2c_to_c2w,
};
pub use nalgebra::{Matrix3, Matrix6, Vector3, Vector6};
pub use posegrad::{c2w_right_perturbation_gradient, w2c_left_perturbation_gradient};
pub use se3::{
    Se3, join_tangent, se3_left_jacobian, se3_left_jacobian_inv, se3_right_jacobian,
    se3_right_jacobian_inv, split_tangent,
};
pub use so3::{
    So3, hat, so3_left_jacobian, so3_left_jacobian_inv, so3_right_jacobian, so3_right_jacobian_inv,
    vee,
};
pub use trajectory::{
    BEZIER_DEFAULT_KNOTS, Jacobian6, PathCentre, Trajectory, TrajectoryKind, anchor_energy,
    bernstein, hold_midpoint, midpoint_tangent_gradient, off_centre_energy, straighten_knots,
    uneven_speed_energy,
};

/// Errors of the maths layer (bad sizes or degenerate geometry; never a panic on user data).
#[derive(Debug, thiserror::Error)]
pub enum MathError {
    #[error("{kind:?} trajectory needs {expected} knot(s), got {got}")]
    KnotCount {
        kind: TrajectoryKind,
        expected: usize,
        got: usize,
    },
    #[error("estimate has {est} poses but the reference has {reference}")]
    LengthMismatch { est: usize, reference: usize },
    #[error("degenerate alignment: {0}")]
    Degenerate(String),
}

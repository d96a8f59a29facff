//! The bridge from the renderer's Euclidean pose gradients to Lie-algebra gradients.
//!
//! The renderer's camera is world-to-camera (R, t) and it returns dL/dR (3×3) and dL/dt. For a
//! LEFT perturbation ε = [ρ; φ] of world-to-camera, w2c ← Exp(ε)·w2c, to first order
//! R ← (I + \[φ\]×) R and t ← (I + \[φ\]×) t + ρ, so
//!   dL/dρ = dL/dt,   dL/dφ = vee-gradient of A = (dL/dR) Rᵀ + (dL/dt) tᵀ,
//! where ⟨A, \[φ\]×⟩ = φ · (A₃₂ − A₂₃, A₁₃ − A₃₁, A₂₁ − A₁₂).
//!
//! For a RIGHT perturbation δ of camera-to-world, c2w ← c2w·Exp(δ) ⇔ w2c ← Exp(−δ)·w2c, so
//! dL/dδ = −dL/dε ([`c2w_right_perturbation_gradient`]). That is the quantity to feed to
//! [`crate::Trajectory::accumulate_knot_gradients`]: for a virtual camera c2w(u) = c2w_init·Δ(u),
//! the right perturbation of c2w(u) is the right perturbation of Δ(u).

use nalgebra::{Matrix3, Vector3};

use crate::se3::Se3;

/// Gradient w.r.t. ε for w2c ← Exp(ε)·w2c, ordered [ρ; φ]. `grad_rot` is row-major dL/dR.
pub fn w2c_left_perturbation_gradient(
    w2c: &Se3,
    grad_rot: &[[f64; 3]; 3],
    grad_trans: &[f64; 3],
) -> [f64; 6] {
    let gr = Matrix3::from_fn(|i, j| grad_rot[i][j]);
    let gt = Vector3::from(*grad_trans);
    let a = gr * w2c.rot.transpose() + gt * w2c.trans.transpose();
    [
        gt.x,
        gt.y,
        gt.z,
        a[(2, 1)] - a[(1, 2)],
        a[(0, 2)] - a[(2, 0)],
        a[(1, 0)] - a[(0, 1)],
    ]
}

/// Gradient w.r.t. δ for c2w ← c2w·Exp(δ), given the world-to-camera pose and the renderer's
/// gradients w.r.t. its (R, t): the negation of [`w2c_left_perturbation_gradient`].
pub fn c2w_right_perturbation_gradient(
    w2c: &Se3,
    grad_rot: &[[f64; 3]; 3],
    grad_trans: &[f64; 3],
) -> [f64; 6] {
    w2c_left_perturbation_gradient(w2c, grad_rot, grad_trans).map(|g| -g)
}

//! SO(3): rotation matrices, exponential/logarithm and their Jacobians.

use nalgebra::{Matrix3, Vector3};

/// Below this angle sin(x)/x uses its Taylor polynomial (the omitted term is < 1e-18 relative).
pub(crate) const SMALL_ANGLE: f64 = 1e-4;

/// Skew-symmetric matrix `[v]×` such that `[v]× w = v × w`.
pub fn hat(v: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -v.z, v.y, v.z, 0.0, -v.x, -v.y, v.x, 0.0)
}

/// Inverse of [`hat`] for the antisymmetric part of `m`: `vee([v]×) = v`.
pub fn vee(m: &Matrix3<f64>) -> Vector3<f64> {
    Vector3::new(
        0.5 * (m[(2, 1)] - m[(1, 2)]),
        0.5 * (m[(0, 2)] - m[(2, 0)]),
        0.5 * (m[(1, 0)] - m[(0, 1)]),
    )
}

/// Below this angle the higher-order Jacobian coefficients, whose closed forms cancel
/// catastrophically (relative error ~ε/θ⁴), are evaluated by their power series instead. Six series
/// terms leave a truncation error under 1e-16 there.
pub(crate) const SERIES_ANGLE: f64 = 0.5;

/// Σ_k (−1)^k θ^{2k} / (2k + offset)!, k = 0..6: the series of (θ − sin θ)/θ³ (offset 3) and
/// (θ² + 2cos θ − 2)/(2θ⁴) (offset 4).
pub(crate) fn alt_factorial_series(t2: f64, offset: u32) -> f64 {
    let mut fact: f64 = (1..=offset).map(f64::from).product();
    let (mut sum, mut pow, mut sign) = (0.0, 1.0, 1.0);
    for k in 0..6u32 {
        if k > 0 {
            let n = 2 * k + offset;
            fact *= f64::from(n - 1) * f64::from(n);
        }
        sum += sign * pow / fact;
        pow *= t2;
        sign = -sign;
    }
    sum
}

/// sin(θ)/θ, (1−cos θ)/θ², (θ−sin θ)/θ³ — the Rodrigues / Jacobian coefficients, stable at θ → 0.
pub(crate) fn rodrigues_coeffs(theta: f64) -> (f64, f64, f64) {
    let t2 = theta * theta;
    let sinc = |x: f64| {
        if x < SMALL_ANGLE {
            1.0 - x * x / 6.0
        } else {
            x.sin() / x
        }
    };
    // 1 − cos θ = 2 sin²(θ/2) avoids the cancellation of the direct form.
    let half = sinc(0.5 * theta);
    let c = if theta < SERIES_ANGLE {
        alt_factorial_series(t2, 3)
    } else {
        (theta - theta.sin()) / (t2 * theta)
    };
    (sinc(theta), 0.5 * half * half, c)
}

/// A rotation matrix (orthonormal, det +1).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct So3(pub Matrix3<f64>);

impl Default for So3 {
    fn default() -> Self {
        Self::identity()
    }
}

impl So3 {
    pub fn identity() -> Self {
        So3(Matrix3::identity())
    }

    /// Wraps a matrix that the caller guarantees is a rotation.
    pub fn from_matrix_unchecked(m: Matrix3<f64>) -> Self {
        So3(m)
    }

    /// Nearest rotation to an arbitrary 3×3 matrix (polar decomposition via SVD), for matrices that
    /// drifted from orthonormality (f32 round trips, file inputs).
    pub fn from_matrix_orthonormalized(m: &Matrix3<f64>) -> Self {
        let svd = m.svd(true, true);
        let (u, vt) = (
            svd.u.expect("U was requested"),
            svd.v_t.expect("Vᵀ was requested"),
        );
        let mut d = Matrix3::identity();
        if (u * vt).determinant() < 0.0 {
            d[(2, 2)] = -1.0;
        }
        So3(u * d * vt)
    }

    pub fn matrix(&self) -> &Matrix3<f64> {
        &self.0
    }

    /// Exp: axis-angle vector φ (angle = |φ|) to rotation (Rodrigues).
    pub fn exp(phi: &Vector3<f64>) -> Self {
        let theta = phi.norm();
        let (a, b, _) = rodrigues_coeffs(theta);
        let k = hat(phi);
        So3(Matrix3::identity() + k * a + k * k * b)
    }

    /// Log: rotation to axis-angle φ with |φ| ∈ [0, π]. Goes through the unit quaternion, which is
    /// well conditioned everywhere including θ ≈ 0 and θ ≈ π.
    pub fn log(&self) -> Vector3<f64> {
        let q = crate::convert::rotation_to_quat_wxyz(&self.0);
        crate::convert::quat_wxyz_log(q)
    }

    pub fn inverse(&self) -> Self {
        So3(self.0.transpose())
    }

    pub fn act(&self, p: &Vector3<f64>) -> Vector3<f64> {
        self.0 * p
    }
}

impl std::ops::Mul for So3 {
    type Output = So3;
    fn mul(self, rhs: So3) -> So3 {
        So3(self.0 * rhs.0)
    }
}

/// Left Jacobian of SO(3): Exp(φ + dφ) ≈ Exp(J_l(φ) dφ) · Exp(φ).
pub fn so3_left_jacobian(phi: &Vector3<f64>) -> Matrix3<f64> {
    let (_, b, c) = rodrigues_coeffs(phi.norm());
    let k = hat(phi);
    Matrix3::identity() + k * b + k * k * c
}

/// Right Jacobian of SO(3): Exp(φ + dφ) ≈ Exp(φ) · Exp(J_r(φ) dφ); J_r(φ) = J_l(−φ).
pub fn so3_right_jacobian(phi: &Vector3<f64>) -> Matrix3<f64> {
    so3_left_jacobian(&-phi)
}

/// Coefficient of [φ]² in J_l⁻¹: 1/θ² − (1 + cos θ)/(2 θ sin θ).
fn inv_jac_coeff(theta: f64) -> f64 {
    // Series of 1/θ² − cot(θ/2)/(2θ); below 0.1 the closed form loses ~1e-13 relative and the
    // truncation error of five terms is far below that.
    if theta < 0.1 {
        let t2 = theta * theta;
        1.0 / 12.0
            + t2 * (1.0 / 720.0 + t2 * (1.0 / 30240.0 + t2 * (1.0 / 1209600.0 + t2 / 47900160.0)))
    } else {
        let (s, c) = theta.sin_cos();
        1.0 / (theta * theta) - (1.0 + c) / (2.0 * theta * s)
    }
}

/// Inverse of [`so3_left_jacobian`] (singular at |φ| = 2π, fine on the principal branch |φ| ≤ π).
pub fn so3_left_jacobian_inv(phi: &Vector3<f64>) -> Matrix3<f64> {
    let k = hat(phi);
    Matrix3::identity() - k * 0.5 + k * k * inv_jac_coeff(phi.norm())
}

/// Inverse of [`so3_right_jacobian`].
pub fn so3_right_jacobian_inv(phi: &Vector3<f64>) -> Matrix3<f64> {
    so3_left_jacobian_inv(&-phi)
}

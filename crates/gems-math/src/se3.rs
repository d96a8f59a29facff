//! SE(3): rigid transforms, exponential/logarithm (tangent ordered [ρ; φ]) and their Jacobians.

use nalgebra::{Matrix3, Matrix6, Vector3, Vector6};

use crate::so3::{
    SERIES_ANGLE, So3, alt_factorial_series, hat, so3_left_jacobian, so3_left_jacobian_inv,
};

/// A rigid transform p ↦ R p + t.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Se3 {
    pub rot: Matrix3<f64>,
    pub trans: Vector3<f64>,
}

impl Default for Se3 {
    fn default() -> Self {
        Self::identity()
    }
}

/// Splits a tangent vector into its translation part ρ and rotation part φ.
pub fn split_tangent(xi: &Vector6<f64>) -> (Vector3<f64>, Vector3<f64>) {
    (xi.fixed_rows::<3>(0).into(), xi.fixed_rows::<3>(3).into())
}

/// Joins ρ (translation part, first) and φ (rotation part, second) into a tangent vector.
pub fn join_tangent(rho: &Vector3<f64>, phi: &Vector3<f64>) -> Vector6<f64> {
    Vector6::new(rho.x, rho.y, rho.z, phi.x, phi.y, phi.z)
}

impl Se3 {
    pub fn identity() -> Self {
        Se3 {
            rot: Matrix3::identity(),
            trans: Vector3::zeros(),
        }
    }

    pub fn new(rot: Matrix3<f64>, trans: Vector3<f64>) -> Self {
        Se3 { rot, trans }
    }

    pub fn rotation(&self) -> So3 {
        So3(self.rot)
    }

    pub fn inverse(&self) -> Self {
        let rt = self.rot.transpose();
        Se3 {
            rot: rt,
            trans: -(rt * self.trans),
        }
    }

    /// `self · other` (apply `other` first).
    pub fn compose(&self, other: &Se3) -> Se3 {
        Se3 {
            rot: self.rot * other.rot,
            trans: self.rot * other.trans + self.trans,
        }
    }

    pub fn act(&self, p: &Vector3<f64>) -> Vector3<f64> {
        self.rot * p + self.trans
    }

    /// Exp of ξ = [ρ; φ]: rotation Exp(φ), translation J_l(φ) ρ.
    pub fn exp(xi: &Vector6<f64>) -> Self {
        let (rho, phi) = split_tangent(xi);
        Se3 {
            rot: So3::exp(&phi).0,
            trans: so3_left_jacobian(&phi) * rho,
        }
    }

    /// Log, the inverse of [`Se3::exp`] on the principal branch (|φ| ≤ π).
    pub fn log(&self) -> Vector6<f64> {
        let phi = So3(self.rot).log();
        let rho = so3_left_jacobian_inv(&phi) * self.trans;
        join_tangent(&rho, &phi)
    }

    /// Adjoint: T · Exp(δ) = Exp(Ad_T δ) · T. Ad_T = [[R, \[t\]×R], [0, R]] for [ρ; φ] ordering.
    pub fn adjoint(&self) -> Matrix6<f64> {
        let mut m = Matrix6::zeros();
        m.fixed_view_mut::<3, 3>(0, 0).copy_from(&self.rot);
        m.fixed_view_mut::<3, 3>(3, 3).copy_from(&self.rot);
        m.fixed_view_mut::<3, 3>(0, 3)
            .copy_from(&(hat(&self.trans) * self.rot));
        m
    }
}

impl std::ops::Mul for Se3 {
    type Output = Se3;
    fn mul(self, rhs: Se3) -> Se3 {
        self.compose(&rhs)
    }
}

impl std::ops::Mul<&Se3> for &Se3 {
    type Output = Se3;
    fn mul(self, rhs: &Se3) -> Se3 {
        self.compose(rhs)
    }
}

/// The coupling block Q(ρ, φ) of the SE(3) left Jacobian (Barfoot, "State Estimation for
/// Robotics", eq. 7.86), with power-series coefficients below [`SERIES_ANGLE`].
fn se3_q(rho: &Vector3<f64>, phi: &Vector3<f64>) -> Matrix3<f64> {
    let theta = phi.norm();
    let t2 = theta * theta;
    let (c1, c2, c3) = if theta < SERIES_ANGLE {
        // c3 = Σ_{n≥2} (−1)^n (n−1) θ^{2n−4} / (2n+1)!.
        let (mut c3, mut pow, mut fact, mut sign) = (0.0, 1.0, 120.0, 1.0);
        for n in 2..8u32 {
            if n > 2 {
                fact *= f64::from(2 * n) * f64::from(2 * n + 1);
            }
            c3 += sign * f64::from(n - 1) * pow / fact;
            pow *= t2;
            sign = -sign;
        }
        (alt_factorial_series(t2, 3), alt_factorial_series(t2, 4), c3)
    } else {
        let (s, c) = theta.sin_cos();
        let t4 = t2 * t2;
        (
            (theta - s) / (t2 * theta),
            (t2 + 2.0 * c - 2.0) / (2.0 * t4),
            (2.0 * theta - 3.0 * s + theta * c) / (2.0 * t4 * theta),
        )
    };
    let p = hat(phi);
    let r = hat(rho);
    let pr = p * r;
    let rp = r * p;
    let prp = pr * p;
    r * 0.5 + (pr + rp + prp) * c1 + (p * pr + rp * p - prp * 3.0) * c2 + (prp * p + p * prp) * c3
}

/// Left Jacobian of SE(3): Exp(ξ + dξ) ≈ Exp(𝒥_l(ξ) dξ) · Exp(ξ).
pub fn se3_left_jacobian(xi: &Vector6<f64>) -> Matrix6<f64> {
    let (rho, phi) = split_tangent(xi);
    let j = so3_left_jacobian(&phi);
    let mut m = Matrix6::zeros();
    m.fixed_view_mut::<3, 3>(0, 0).copy_from(&j);
    m.fixed_view_mut::<3, 3>(3, 3).copy_from(&j);
    m.fixed_view_mut::<3, 3>(0, 3).copy_from(&se3_q(&rho, &phi));
    m
}

/// Right Jacobian of SE(3): Exp(ξ + dξ) ≈ Exp(ξ) · Exp(𝒥_r(ξ) dξ); 𝒥_r(ξ) = 𝒥_l(−ξ).
pub fn se3_right_jacobian(xi: &Vector6<f64>) -> Matrix6<f64> {
    se3_left_jacobian(&-xi)
}

/// Inverse of [`se3_left_jacobian`]: [[J⁻¹, −J⁻¹ Q J⁻¹], [0, J⁻¹]].
pub fn se3_left_jacobian_inv(xi: &Vector6<f64>) -> Matrix6<f64> {
    let (rho, phi) = split_tangent(xi);
    let ji = so3_left_jacobian_inv(&phi);
    let q = se3_q(&rho, &phi);
    let mut m = Matrix6::zeros();
    m.fixed_view_mut::<3, 3>(0, 0).copy_from(&ji);
    m.fixed_view_mut::<3, 3>(3, 3).copy_from(&ji);
    m.fixed_view_mut::<3, 3>(0, 3).copy_from(&(-(ji * q * ji)));
    m
}

/// Inverse of [`se3_right_jacobian`].
pub fn se3_right_jacobian_inv(xi: &Vector6<f64>) -> Matrix6<f64> {
    se3_left_jacobian_inv(&-xi)
}

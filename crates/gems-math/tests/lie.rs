//! SO(3)/SE(3) exp/log, Jacobians (vs central finite differences) and conversions.

use gems_math::*;
use proptest::prelude::*;

fn v3(a: [f64; 3]) -> Vector3<f64> {
    Vector3::from(a)
}

fn v6(a: [f64; 6]) -> Vector6<f64> {
    Vector6::from(a)
}

fn max_abs_diff3(a: &Matrix3<f64>, b: &Matrix3<f64>) -> f64 {
    (a - b).abs().max()
}

/// Right-perturbation difference: Log(A⁻¹ B).
fn se3_right_diff(a: &Se3, b: &Se3) -> Vector6<f64> {
    (a.inverse() * *b).log()
}

fn se3_left_diff(a: &Se3, b: &Se3) -> Vector6<f64> {
    (*b * a.inverse()).log()
}

/// Central FD of ξ ↦ diff(Exp(ξ), Exp(ξ + h e_c)), one column per c.
fn fd_se3_jac(xi: &Vector6<f64>, left: bool) -> Matrix6<f64> {
    let h = 1e-6;
    let base = Se3::exp(xi);
    let diff = |b: &Se3| {
        if left {
            se3_left_diff(&base, b)
        } else {
            se3_right_diff(&base, b)
        }
    };
    let mut m = Matrix6::zeros();
    for c in 0..6 {
        let mut p = *xi;
        p[c] += h;
        let mut q = *xi;
        q[c] -= h;
        let col = (diff(&Se3::exp(&p)) - diff(&Se3::exp(&q))) / (2.0 * h);
        m.set_column(c, &col);
    }
    m
}

fn fd_so3_jac(phi: &Vector3<f64>, left: bool) -> Matrix3<f64> {
    let h = 1e-6;
    let base = So3::exp(phi);
    let diff = |b: &So3| {
        if left {
            (*b * base.inverse()).log()
        } else {
            (base.inverse() * *b).log()
        }
    };
    let mut m = Matrix3::zeros();
    for c in 0..3 {
        let mut p = *phi;
        p[c] += h;
        let mut q = *phi;
        q[c] -= h;
        m.set_column(
            c,
            &((diff(&So3::exp(&p)) - diff(&So3::exp(&q))) / (2.0 * h)),
        );
    }
    m
}

fn sample_tangents() -> Vec<Vector6<f64>> {
    vec![
        v6([0.0; 6]),
        v6([1e-9, -2e-9, 3e-9, 1e-9, 2e-9, -1e-9]),
        v6([0.3, -0.2, 0.5, 1e-6, -2e-6, 5e-7]),
        v6([0.3, -0.2, 0.5, 5e-5, -3e-5, 8e-5]), // just inside the Taylor branch
        v6([0.3, -0.2, 0.5, 2e-4, -1e-4, 1e-4]), // just outside it
        v6([1.0, 2.0, -0.5, 0.4, -0.3, 0.9]),
        v6([-0.7, 0.1, 0.2, 2.0, 1.0, -1.5]),
    ]
}

#[test]
fn se3_jacobians_match_finite_differences() {
    for xi in sample_tangents() {
        let jl = se3_left_jacobian(&xi);
        let jr = se3_right_jacobian(&xi);
        let err_l = (jl - fd_se3_jac(&xi, true)).abs().max();
        let err_r = (jr - fd_se3_jac(&xi, false)).abs().max();
        assert!(err_l < 1e-7, "left SE(3) Jacobian at {xi:?}: err {err_l}");
        assert!(err_r < 1e-7, "right SE(3) Jacobian at {xi:?}: err {err_r}");
        let il = (se3_left_jacobian_inv(&xi) * jl - Matrix6::identity())
            .abs()
            .max();
        let ir = (se3_right_jacobian_inv(&xi) * jr - Matrix6::identity())
            .abs()
            .max();
        assert!(
            il < 1e-12 && ir < 1e-12,
            "inverse Jacobians at {xi:?}: {il} {ir}"
        );
    }
}

#[test]
fn so3_jacobians_match_finite_differences() {
    for xi in sample_tangents() {
        let phi = split_tangent(&xi).1;
        let jl = so3_left_jacobian(&phi);
        let jr = so3_right_jacobian(&phi);
        assert!(
            (jl - fd_so3_jac(&phi, true)).abs().max() < 1e-7,
            "left SO(3) at {phi:?}"
        );
        assert!(
            (jr - fd_so3_jac(&phi, false)).abs().max() < 1e-7,
            "right SO(3) at {phi:?}"
        );
        assert!(
            (so3_left_jacobian_inv(&phi) * jl - Matrix3::identity())
                .abs()
                .max()
                < 1e-12
        );
        assert!(
            (so3_right_jacobian_inv(&phi) * jr - Matrix3::identity())
                .abs()
                .max()
                < 1e-12
        );
    }
}

#[test]
fn series_branches_are_continuous() {
    // Values just below and above every switch angle must agree to ~machine precision.
    for switch in [1e-4, 0.1, 0.5] {
        for axis in [v3([1.0, 0.0, 0.0]), v3([0.3, -0.5, 0.8]).normalize()] {
            let lo = axis * (switch * (1.0 - 1e-14));
            let hi = axis * (switch * (1.0 + 1e-14));
            let rho = v3([0.4, -1.0, 2.0]);
            let pairs = [
                (
                    se3_left_jacobian(&join_tangent(&rho, &lo)),
                    se3_left_jacobian(&join_tangent(&rho, &hi)),
                ),
                (
                    se3_left_jacobian_inv(&join_tangent(&rho, &lo)),
                    se3_left_jacobian_inv(&join_tangent(&rho, &hi)),
                ),
            ];
            for (a, b) in pairs {
                assert!(
                    (a - b).abs().max() < 1e-12,
                    "switch {switch}: {}",
                    (a - b).abs().max()
                );
            }
            assert!((So3::exp(&lo).0 - So3::exp(&hi).0).abs().max() < 1e-13);
        }
    }
}

#[test]
fn log_near_pi_and_identity() {
    for angle in [
        std::f64::consts::PI,
        std::f64::consts::PI - 1e-9,
        1e-12,
        0.0,
    ] {
        let axis = v3([0.2, -0.9, 0.4]).normalize();
        let r = So3::exp(&(axis * angle));
        let phi = r.log();
        assert!(
            max_abs_diff3(&So3::exp(&phi).0, &r.0) < 1e-12,
            "angle {angle}"
        );
        assert!(
            (phi.norm() - angle).abs() < 1e-8,
            "angle {angle}: got {}",
            phi.norm()
        );
    }
}

#[test]
fn adjoint_moves_perturbation_across() {
    let t = Se3::exp(&v6([0.5, -1.0, 0.2, 0.3, 0.8, -0.4]));
    let d = v6([0.1, 0.2, -0.3, -0.2, 0.1, 0.05]);
    let lhs = t * Se3::exp(&d);
    let rhs = Se3::exp(&(t.adjoint() * d)) * t;
    assert!(max_abs_diff3(&lhs.rot, &rhs.rot) < 1e-12 && (lhs.trans - rhs.trans).norm() < 1e-12);
}

#[test]
fn quaternion_conventions() {
    // 90° about z: q = (cos 45°, 0, 0, sin 45°), x ↦ y.
    let r = axis_angle_to_rotation(&Vector3::z(), std::f64::consts::FRAC_PI_2);
    let q = rotation_to_quat_wxyz(&r.0);
    let h = std::f64::consts::FRAC_1_SQRT_2;
    for (a, b) in q.iter().zip([h, 0.0, 0.0, h]) {
        assert!((a - b).abs() < 1e-12, "{q:?}");
    }
    assert!((r.act(&Vector3::x()) - Vector3::y()).norm() < 1e-12);
    let (axis, angle) = rotation_to_axis_angle(&r);
    assert!(
        (axis - Vector3::z()).norm() < 1e-12 && (angle - std::f64::consts::FRAC_PI_2).abs() < 1e-12
    );
}

#[test]
fn look_at_is_opencv() {
    let eye = v3([1.0, 2.0, 3.0]);
    let target = v3([4.0, 2.0, 3.0]);
    let up = v3([0.0, 0.0, 1.0]);
    let c2w = look_at_c2w(&eye, &target, &up).unwrap();
    let w2c = c2w_to_w2c(&c2w);
    // The target lies on the optical axis, in front.
    let pc = w2c.act(&target);
    assert!(pc.x.abs() < 1e-12 && pc.y.abs() < 1e-12 && (pc.z - 3.0).abs() < 1e-12);
    // A point above the target (world up) appears at negative y (image up), on the same column.
    let above = w2c.act(&(target + up));
    assert!(above.y < -0.9 && above.x.abs() < 1e-12);
    // Right-handed camera with det +1.
    assert!((c2w.rot.determinant() - 1.0).abs() < 1e-12);
    assert!((camera_center_from_w2c(&w2c) - eye).norm() < 1e-12);
    assert!((w2c_to_c2w(&w2c).trans - eye).norm() < 1e-12);
    assert!(look_at_c2w(&eye, &(eye + up), &up).is_none());
}

#[test]
fn f32_round_trip() {
    let t = Se3::exp(&v6([0.5, -1.0, 0.2, 0.3, 0.8, -0.4]));
    let (r, tr) = t.to_f32_arrays();
    assert_eq!(r[0][1], t.rot[(0, 1)] as f32, "row-major");
    let back = Se3::from_f32_arrays(&r, &tr);
    assert!(max_abs_diff3(&back.rot, &t.rot) < 1e-6 && (back.trans - t.trans).norm() < 1e-6);
    assert!(
        (back.rot.transpose() * back.rot - Matrix3::identity())
            .abs()
            .max()
            < 1e-14
    );
    let (r64, t64) = t.to_arrays();
    assert_eq!(Se3::from_arrays(&r64, &t64), t);
    let (tq, q) = t.to_translation_quat_wxyz();
    let back = Se3::from_translation_quat_wxyz(tq, q);
    assert!(max_abs_diff3(&back.rot, &t.rot) < 1e-12);
}

fn tangent() -> impl Strategy<Value = Vector6<f64>> {
    // Rotation angle kept below π (the principal branch), with many tiny cases.
    (
        prop::array::uniform3(-3.0f64..3.0),
        prop::array::uniform3(-1.0f64..1.0),
        prop::sample::select(vec![1e-9, 1e-5, 1e-3, 0.5, 1.0, 1.7]),
    )
        .prop_map(|(rho, dir, mag)| {
            let phi = v3(dir) * mag;
            join_tangent(&v3(rho), &phi)
        })
}

proptest! {
    #[test]
    fn se3_exp_log_round_trip(xi in tangent()) {
        let t = Se3::exp(&xi);
        let back = Se3::exp(&t.log());
        prop_assert!(max_abs_diff3(&back.rot, &t.rot) < 1e-12);
        prop_assert!((back.trans - t.trans).norm() < 1e-11);
        prop_assert!((t.log() - xi).norm() < 1e-10);
    }

    #[test]
    fn quaternion_round_trip(xi in tangent()) {
        let r = Se3::exp(&xi).rot;
        let q = rotation_to_quat_wxyz(&r);
        prop_assert!(q[0] >= 0.0);
        prop_assert!(max_abs_diff3(&quat_wxyz_to_rotation(q), &r) < 1e-12);
    }

    #[test]
    fn inverse_and_compose(a in tangent(), b in tangent(), p in prop::array::uniform3(-5.0f64..5.0)) {
        let (ta, tb) = (Se3::exp(&a), Se3::exp(&b));
        let p = v3(p);
        prop_assert!(((ta * tb).act(&p) - ta.act(&tb.act(&p))).norm() < 1e-11);
        prop_assert!((ta.inverse().act(&ta.act(&p)) - p).norm() < 1e-11);
    }
}

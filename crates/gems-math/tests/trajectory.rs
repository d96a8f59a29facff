//! Exposure trajectories: endpoint/constant properties, knot Jacobians vs central finite
//! differences, the pose-gradient bridge and the whole render-gradient → knot-gradient chain.

use gems_math::*;

fn knots(n: usize, scale: f64) -> Vec<[f64; 6]> {
    (0..n)
        .map(|j| {
            let s = scale * (1.0 + 0.37 * j as f64);
            let a = j as f64 * 0.9;
            [
                s * a.cos(),
                -0.5 * s,
                0.3 * s * a.sin(),
                0.2 * s,
                -s * (a * 0.5).cos(),
                0.7 * s,
            ]
        })
        .collect()
}

fn close(a: &Se3, b: &Se3, tol: f64) -> bool {
    (a.rot - b.rot).abs().max() < tol && (a.trans - b.trans).norm() < tol
}

fn all_kinds() -> [TrajectoryKind; 3] {
    [
        TrajectoryKind::Bezier,
        TrajectoryKind::Linear,
        TrajectoryKind::CubicBSpline,
    ]
}

#[test]
fn endpoints_are_the_end_knots() {
    for kind in [TrajectoryKind::Bezier, TrajectoryKind::Linear] {
        let k = knots(kind.default_knots(), 0.3);
        let t = Trajectory::new(kind, k.clone()).unwrap();
        let first = Se3::exp(&Vector6::from(k[0]));
        let last = Se3::exp(&Vector6::from(*k.last().unwrap()));
        assert!(close(&t.eval(0.0), &first, 1e-12), "{kind:?} u=0");
        assert!(close(&t.eval(1.0), &last, 1e-12), "{kind:?} u=1");
        // And not trivially: the middle differs from both ends.
        assert!(!close(&t.eval(0.5), &first, 1e-3) && !close(&t.eval(0.5), &last, 1e-3));
    }
}

#[test]
fn equal_knots_give_that_pose() {
    let xi = [0.2, -0.4, 0.9, 0.5, -0.3, 1.1];
    let pose = Se3::exp(&Vector6::from(xi));
    for kind in all_kinds() {
        let t = Trajectory::new(kind, vec![xi; kind.default_knots()]).unwrap();
        for u in [0.0, 0.13, 0.5, 0.77, 1.0] {
            assert!(close(&t.eval(u), &pose, 1e-12), "{kind:?} at u={u}");
        }
    }
}

#[test]
fn knot_counts_are_checked() {
    assert!(Trajectory::new(TrajectoryKind::Linear, knots(3, 0.1)).is_err());
    assert!(Trajectory::new(TrajectoryKind::CubicBSpline, knots(2, 0.1)).is_err());
    assert!(Trajectory::new(TrajectoryKind::Bezier, vec![]).is_err());
    let single = Trajectory::new(TrajectoryKind::Bezier, knots(1, 0.2)).unwrap();
    assert!(close(
        &single.eval(0.4),
        &Se3::exp(&Vector6::from(knots(1, 0.2)[0])),
        1e-12
    ));
    assert!(close(
        &Trajectory::identity(TrajectoryKind::Bezier, 9)
            .unwrap()
            .eval(0.3),
        &Se3::identity(),
        1e-15
    ));
}

#[test]
fn bernstein_is_a_partition_of_unity() {
    for u in [0.0, 0.2, 0.5, 0.9, 1.0] {
        let b = bernstein(8, u);
        assert_eq!(b.len(), 9);
        assert!((b.iter().sum::<f64>() - 1.0).abs() < 1e-14);
    }
    // C(8,3) (1−u)^5 u^3 at u = 0.5.
    assert!((bernstein(8, 0.5)[3] - 56.0 / 256.0).abs() < 1e-15);
}

#[test]
fn bezier_is_the_ordered_product() {
    // Δ(u) = Exp(b0 ξ0)·Exp(b1 ξ1)·Exp(b2 ξ2), in that order (not reversed).
    let k = knots(3, 0.6);
    let t = Trajectory::new(TrajectoryKind::Bezier, k.clone()).unwrap();
    let u: f64 = 0.3;
    let b = [(1.0 - u).powi(2), 2.0 * u * (1.0 - u), u * u];
    let e = |j: usize| Se3::exp(&(Vector6::from(k[j]) * b[j]));
    assert!(close(&t.eval(u), &(e(0) * e(1) * e(2)), 1e-12));
    assert!(!close(&t.eval(u), &(e(2) * e(1) * e(0)), 1e-4));
}

#[test]
fn knot_jacobians_match_finite_differences() {
    let h = 1e-6;
    for kind in all_kinds() {
        for scale in [1e-5, 0.05, 0.4] {
            let k = knots(kind.default_knots(), scale);
            let t = Trajectory::new(kind, k.clone()).unwrap();
            for u in [0.0, 0.21, 0.5, 0.93, 1.0] {
                let (pose, jacs) = t.eval_with_jacobians(u);
                assert!(close(&pose, &t.eval(u), 1e-14));
                for (j, jac) in jacs.iter().enumerate() {
                    for c in 0..6 {
                        let shifted = |d: f64| {
                            let mut kk = k.clone();
                            kk[j][c] += d;
                            let p = Trajectory::new(kind, kk).unwrap().eval(u);
                            (pose.inverse() * p).log()
                        };
                        let fd = (shifted(h) - shifted(-h)) / (2.0 * h);
                        for r in 0..6 {
                            let err = (fd[r] - jac[r][c]).abs();
                            assert!(
                                err < 1e-7,
                                "{kind:?} scale {scale} u {u} knot {j} [{r}][{c}]: fd {} vs {}",
                                fd[r],
                                jac[r][c]
                            );
                        }
                    }
                }
            }
        }
    }
}

/// A smooth test loss of a world-to-camera pose: squared distances of transformed points to
/// targets, with its Euclidean gradients dL/dR and dL/dt.
fn loss_and_grads(w2c: &Se3) -> (f64, [[f64; 3]; 3], [f64; 3]) {
    let pts = [[0.3, -1.0, 2.0], [1.5, 0.2, -0.7], [-0.4, 0.9, 1.1]];
    let tgt = [[0.1, 0.2, 3.0], [-0.5, 1.0, 0.4], [0.0, -0.3, 2.2]];
    let mut l = 0.0;
    let mut gr = [[0.0; 3]; 3];
    let mut gt = [0.0; 3];
    for (p, q) in pts.iter().zip(&tgt) {
        let e = w2c.act(&Vector3::from(*p)) - Vector3::from(*q);
        l += e.norm_squared();
        for i in 0..3 {
            gt[i] += 2.0 * e[i];
            for (jj, pj) in p.iter().enumerate() {
                gr[i][jj] += 2.0 * e[i] * pj;
            }
        }
    }
    (l, gr, gt)
}

#[test]
fn pose_gradient_bridge_matches_finite_differences() {
    let w2c = Se3::exp(&Vector6::from([0.4, -0.2, 1.0, 0.3, -0.6, 0.2]));
    let (_, gr, gt) = loss_and_grads(&w2c);
    let left = w2c_left_perturbation_gradient(&w2c, &gr, &gt);
    let right = c2w_right_perturbation_gradient(&w2c, &gr, &gt);
    let h = 1e-6;
    for c in 0..6 {
        let mut e = Vector6::zeros();
        e[c] = h;
        let fd_left = (loss_and_grads(&(Se3::exp(&e) * w2c)).0
            - loss_and_grads(&(Se3::exp(&-e) * w2c)).0)
            / (2.0 * h);
        let c2w = w2c.inverse();
        let via_c2w = |d: &Vector6<f64>| loss_and_grads(&(c2w * Se3::exp(d)).inverse()).0;
        let fd_right = (via_c2w(&e) - via_c2w(&-e)) / (2.0 * h);
        assert!(
            (fd_left - left[c]).abs() < 1e-6,
            "left [{c}]: {fd_left} vs {}",
            left[c]
        );
        assert!(
            (fd_right - right[c]).abs() < 1e-6,
            "right [{c}]: {fd_right} vs {}",
            right[c]
        );
    }
}

#[test]
fn render_gradient_to_knot_gradient_chain() {
    // The trainer's chain: w2c(u) = (c2w_init · Δ(u))⁻¹, renderer gives dL/dR, dL/dt, and
    // dL/dξ_j comes from c2w_right_perturbation_gradient + accumulate_knot_gradients.
    let c2w_init = Se3::exp(&Vector6::from([1.0, 0.5, -2.0, 0.1, 0.7, -0.3]));
    let u = 0.37;
    for kind in all_kinds() {
        let k = knots(kind.default_knots(), 0.1);
        let t = Trajectory::new(kind, k.clone()).unwrap();
        let w2c = (c2w_init * t.eval(u)).inverse();
        let (_, gr, gt) = loss_and_grads(&w2c);
        let g = c2w_right_perturbation_gradient(&w2c, &gr, &gt);
        let mut grads = vec![[0.0; 6]; k.len()];
        t.accumulate_knot_gradients(u, &g, &mut grads);
        let h = 1e-6;
        for j in 0..k.len() {
            for c in 0..6 {
                let l = |d: f64| {
                    let mut kk = k.clone();
                    kk[j][c] += d;
                    let tt = Trajectory::new(kind, kk).unwrap();
                    loss_and_grads(&(c2w_init * tt.eval(u)).inverse()).0
                };
                let fd = (l(h) - l(-h)) / (2.0 * h);
                assert!(
                    (fd - grads[j][c]).abs() < 1e-6 * (1.0 + fd.abs()),
                    "{kind:?} knot {j} c {c}: {fd} vs {}",
                    grads[j][c]
                );
            }
        }
    }
}

fn times(n: usize) -> Vec<f64> {
    (0..n).map(|k| k as f64 / (n - 1) as f64).collect()
}

/// A knot-gradient regulariser's signature: (trajectory, times, weight, knot gradients) → energy.
type KnotEnergy = fn(&Trajectory, &[f64], f64, &mut [[f64; 6]]) -> f64;

/// Checks `energy`'s knot gradient against central finite differences of the energy, for every
/// trajectory kind, at weight 1.5 on 7 evenly spaced times.
fn assert_knot_gradient_matches_finite_differences(energy_of: KnotEnergy) {
    let ts = times(7);
    for kind in all_kinds() {
        let k0 = knots(kind.default_knots(), 0.2);
        let t = Trajectory::new(kind, k0.clone()).unwrap();
        let mut grad = vec![[0.0; 6]; k0.len()];
        let e = energy_of(&t, &ts, 1.5, &mut grad);
        assert!(e > 0.0);
        let h = 1e-6;
        for j in 0..k0.len() {
            for c in 0..6 {
                let energy = |d: f64| {
                    let mut k = k0.clone();
                    k[j][c] += d;
                    let t = Trajectory::new(kind, k).unwrap();
                    energy_of(&t, &ts, 1.5, &mut vec![[0.0; 6]; k0.len()])
                };
                let fd = (energy(h) - energy(-h)) / (2.0 * h);
                assert!(
                    (fd - grad[j][c]).abs() < 1e-6 * (1.0 + fd.abs()),
                    "{kind:?} knot {j} coordinate {c}: analytic {} vs finite difference {fd}",
                    grad[j][c]
                );
            }
        }
    }
}

/// The uneven-speed energy's knot gradient against central finite differences of the energy,
/// for every trajectory kind.
#[test]
fn uneven_speed_gradient_matches_finite_differences() {
    assert_knot_gradient_matches_finite_differences(uneven_speed_energy);
}

/// Along one straight path, evenly spaced poses have less energy than the same path walked
/// unevenly (a dwell at one end, the blur-equivalent reparametrisation that moves u = ½ off the
/// middle); a path that folds back costs more than the straight one; weight 0 adds nothing.
#[test]
fn uneven_speed_energy_is_smallest_for_even_spacing() {
    let line = |a: f64| -> [f64; 6] { [a, 0.5 * a, 0.0, 0.0, 0.1 * a, 0.0] };
    let ts = times(9);
    // Linear trajectory: Δ(u) moves at constant speed from knot 0 to knot 1.
    let even = Trajectory::new(TrajectoryKind::Linear, vec![line(-0.1), line(0.1)]).unwrap();
    let mut g = vec![[0.0; 6]; 2];
    let e_even = uneven_speed_energy(&even, &ts, 1.0, &mut g);
    // The same segment walked with u² timing: the same poses set, bunched at the start.
    let bunched: Vec<f64> = ts.iter().map(|u| u * u).collect();
    let e_bunched = uneven_speed_energy(&even, &bunched, 1.0, &mut [[0.0; 6]; 2]);
    assert!(e_even < e_bunched, "{e_even} vs {e_bunched}");
    // Folding back over the first half (out to the end and back) doubles the distance covered.
    let folded: Vec<f64> = ts.iter().map(|u| 1.0 - (2.0 * u - 1.0).abs()).collect();
    let e_folded = uneven_speed_energy(&even, &folded, 1.0, &mut [[0.0; 6]; 2]);
    assert!(e_folded > e_even, "{e_folded} vs {e_even}");
    let mut zero = vec![[0.0; 6]; 2];
    assert_eq!(uneven_speed_energy(&even, &ts, 0.0, &mut zero), 0.0);
    assert_eq!(zero, vec![[0.0; 6]; 2]);
}

/// The off-centre energy's knot gradient against central finite differences of the energy, for
/// every trajectory kind and both centres (the median's choice of poses is constant near these
/// knots).
#[test]
fn off_centre_gradient_matches_finite_differences() {
    assert_knot_gradient_matches_finite_differences(|t, ts, w, g| {
        off_centre_energy(t, ts, PathCentre::Mean, w, g)
    });
    // Even paths have their median at u = ½ (no energy): sample them unevenly.
    assert_knot_gradient_matches_finite_differences(|t, ts, w, g| {
        let uneven: Vec<f64> = ts.iter().map(|u| u * u).collect();
        off_centre_energy(t, &uneven, PathCentre::Median, w, g)
    });
}

/// A path walked at even speed along a line has its middle on the mean and the median of its
/// poses (no energy, whatever its length); the same segment walked with u² timing has its
/// u = ½ pose off both, and so does a path that folds back at u = ½; weight 0 adds nothing.
#[test]
fn off_centre_energy_vanishes_only_for_a_centred_path() {
    let line = |a: f64| -> [f64; 6] { [a, 0.5 * a, 0.0, 0.0, 0.0, 0.0] };
    let even = Trajectory::new(TrajectoryKind::Linear, vec![line(-0.3), line(0.3)]).unwrap();
    for centre in [PathCentre::Mean, PathCentre::Median] {
        for ts in [times(9), times(8)] {
            let mut g = vec![[0.0; 6]; 2];
            assert!(off_centre_energy(&even, &ts, centre, 1.0, &mut g) < 1e-24);
            assert!(g.iter().flatten().all(|x| x.abs() < 1e-12), "{g:?}");
            let bunched: Vec<f64> = ts.iter().map(|u| u * u).collect();
            assert!(off_centre_energy(&even, &bunched, centre, 1.0, &mut [[0.0; 6]; 2]) > 1e-3);
            // Pure translations compose additively: x(u) = 4·0.3·u(1 − u), out and back.
            let folded =
                Trajectory::new(TrajectoryKind::Bezier, vec![[0.0; 6], line(0.6), [0.0; 6]])
                    .unwrap();
            let e = off_centre_energy(&folded, &ts, centre, 1.0, &mut [[0.0; 6]; 3]);
            assert!(e > 1e-3, "{centre:?} {e}");
            let mut zero = vec![[0.0; 6]; 2];
            assert_eq!(
                off_centre_energy(&even, &bunched, centre, 0.0, &mut zero),
                0.0
            );
            assert_eq!(zero, vec![[0.0; 6]; 2]);
        }
    }
}

/// On a curved path walked at even speed (a cubic Bézier whose inner knots bend it sideways, the
/// shape of `gems synth`'s exposures), and on a straight one walked at uneven speed, u = ½ is
/// the median of the poses but not their mean: the mean lies inside the bend, or toward the slow
/// end.
#[test]
fn the_median_is_the_middle_of_curved_and_uneven_paths() {
    let ts = times(15);
    // Bézier knots are a product of Exp(b_j ξ_j): a path that sweeps along x and bends along y
    // in translation and rotation alike.
    let bent = Trajectory::new(
        TrajectoryKind::Bezier,
        vec![
            [-0.3, 0.0, 0.0, 0.0, -0.2, 0.0],
            [0.2, 0.25, 0.0, 0.15, 0.1, 0.0],
            [0.2, -0.25, 0.0, -0.15, 0.1, 0.0],
            [0.2, 0.0, 0.0, 0.0, 0.1, 0.0],
        ],
    )
    .unwrap();
    let mut g = vec![[0.0; 6]; 4];
    let median = off_centre_energy(&bent, &ts, PathCentre::Median, 1.0, &mut g);
    let mean = off_centre_energy(&bent, &ts, PathCentre::Mean, 1.0, &mut [[0.0; 6]; 4]);
    assert!(median < 1e-24, "median {median}");
    assert!(mean > 1e-4, "mean {mean}");
    // A straight path, its poses at u^1.5: faster toward the end, monotone.
    let line = |a: f64| -> [f64; 6] { [a, 0.5 * a, 0.0, 0.0, 0.1 * a, 0.0] };
    let straight = Trajectory::new(TrajectoryKind::Linear, vec![line(-0.3), line(0.3)]).unwrap();
    let uneven: Vec<f64> = ts.iter().map(|u: &f64| u.powf(1.5)).collect();
    let mid_time = uneven[7];
    // Re-time the path so that its pose at u = ½ is the one at the middle sample.
    let shifted: Vec<f64> = uneven
        .iter()
        .map(|u| (u - mid_time + 0.5).clamp(0.0, 1.0))
        .collect();
    let mut g = vec![[0.0; 6]; 2];
    let median = off_centre_energy(&straight, &shifted, PathCentre::Median, 1.0, &mut g);
    let mean = off_centre_energy(&straight, &shifted, PathCentre::Mean, 1.0, &mut g);
    assert!(median < 1e-24, "median {median}");
    assert!(mean > 1e-4, "mean {mean}");
}

#[test]
fn straightened_knots_are_their_least_squares_line() {
    for n in [3, 4, 9] {
        let bent = knots(n, 0.3);
        let mut line = bent.clone();
        straighten_knots(&mut line);
        let t: Vec<f64> = (0..n).map(|j| j as f64 / (n - 1) as f64 - 0.5).collect();
        for i in 0..6 {
            // The residuals are orthogonal to both regressors (1 and t): the normal equations.
            let r: Vec<f64> = bent.iter().zip(&line).map(|(b, l)| b[i] - l[i]).collect();
            assert!(r.iter().sum::<f64>().abs() < 1e-12, "n={n} coord {i}");
            let rt: f64 = r.iter().zip(&t).map(|(r, t)| r * t).sum();
            assert!(rt.abs() < 1e-12, "n={n} coord {i}");
            // Evenly spaced on the line.
            let step = line[1][i] - line[0][i];
            for j in 1..n {
                assert!((line[j][i] - line[j - 1][i] - step).abs() < 1e-12);
            }
        }
        // Not trivially: the test knots are bent, and the line is a fixed point.
        assert!(bent != line);
        let mut again = line.clone();
        straighten_knots(&mut again);
        for (a, l) in again.iter().zip(&line) {
            for i in 0..6 {
                assert!((a[i] - l[i]).abs() < 1e-14);
            }
        }
    }
    // Two knots are already a line.
    let mut two = knots(2, 0.3);
    let before = two.clone();
    straighten_knots(&mut two);
    assert_eq!(two, before);
}

#[test]
fn straight_knots_give_a_constant_speed_path() {
    let screw = [0.11, -0.07, 0.05, 0.04, -0.09, 0.06];
    let along = |d: [f64; 6], n: usize| -> Vec<[f64; 6]> {
        (0..n)
            .map(|j| d.map(|x| x * j as f64 / (n - 1) as f64))
            .collect()
    };
    let scaled = |d: [f64; 6], s: f64| Se3::exp(&Vector6::from(d.map(|x| x * s)));
    let u_grid = [0.0, 0.21, 0.5, 0.64, 1.0];
    // Bézier: Exp(u·d) for any screw d.
    let mut k = along(screw, 9);
    straighten_knots(&mut k);
    let bezier = Trajectory::new(TrajectoryKind::Bezier, k).unwrap();
    for u in u_grid {
        assert!(
            close(&bezier.eval(u), &scaled(screw, u), 1e-12),
            "bezier u={u}"
        );
    }
    // Linear and the cubic B-spline interpolate translation and rotation apart, so they are a
    // constant-speed line for a pure translation or a pure rotation; the spline's one segment
    // spans the middle third of its knots (from d/3 to 2d/3).
    for d in [
        [0.11, -0.07, 0.05, 0.0, 0.0, 0.0],
        [0.0, 0.0, 0.0, 0.04, -0.09, 0.06],
    ] {
        for (kind, start, span) in [
            (TrajectoryKind::Linear, 0.0, 1.0),
            (TrajectoryKind::CubicBSpline, 1.0 / 3.0, 1.0 / 3.0),
        ] {
            let mut k = along(d, kind.default_knots());
            straighten_knots(&mut k);
            let t = Trajectory::new(kind, k).unwrap();
            for u in u_grid {
                let want = scaled(d, start + span * u);
                assert!(close(&t.eval(u), &want, 1e-12), "{kind:?} u={u}");
            }
        }
    }
}

/// The anchor energy's knot gradient against central finite differences, for every kind; it
/// vanishes for a path centred on the initial camera and grows with a shared offset.
#[test]
fn anchor_gradient_matches_finite_differences_and_measures_the_offset() {
    assert_knot_gradient_matches_finite_differences(anchor_energy);
    let ts = times(9);
    let line = |a: f64, off: f64| -> [f64; 6] { [a + off, 0.5 * a, 0.0, 0.0, 0.0, 0.0] };
    let centred = Trajectory::new(
        TrajectoryKind::Linear,
        vec![line(-0.1, 0.0), line(0.1, 0.0)],
    )
    .unwrap();
    assert!(anchor_energy(&centred, &ts, 1.0, &mut [[0.0; 6]; 2]) < 1e-24);
    let shifted = Trajectory::new(
        TrajectoryKind::Linear,
        vec![line(-0.1, 0.2), line(0.1, 0.2)],
    )
    .unwrap();
    let e = anchor_energy(&shifted, &ts, 1.0, &mut [[0.0; 6]; 2]);
    assert!((e - 0.04).abs() < 1e-9, "{e}");
    let mut zero = vec![[0.0; 6]; 2];
    assert_eq!(anchor_energy(&shifted, &ts, 0.0, &mut zero), 0.0);
    assert_eq!(zero, vec![[0.0; 6]; 2]);
}

/// Holding the midpoint puts Δ(½) on the identity for every kind, from paths far off it, and
/// moves the path rigidly: each pose relative to the midpoint, Δ(½)⁻¹ Δ(u), is kept to first
/// order in the path's size (exactly for a constant-speed screw, whose factors commute).
#[test]
fn holding_the_midpoint_centres_the_path_and_keeps_its_shape() {
    let u_grid = [0.0, 0.13, 0.5, 0.77, 1.0];
    for kind in all_kinds() {
        for scale in [0.01, 0.05, 0.2] {
            let mut t = Trajectory::new(kind, knots(kind.knots(9), scale)).unwrap();
            let before_mid = t.eval(0.5);
            assert!(
                before_mid.log().norm() > scale * 0.1,
                "{kind:?}: not trivially"
            );
            let relative = |t: &Trajectory, u: f64| t.eval(0.5).inverse() * t.eval(u);
            let shape: Vec<Se3> = u_grid.iter().map(|&u| relative(&t, u)).collect();
            let size = t
                .knots()
                .iter()
                .map(|k| Vector6::from(*k).norm())
                .fold(0.0, f64::max);
            let residual = hold_midpoint(&mut t, 1e-13, 20);
            assert!(residual <= 1e-13, "{kind:?} scale {scale}: {residual}");
            assert!(t.eval(0.5).log().norm() <= 1e-13);
            // The shape changes only at second order in the path's size.
            for (&u, s) in u_grid.iter().zip(&shape) {
                let err = (relative(&t, u).inverse() * *s).log().norm();
                assert!(
                    err < size * size,
                    "{kind:?} scale {scale} u {u}: {err} ({size})"
                );
            }
        }
    }
    // A constant-speed screw off the camera (commuting factors) keeps its shape exactly.
    let screw = [0.11, -0.07, 0.05, 0.04, -0.09, 0.06];
    let line = (0..9)
        .map(|j| screw.map(|x| x * (j as f64 / 8.0 + 0.3)))
        .collect();
    let mut t = Trajectory::new(TrajectoryKind::Bezier, line).unwrap();
    let step = t.eval(0.25).inverse() * t.eval(0.75);
    hold_midpoint(&mut t, 1e-14, 20);
    let after = t.eval(0.25).inverse() * t.eval(0.75);
    assert!(close(&step, &after, 1e-12));
    // A centred path is a fixed point.
    let before = t.clone();
    hold_midpoint(&mut t, 1e-12, 20);
    assert_eq!(t, before);
}

/// The projected gradient moves no knot combination that moves the midpoint (Σ_j J_j g_j = 0),
/// and it is the orthogonal projection: idempotent, and what it removed is orthogonal to it.
#[test]
fn the_midpoint_tangent_gradient_leaves_the_midpoint_in_place() {
    for kind in all_kinds() {
        let t = Trajectory::new(kind, knots(kind.knots(9), 0.1)).unwrap();
        let g0 = knots(t.num_knots(), 0.7)
            .into_iter()
            .map(|k| k.map(|x| x + 0.3))
            .collect::<Vec<_>>();
        let mut g = g0.clone();
        midpoint_tangent_gradient(&t, &mut g);
        let (_, jacs) = t.eval_with_jacobians(0.5);
        let moved = |g: &[[f64; 6]]| {
            (0..6)
                .map(|r| {
                    jacs.iter()
                        .zip(g)
                        .map(|(j, g)| (0..6).map(|c| j[r][c] * g[c]).sum::<f64>())
                        .sum::<f64>()
                        .powi(2)
                })
                .sum::<f64>()
                .sqrt()
        };
        assert!(moved(&g0) > 0.1, "{kind:?}: not trivially");
        assert!(moved(&g) < 1e-12, "{kind:?}: {}", moved(&g));
        let dot = |a: &[[f64; 6]], b: &[[f64; 6]]| {
            a.iter()
                .zip(b)
                .map(|(a, b)| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>())
                .sum::<f64>()
        };
        let removed: Vec<[f64; 6]> = g0
            .iter()
            .zip(&g)
            .map(|(a, b)| std::array::from_fn(|i| a[i] - b[i]))
            .collect();
        assert!(dot(&removed, &g).abs() < 1e-12, "{kind:?}: not orthogonal");
        let mut again = g.clone();
        midpoint_tangent_gradient(&t, &mut again);
        assert!(
            dot(&again, &again) - dot(&g, &g) < 1e-12
                && again
                    .iter()
                    .zip(&g)
                    .all(|(a, b)| a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-12))
        );
    }
}

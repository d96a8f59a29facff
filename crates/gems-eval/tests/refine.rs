//! Test-time pose refinement: gradient vs central finite differences, and recovery of a
//! perturbed pose with the Gaussians frozen.

mod common;

use gems_eval::refine::{pose_loss_and_grad, render};
use gems_eval::{PoseRefineConfig, refine_pose};
use gems_gpu::Engine;

#[test]
fn pose_gradient_matches_finite_differences() {
    let g = common::scene(60, -2.6, 0.5);
    let k = common::intrinsics();
    let mut engine = Engine::cpu();
    let mut r = engine.freeze(&g).unwrap();
    let gt = render(&mut r, &common::camera(0.0), &k).unwrap();
    let start = common::perturb(
        &common::camera(0.0),
        [0.05, -0.04, 0.03, 0.02, -0.015, 0.01],
    );
    let delta = [0.01, 0.02, -0.01, 0.005, 0.004, -0.006];
    let (_, grad) = pose_loss_and_grad(&mut r, &start, &k, &gt, &delta).unwrap();
    let h = 1e-4;
    let gmax = grad.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    assert!(gmax > 1e-4, "gradient should not vanish: {grad:?}");
    for c in 0..6 {
        let mut at = |s: f64| {
            let mut d = delta;
            d[c] += s;
            pose_loss_and_grad(&mut r, &start, &k, &gt, &d).unwrap().0
        };
        let fd = (at(h) - at(-h)) / (2.0 * h);
        // The analytic gradient is gsplat's (it ignores the jumps where a Gaussian crosses
        // the α ≥ 1/255 cut-off); finite differences see those jumps, a few percent here.
        assert!(
            (fd - grad[c]).abs() < 0.1 * fd.abs() + 0.02 * gmax,
            "component {c}: fd {fd} vs {}",
            grad[c]
        );
    }
}

#[test]
fn refinement_recovers_a_perturbed_pose() {
    let g = common::scene(60, -2.6, 0.5);
    let k = common::intrinsics();
    let mut engine = Engine::cpu();
    let mut r = engine.freeze(&g).unwrap();
    let truth = common::camera(0.3);
    let gt = render(&mut r, &truth, &k).unwrap();
    let start = common::perturb(&truth, [0.03, -0.02, 0.02, 0.01, -0.012, 0.008]);
    let before = common::reprojection_error(&g, &k, &start, &truth);
    let out = refine_pose(&mut r, &start, &k, &gt, &PoseRefineConfig::default()).unwrap();
    let after = common::reprojection_error(&g, &k, &out.c2w, &truth);
    assert!(
        out.l1_after < 0.1 * out.l1_before,
        "L1 {} -> {}",
        out.l1_before,
        out.l1_after
    );
    assert!(
        before > 1.0 && after < 0.2,
        "reprojection error {before} px -> {after} px"
    );
    // Zero steps: the initial pose, unchanged.
    let none = refine_pose(
        &mut r,
        &start,
        &k,
        &gt,
        &PoseRefineConfig {
            steps: 0,
            ..Default::default()
        },
    )
    .unwrap();
    assert_eq!(none.c2w, start);
    assert_eq!(none.l1_before, none.l1_after);
}

//! The blur model's gradient chain (renders → mean → per-camera pose gradients → tangent →
//! knot Jacobians) checked against central finite differences of the full loss w.r.t. knots,
//! on the f64 reference renderer (with the hard 1/255 and 3.33σ cut-offs removed: they make the
//! loss discontinuous, which biases finite differences by a non-vanishing amount).

mod common;

use gems_math::{Trajectory, TrajectoryKind};
use gems_splat::Camera;
use gems_splat::reference;
use gems_train::{BlurWorkspace, Exposure, backward_blurred, render_blurred};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

#[test]
fn knot_gradients_match_finite_differences_of_the_blurred_loss() {
    let g = common::wall(40, 11, 0.9);
    let k = common::intrinsics(24, 18);
    let c2w0 = common::pose(0.05, -0.02, 0.03);
    let times: Vec<f64> = (0..5).map(|i| i as f64 / 4.0).collect();
    let mut rng = ChaCha8Rng::seed_from_u64(4);
    let knots: Vec<[f64; 6]> = (0..4)
        .map(|_| std::array::from_fn(|_| (rng.random::<f64>() - 0.5) * 0.06))
        .collect();
    let traj = Trajectory::new(TrajectoryKind::Bezier, knots.clone()).unwrap();
    // Loss = Σ w · blurred with fixed random weights: its gradient w.r.t. the blurred image is w.
    let w: Vec<f32> = (0..(k.width * k.height * 3))
        .map(|_| rng.random::<f32>() - 0.5)
        .collect();
    let bg = [0.2f32, 0.3, 0.1];

    let mut ws = BlurWorkspace::default();
    let mut r = common::Reference(common::smooth_settings());
    let exposure = Exposure {
        c2w_init: &c2w0,
        trajectory: &traj,
        times: &times,
        intrinsics: &k,
    };
    render_blurred(&mut r, &g, &exposure, bg, &mut ws).unwrap();
    let mut analytic = vec![[0.0f64; 6]; 4];
    backward_blurred(&mut r, &g, &exposure, &w, None, &mut ws, &mut analytic).unwrap();

    // f64 loss straight from the reference renderer.
    let loss = |knots: &[[f64; 6]]| -> f64 {
        let t = Trajectory::new(TrajectoryKind::Bezier, knots.to_vec()).unwrap();
        let cams: Vec<_> = times
            .iter()
            .map(|&u| Camera::from_c2w(&k, &(c2w0 * t.eval(u))))
            .collect();
        let out = reference::forward(&g, &cams, &vec![bg; cams.len()], &common::smooth_settings())
            .unwrap();
        let img = w.len();
        out.rgb
            .chunks_exact(img)
            .map(|v| v.iter().zip(&w).map(|(a, b)| a * *b as f64).sum::<f64>())
            .sum::<f64>()
            / times.len() as f64
    };
    let h = 1e-3;
    let max_abs = analytic
        .iter()
        .flatten()
        .fold(0.0f64, |m, v| m.max(v.abs()));
    assert!(
        max_abs > 1e-2,
        "test scene gives a meaningful pose gradient ({max_abs})"
    );
    for j in 0..4 {
        for c in 0..6 {
            let mut p = knots.clone();
            p[j][c] += h;
            let mut m = knots.clone();
            m[j][c] -= h;
            let fd = (loss(&p) - loss(&m)) / (2.0 * h);
            let a = analytic[j][c];
            assert!(
                (fd - a).abs() <= 5e-3 * fd.abs().max(a.abs()) + 1e-4 * max_abs,
                "knot {j} component {c}: analytic {a} vs finite difference {fd}"
            );
        }
    }
}

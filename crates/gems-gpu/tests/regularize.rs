//! The MCMC regularisers on the GPU against an f64 reference of gems-train's `add_regularizers`
//! (private to trainer.rs, so restated here: R = opacity_reg·mean σ(l) + scale_reg·mean e^{ls}),
//! with central differences of that reference for the gradients.

mod common;

use common::{ctx, gaussians, values};
use gems_gpu::{GpuGaussians, GpuGradients, GpuRegularizers};
use gems_splat::Gaussians;
use gems_splat::activation::sigmoid_f64;

const OR: f64 = 0.01;
const SR: f64 = 0.01;

fn reference(g: &Gaussians) -> f64 {
    let n = g.len() as f64;
    let o: f64 = g
        .opacity_logits
        .iter()
        .map(|&l| sigmoid_f64(l as f64))
        .sum();
    let s: f64 = g
        .log_scales
        .iter()
        .flatten()
        .map(|&l| (l as f64).exp())
        .sum();
    OR * o / n + SR * s / (3.0 * n)
}

#[test]
fn value_and_gradients_match_the_f64_reference() {
    let ctx = ctx();
    // 1000 Gaussians: four workgroups of partial sums, the last one partial.
    let g = gaussians(1000, 8);
    let n = g.len();
    // Start from nonzero gradients: the regularisers add to what the rasterizer wrote.
    let base = gems_splat::Gradients {
        means: vec![[0.0; 3]; n],
        quats: vec![[0.0; 4]; n],
        log_scales: bytemuck::cast_slice(&values(3 * n, 1, -1e-3, 1e-3)).to_vec(),
        opacity_logits: values(n, 2, -1e-3, 1e-3),
        sh: vec![[[0.0; 3]; 16]; n],
        ..Default::default()
    };
    let resident = GpuGaussians::upload(ctx, &g, 0).unwrap();
    let grads = GpuGradients::upload(ctx, &base, 0).unwrap();
    let reg = GpuRegularizers::new(ctx).unwrap();
    let mut enc = ctx.device.create_command_encoder(&Default::default());
    reg.encode(ctx, &mut enc, &resident, &grads, OR as f32, SR as f32)
        .unwrap();
    ctx.queue.submit([enc.finish()]);
    let value = reg.read(ctx).unwrap() as f64;
    let r = reference(&g);
    eprintln!("R gpu {value} vs f64 {r}");
    // f32 terms summed by fixed-order trees over ≤ 3000 values: ~1e-6 relative.
    assert!((value - r).abs() < 2e-6 * r, "{value} vs {r}");

    let go: Vec<f32> =
        gems_gpu::buffers::download(ctx, grads.group(gems_gpu::Group::OpacityLogits), 0, n)
            .unwrap();
    let gs: Vec<f32> =
        gems_gpu::buffers::download(ctx, grads.group(gems_gpu::Group::LogScales), 0, 3 * n)
            .unwrap();
    // Analytic f64 gradients plus the starting values; the f32 formulas are within a few ulps
    // of the (≤ 1e-5) regulariser term, i.e. ~1e-11 absolute.
    let mut worst = 0.0f64;
    for i in 0..n {
        let o = sigmoid_f64(g.opacity_logits[i] as f64);
        let want = base.opacity_logits[i] as f64 + OR * o * (1.0 - o) / n as f64;
        worst = worst.max((go[i] as f64 - want).abs());
        for a in 0..3 {
            let e = (g.log_scales[i][a] as f64).exp();
            let want = base.log_scales[i][a] as f64 + SR * e / (3 * n) as f64;
            worst = worst.max((gs[3 * i + a] as f64 - want).abs());
        }
    }
    eprintln!("gradients: max |gpu − f64| = {worst:e}");
    // The base gradients are ~1e-3: adding the term rounds at ~6e-11.
    assert!(worst < 2e-10, "{worst}");

    // Central differences of the reference for one logit and one log-scale.
    let eps = 1e-3f32;
    let fd = |edit: &dyn Fn(&mut Gaussians, f32)| {
        let (mut p, mut m) = (g.clone(), g.clone());
        edit(&mut p, eps);
        edit(&mut m, -eps);
        (reference(&p) - reference(&m)) / (2.0 * eps as f64)
    };
    let d_l = fd(&|x: &mut Gaussians, e| x.opacity_logits[7] += e);
    let d_s = fd(&|x: &mut Gaussians, e| x.log_scales[9][2] += e);
    let (a_l, a_s) = (
        go[7] as f64 - base.opacity_logits[7] as f64,
        gs[29] as f64 - base.log_scales[9][2] as f64,
    );
    assert!((d_l - a_l).abs() < 1e-3 * d_l.abs(), "{d_l} vs {a_l}");
    assert!((d_s - a_s).abs() < 1e-3 * d_s.abs(), "{d_s} vs {a_s}");
}

#[test]
fn no_gaussians_give_zero_and_short_gradients_are_an_error() {
    let ctx = ctx();
    let reg = GpuRegularizers::new(ctx).unwrap();
    let empty = GpuGaussians::upload(ctx, &Gaussians::with_degree(0), 0).unwrap();
    let grads = GpuGradients::new(ctx, 0).unwrap();
    let mut enc = ctx.device.create_command_encoder(&Default::default());
    reg.encode(ctx, &mut enc, &empty, &grads, 0.01, 0.01)
        .unwrap();
    ctx.queue.submit([enc.finish()]);
    assert_eq!(reg.read(ctx).unwrap(), 0.0);
    let some = GpuGaussians::upload(ctx, &gaussians(10, 1), 0).unwrap();
    let mut enc = ctx.device.create_command_encoder(&Default::default());
    assert!(
        reg.encode(ctx, &mut enc, &some, &grads, 0.01, 0.01)
            .is_err()
    );
}

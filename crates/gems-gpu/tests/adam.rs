//! GPU Adam against gems-train's CPU Adam (`AdamState`, as the trainer calls it per group) over
//! several steps.

mod common;

use common::{ctx, gaussians, max_rounding_err, values};
use gems_gpu::{
    AdamConfig, AdamGroupStep, GaussianLrs, GpuAdam, GpuGaussians, GpuGradients, Group, buffers,
};
use gems_train::adam::GaussianAdam;
use gems_train::adam::{AdamHyper, AdamState};

const LRS: GaussianLrs = GaussianLrs {
    means: 1.6e-4 * 3.7,
    quats: 1e-3,
    log_scales: 5e-3,
    opacity_logits: 5e-2,
    sh_dc: 2.5e-3,
    sh_rest: 2.5e-3 / 20.0,
};

const CFG: AdamConfig = AdamConfig {
    beta1: 0.9,
    beta2: 0.999,
    eps: 1e-15,
    weight_decay: 0.0,
};

fn gradients(n: usize, seed: u64) -> gems_splat::Gradients {
    let g = gaussians(n, seed);
    // Gradients of mixed magnitudes and signs, some exactly zero (the `sign(0)` case).
    let scale = |v: &mut [f32], s: f32| {
        for (i, x) in v.iter_mut().enumerate() {
            *x = if i % 97 == 0 { 0.0 } else { *x * s };
        }
    };
    let mut out = gems_splat::Gradients {
        means: g.means,
        quats: g.quats,
        log_scales: g.log_scales,
        opacity_logits: g.opacity_logits,
        sh: g.sh,
        ..Default::default()
    };
    scale(bytemuck::cast_slice_mut(&mut out.means), 1e-3);
    scale(bytemuck::cast_slice_mut(&mut out.quats), 1e-5);
    scale(bytemuck::cast_slice_mut(&mut out.log_scales), 1e-2);
    scale(&mut out.opacity_logits, 1e-4);
    scale(bytemuck::cast_slice_mut(&mut out.sh), 1e-6);
    out
}

/// The CPU trainer's Gaussian Adam step (gems-train `GaussianAdam::step`).
fn cpu_step(g: &mut gems_splat::Gaussians, a: &mut GaussianAdam, gr: &gems_splat::Gradients) {
    let h = AdamHyper {
        beta1: CFG.beta1,
        beta2: CFG.beta2,
        eps: CFG.eps,
    };
    a.step(g, gr, &LRS, h);
}

fn cpu_state(a: &GaussianAdam, group: Group) -> &AdamState {
    match group {
        Group::Means => &a.means,
        Group::Quats => &a.quats,
        Group::LogScales => &a.log_scales,
        Group::OpacityLogits => &a.opacity_logits,
        Group::Sh => &a.sh,
    }
}

fn group_values(g: &gems_splat::Gaussians, group: Group) -> Vec<f32> {
    match group {
        Group::Means => bytemuck::cast_slice(&g.means).to_vec(),
        Group::Quats => bytemuck::cast_slice(&g.quats).to_vec(),
        Group::LogScales => bytemuck::cast_slice(&g.log_scales).to_vec(),
        Group::OpacityLogits => g.opacity_logits.clone(),
        Group::Sh => bytemuck::cast_slice(&g.sh).to_vec(),
    }
}

/// The gradients' magnitudes: Adam on them accumulates, in its first moments, the sum of the
/// magnitudes of the terms that entered each moment, the scale of its rounding errors.
fn magnitudes(g: &gems_splat::Gradients) -> gems_splat::Gradients {
    let mut out = g.clone();
    let groups: [&mut [f32]; 5] = [
        bytemuck::cast_slice_mut(&mut out.means),
        bytemuck::cast_slice_mut(&mut out.quats),
        bytemuck::cast_slice_mut(&mut out.log_scales),
        &mut out.opacity_logits,
        bytemuck::cast_slice_mut(&mut out.sh),
    ];
    for x in groups.into_iter().flatten() {
        *x = x.abs();
    }
    out
}

/// The largest learning rate of a group (SH: dc and rest share one array).
fn group_lr(group: Group) -> f32 {
    match group {
        Group::Means => LRS.means,
        Group::Quats => LRS.quats,
        Group::LogScales => LRS.log_scales,
        Group::OpacityLogits => LRS.opacity_logits,
        Group::Sh => LRS.sh_dc.max(LRS.sh_rest),
    }
}

/// Each parameter's scale after `steps` Adam steps of learning rate `lr` from `start`: an Adam
/// step moves a parameter by lr·|m̂/√v̂|, which is lr on the first step and stays below ~3·lr
/// for these gradients.
fn param_scale(start: &[f32], steps: u64, lr: f32) -> Vec<f32> {
    start
        .iter()
        .map(|p| p.abs() + 3.0 * steps as f32 * lr)
        .collect()
}

#[test]
fn matches_cpu_adam_of_every_gaussian_group_over_steps() {
    let ctx = ctx();
    // 1000 rows: several workgroups, not a multiple of 256; capacity above len.
    let n = 1000;
    let start = gaussians(n, 1);
    let mut cpu = start.clone();
    let mut cpu_adam = GaussianAdam::new(n);
    let (mut abs_params, mut abs_adam) = (start.clone(), GaussianAdam::new(n));
    let mut gpu = GpuGaussians::upload(ctx, &cpu, 1200).unwrap();
    let adam = GpuAdam::new(ctx);
    let steps = 6;
    for s in 0..steps {
        let gr = gradients(n, 100 + s);
        cpu_step(&mut cpu, &mut cpu_adam, &gr);
        cpu_step(&mut abs_params, &mut abs_adam, &magnitudes(&gr));
        let ggr = GpuGradients::upload(ctx, &gr, n).unwrap();
        adam.step_gaussians(ctx, &mut gpu, &ggr, &LRS, CFG).unwrap();
    }
    let out = gpu.download(ctx).unwrap();
    for group in Group::ALL {
        let (a, b) = (group_values(&out, group), group_values(&cpu, group));
        let mom = gpu.moments(ctx, group).unwrap();
        let st = cpu_state(&cpu_adam, group);
        assert_eq!(mom.step, steps);
        let p_scale = param_scale(&group_values(&start, group), steps, group_lr(group));
        let (ep, em, ev) = (
            max_rounding_err(&a, &b, &p_scale),
            max_rounding_err(&mom.m, &st.m, &cpu_state(&abs_adam, group).m),
            // v sums squares: no cancellation, its own value is its scale.
            max_rounding_err(&mom.v, &st.v, &st.v),
        );
        let dp = common::max_abs_diff(&a, &b);
        eprintln!("{group:?}: params {ep:.2} ε (|Δ| ≤ {dp:e}), m {em:.2} ε, v {ev:.2} ε");
        // Same f32 formula and order. A fused multiply-add moves each moment update by about
        // one rounding of its terms, six steps at most 6 ε of their magnitudes; the division
        // (≤ 2.5 ulp) and the inverse square root (≤ 2 ulp) that Vulkan allows move each
        // parameter update by ≲ 10 ulps of the update, which is ≤ 3·lr.
        assert!(em <= 8.0 && ev <= 8.0, "{group:?}: moments {em}/{ev} ε");
        assert!(ep <= 16.0, "{group:?}: parameters {ep} ε apart");
    }
}

#[test]
fn single_group_with_weight_decay_and_column_split_matches_cpu() {
    // A knot-like group (width 6, weight decay) with a per-column split at column 2.
    let ctx = ctx();
    let (rows, width) = (333, 6);
    let cfg = AdamConfig {
        weight_decay: 1e-2,
        ..CFG
    };
    let mut p_cpu = values(rows * width, 9, -1.0, 1.0);
    let mut st = AdamState::new(rows, width);
    let p = buffers::upload(ctx, "p", &p_cpu).unwrap();
    let m = buffers::storage_buffer(ctx, "m", rows * width).unwrap();
    let v = buffers::storage_buffer(ctx, "v", rows * width).unwrap();
    let adam = GpuAdam::new(ctx);
    for t in 1..=5u64 {
        let g = values(rows * width, 20 + t, -0.1, 0.1);
        st.step_by_column(
            &mut p_cpu,
            &g,
            |c| if c < 2 { 3e-3 } else { 1e-4 },
            cfg.weight_decay,
            AdamHyper {
                beta1: cfg.beta1,
                beta2: cfg.beta2,
                eps: cfg.eps,
            },
        );
        let gb = buffers::upload(ctx, "g", &g).unwrap();
        let mut enc = ctx.device.create_command_encoder(&Default::default());
        let step = AdamGroupStep {
            param: &p,
            grad: &gb,
            m: &m,
            v: &v,
            rows,
            width,
            lr_lo: 3e-3,
            lr_hi: 1e-4,
            split_col: 2,
            t,
        };
        adam.encode_group(ctx, &mut enc, &step, cfg).unwrap();
        ctx.queue.submit([enc.finish()]);
    }
    let p_gpu: Vec<f32> = buffers::download(ctx, &p, 0, rows * width).unwrap();
    let e = max_rounding_err(
        &p_gpu,
        &p_cpu,
        &param_scale(&values(rows * width, 9, -1.0, 1.0), 5, 3e-3),
    );
    eprintln!("weight-decay group: {e:.2} ε");
    assert!(e <= 16.0, "{e} ε");
    assert!(
        p_gpu != values(rows * width, 9, -1.0, 1.0),
        "parameters moved"
    );
}

#[test]
fn bad_inputs_are_errors() {
    let ctx = ctx();
    let adam = GpuAdam::new(ctx);
    let small = buffers::storage_buffer(ctx, "small", 4).unwrap();
    let mut enc = ctx.device.create_command_encoder(&Default::default());
    let step = AdamGroupStep {
        param: &small,
        grad: &small,
        m: &small,
        v: &small,
        rows: 2,
        width: 3,
        lr_lo: 1.0,
        lr_hi: 1.0,
        split_col: 0,
        t: 1,
    };
    assert!(adam.encode_group(ctx, &mut enc, &step, CFG).is_err());
    let step = AdamGroupStep {
        rows: 1,
        t: 0,
        ..step
    };
    assert!(adam.encode_group(ctx, &mut enc, &step, CFG).is_err());
    let mut gpu = GpuGaussians::upload(ctx, &gaussians(10, 1), 10).unwrap();
    let grads = GpuGradients::new(ctx, 5).unwrap();
    assert!(
        adam.step_gaussians(ctx, &mut gpu, &grads, &LRS, CFG)
            .is_err()
    );
}

#[test]
fn dispatches_beyond_65535_workgroups_cover_every_element() {
    // 17.1M values > 65535 × 256: the dispatch folds into two dimensions (as the SH group of
    // ~360k Gaussians or more does) and every element must still be updated exactly once.
    let ctx = ctx();
    let len = 65_535 * 256 + 300_001;
    let mut p_cpu = values(len, 31, -1.0, 1.0);
    let g = values(len, 32, -0.1, 0.1);
    let p = buffers::upload(ctx, "p", &p_cpu).unwrap();
    let gb = buffers::upload(ctx, "g", &g).unwrap();
    let m = buffers::storage_buffer(ctx, "m", len).unwrap();
    let v = buffers::storage_buffer(ctx, "v", len).unwrap();
    let mut st = AdamState::new(len, 1);
    let h = AdamHyper {
        beta1: CFG.beta1,
        beta2: CFG.beta2,
        eps: CFG.eps,
    };
    st.step(&mut p_cpu, &g, 1e-3, 0.0, h);
    let mut enc = ctx.device.create_command_encoder(&Default::default());
    let step = AdamGroupStep {
        param: &p,
        grad: &gb,
        m: &m,
        v: &v,
        rows: len,
        width: 1,
        lr_lo: 1e-3,
        lr_hi: 1e-3,
        split_col: 0,
        t: 1,
    };
    GpuAdam::new(ctx)
        .encode_group(ctx, &mut enc, &step, CFG)
        .unwrap();
    ctx.queue.submit([enc.finish()]);
    let out: Vec<f32> = buffers::download(ctx, &p, 0, len).unwrap();
    let scale = param_scale(&values(len, 31, -1.0, 1.0), 1, 1e-3);
    assert!(max_rounding_err(&out, &p_cpu, &scale) <= 16.0);
    // The last element (in the second row of workgroups) moved like the first.
    assert_ne!(out[len - 1], values(len, 31, -1.0, 1.0)[len - 1]);
}

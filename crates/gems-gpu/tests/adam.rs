//! GPU Adam against gems-train's CPU Adam (`AdamState`, as the trainer calls it per group) over
//! several steps.

mod common;

use common::{ctx, gaussians, max_ulps, values};
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

#[test]
fn matches_cpu_adam_of_every_gaussian_group_over_steps() {
    let ctx = ctx();
    // 1000 rows: several workgroups, not a multiple of 256; capacity above len.
    let n = 1000;
    let mut cpu = gaussians(n, 1);
    let mut cpu_adam = GaussianAdam::new(n);
    let mut gpu = GpuGaussians::upload(ctx, &cpu, 1200).unwrap();
    let adam = GpuAdam::new(ctx);
    let steps = 6;
    for s in 0..steps {
        let gr = gradients(n, 100 + s);
        cpu_step(&mut cpu, &mut cpu_adam, &gr);
        let ggr = GpuGradients::upload(ctx, &gr, n).unwrap();
        adam.step_gaussians(ctx, &mut gpu, &ggr, &LRS, CFG).unwrap();
    }
    let out = gpu.download(ctx).unwrap();
    for group in Group::ALL {
        let (a, b) = (group_values(&out, group), group_values(&cpu, group));
        let mom = gpu.moments(ctx, group).unwrap();
        let st = cpu_state(&cpu_adam, group);
        assert_eq!(mom.step, steps);
        let (up, um, uv) = (
            max_ulps(&a, &b),
            max_ulps(&mom.m, &st.m),
            max_ulps(&mom.v, &st.v),
        );
        let dp = common::max_abs_diff(&a, &b);
        eprintln!("{group:?}: params {up} ulp (|Δ| ≤ {dp:e}), m {um} ulp, v {uv} ulp");
        // Same f32 formula and order; a correctly rounded sqrt/division (lavapipe, and Vulkan's
        // precision rules allow ≤ 2.5 ulp for division) or a fused multiply-add can move each
        // step's update by a few ulps of the update, which is ≤ lr ≈ 1e-3·|p| of the parameter:
        // 4 ulps of the moments, 8 of the parameters.
        assert!(um <= 4 && uv <= 4, "{group:?}: moments {um}/{uv} ulp");
        assert!(up <= 8, "{group:?}: parameters {up} ulp apart");
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
    let u = max_ulps(&p_gpu, &p_cpu);
    eprintln!("weight-decay group: {u} ulp");
    assert!(u <= 8, "{u} ulp");
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
    assert!(max_ulps(&out, &p_cpu) <= 8);
    // The last element (in the second row of workgroups) moved like the first.
    assert_ne!(out[len - 1], values(len, 31, -1.0, 1.0)[len - 1]);
}

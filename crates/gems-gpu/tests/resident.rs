//! [`ResidentStep`], the training step resident on the GPU: camera chunks give bit-identical
//! results to one call over all cameras; a step agrees with the same chain run through the
//! engine's host API (upload, render, loss, backward with read-back, regularisers, Adam); and a
//! batch larger than the adapter's binding limit (lavapipe: 128 MiB) is split into chunks
//! instead of failing.

mod common;
#[path = "../../gems-splat/tests/common/mod.rs"]
mod splat_common;

use common::{ctx, max_abs, max_abs_diff};
use gems_gpu::{
    AdamConfig, BlurLoss, GaussianLrs, GpuAdam, GpuGaussians, GpuGradients, GpuRegularizers,
    GpuRenderer, Group, GroupMoments, ResidentStep, StepSettings, buffers,
};
use gems_splat::{Camera, Gaussians, RenderSettings};

fn settings() -> StepSettings {
    StepSettings {
        ssim_lambda: 0.3,
        opacity_reg: 0.01,
        scale_reg: 0.01,
        lrs: GaussianLrs {
            means: 1e-3,
            quats: 1e-3,
            log_scales: 5e-3,
            opacity_logits: 5e-2,
            sh_dc: 2.5e-3,
            sh_rest: 1.25e-4,
        },
        adam: AdamConfig {
            beta1: 0.9,
            beta2: 0.999,
            eps: 1e-15,
            weight_decay: 0.0,
        },
        render: RenderSettings::default(),
    }
}

/// A scene, its cameras and a target: the first camera's render, darkened.
fn scene(n: usize, cams: usize, w: u32, h: u32) -> (Gaussians, Vec<Camera>, Vec<f32>) {
    let (g, cams, bgs) = splat_common::random_scene(11, n, cams, w, h, 1, (-3.0, -1.8));
    let mut r = GpuRenderer::new(ctx());
    let target = r
        .forward(&g, &cams[..1], &bgs[..1], &RenderSettings::default())
        .unwrap()
        .rgb
        .iter()
        .map(|v| 0.8 * v)
        .collect();
    (g, cams, target)
}

fn moment_bits(ms: &[GroupMoments; 5]) -> Vec<u32> {
    ms.iter()
        .flat_map(|m| m.m.iter().chain(&m.v).map(|x| x.to_bits()))
        .collect()
}

#[test]
fn camera_chunks_are_bit_identical_to_one_call() {
    let ctx = ctx();
    let (g, cams, target) = scene(400, 7, 37, 29);
    let s = settings();
    let mut r = GpuRenderer::new(ctx);
    let mut whole = ResidentStep::new(ctx, &g, None).unwrap();
    // 7 cameras in chunks of 3: 3 + 3 + 1, so the carry crosses two boundaries.
    let mut chunked = ResidentStep::new(ctx, &g, None).unwrap();
    chunked.set_max_cameras_per_call(3);
    for step in 0..2 {
        let bg = [0.1, 0.2 * step as f32, 0.3];
        let a = whole.step(&mut r, 0, &target, &cams, bg, &s).unwrap();
        let b = chunked.step(&mut r, 0, &target, &cams, bg, &s).unwrap();
        assert_eq!(chunked.max_cameras_per_call(), 3);
        assert_eq!(a.loss.to_bits(), b.loss.to_bits());
        assert_eq!(a.psnr.to_bits(), b.psnr.to_bits());
        assert_eq!(a.cam_rotation, b.cam_rotation);
        assert_eq!(a.cam_translation, b.cam_translation);
        assert!(max_abs(bytemuck::cast_slice(&a.cam_rotation)) > 0.0);
    }
    let (ga, ma) = whole.download().unwrap();
    let (gb, mb) = chunked.download().unwrap();
    assert_eq!(ga.parameter_bits(), gb.parameter_bits());
    assert_eq!(moment_bits(&ma), moment_bits(&mb));
    assert_ne!(
        ga.parameter_bits(),
        g.parameter_bits(),
        "the step changed the Gaussians"
    );
}

#[test]
fn resident_step_matches_the_host_chain() {
    let ctx = ctx();
    let (g, cams, target) = scene(300, 4, 36, 29);
    let (h, w) = (29usize, 36usize);
    let s = settings();
    let bg = [0.3, 0.1, 0.7];
    let bgs = vec![bg; cams.len()];

    // The host chain: upload, render, loss, backward read back, then the same kernels.
    let mut r = GpuRenderer::new(ctx);
    let loss = BlurLoss::new(ctx, h, w, cams.len(), s.ssim_lambda).unwrap();
    let tb = buffers::upload(ctx, "target", &target).unwrap();
    let batch = r.forward_images(&g, &cams, &bgs, &s.render).unwrap();
    loss.run_batch(ctx, &batch, &tb).unwrap();
    let scalars = loss.read(ctx).unwrap();
    let host = r
        .backward_images(&g, &cams, &bgs, &loss.d_renders_batch(), None)
        .unwrap();
    let mut resident = GpuGaussians::upload(ctx, &g, 0).unwrap();
    let grads = GpuGradients::upload(ctx, &host, 0).unwrap();
    let reg = GpuRegularizers::new(ctx).unwrap();
    let mut enc = ctx.device.create_command_encoder(&Default::default());
    reg.encode(ctx, &mut enc, &resident, &grads, s.opacity_reg, s.scale_reg)
        .unwrap();
    GpuAdam::new(ctx)
        .encode_gaussians(ctx, &mut enc, &mut resident, &grads, &s.lrs, s.adam)
        .unwrap();
    ctx.queue.submit([enc.finish()]);
    let reg_value = reg.read(ctx).unwrap();
    let expected = resident.download(ctx).unwrap();

    // The resident step: nothing but the cameras goes up after the first upload.
    let mut step = ResidentStep::new(ctx, &g, None).unwrap();
    let out = step.step(&mut r, 0, &target, &cams, bg, &s).unwrap();
    let (got, moments) = step.download().unwrap();
    // Same kernels on the same inputs: the same bits (the renderer packs on the GPU instead of
    // the CPU, a pure copy).
    assert_eq!(out.loss.to_bits(), (scalars.loss + reg_value).to_bits());
    assert_eq!(out.photometric_loss.to_bits(), scalars.loss.to_bits());
    assert_eq!(out.psnr.to_bits(), scalars.psnr.to_bits());
    assert_eq!(out.cam_rotation, host.cam_rotation);
    assert_eq!(out.cam_translation, host.cam_translation);
    assert_eq!(got.parameter_bits(), expected.parameter_bits());
    for (group, m) in Group::ALL.into_iter().zip(&moments) {
        assert_eq!(m, &resident.moments(ctx, group).unwrap(), "{group:?}");
    }
    assert!(max_abs_diff(&got.opacity_logits, &g.opacity_logits) > 0.0);
}

/// The GeMS batch at the benchmark's size: 100k Gaussians, 15 cameras of 400×270. On lavapipe
/// (128 MiB per binding) one call needs about 175 MiB of per-entry gradients, so the step
/// splits the cameras; on an adapter with larger bindings it runs in one call.
#[test]
fn a_batch_over_the_binding_limit_is_split_into_camera_chunks() {
    let ctx = ctx();
    let (g, cams, bgs) = splat_common::random_scene(1, 100_000, 15, 400, 270, 3, (-4.6, -3.2));
    let target = vec![0.5f32; 400 * 270 * 3];
    let mut r = GpuRenderer::new(ctx);
    let mut step = ResidentStep::new(ctx, &g, None).unwrap();
    let out = step
        .step(&mut r, 0, &target, &cams, bgs[0], &settings())
        .unwrap();
    let limit = ctx.limits.max_storage_buffer_binding_size;
    eprintln!(
        "binding limit {} MiB: {} cameras per call",
        limit >> 20,
        step.max_cameras_per_call().min(15)
    );
    if limit <= 128 << 20 {
        assert!(step.max_cameras_per_call() < 15);
    }
    assert!(out.loss.is_finite() && out.psnr.is_finite());
    assert_eq!(out.cam_rotation.len(), 15);
    assert!(out.cam_translation.iter().flatten().all(|v| v.is_finite()));
}

/// A step on a profiled context times every kernel it runs (renderer, loss, backward, Adam)
/// and gives the same bits as on the plain context.
#[test]
fn profiled_step_times_every_kernel_and_changes_no_bit() {
    let ctx = ctx();
    assert!(
        ctx.timestamps,
        "{} cannot time compute passes: the profiler's test needs TIMESTAMP_QUERY",
        ctx.adapter
    );
    assert!(ctx.kernel_times().is_none(), "no profiler unless asked");
    let profiled = ctx.with_profiler().unwrap();
    let (g, cams, target) = scene(400, 5, 37, 29);
    let s = settings();
    let bg = [0.2, 0.3, 0.4];
    let run = |c: &gems_gpu::GpuContext| {
        let mut r = GpuRenderer::new(c);
        let mut step = ResidentStep::new(c, &g, None).unwrap();
        let out = step.step(&mut r, 0, &target, &cams, bg, &s).unwrap();
        (out, step.download().unwrap().0)
    };
    let (plain, g_plain) = run(ctx);
    let (timed, g_timed) = run(&profiled);
    assert_eq!(plain.loss.to_bits(), timed.loss.to_bits());
    assert_eq!(plain.cam_rotation, timed.cam_rotation);
    assert_eq!(g_plain.parameter_bits(), g_timed.parameter_bits());

    let times = profiled.kernel_times().unwrap().unwrap();
    eprintln!("{}", times.table());
    for kernel in [
        "project_forward",
        "rasterize_forward",
        "blur_mean",
        "rasterize_backward",
        "project_backward",
        "adam",
    ] {
        let k = times
            .kernels
            .iter()
            .find(|k| k.kernel.starts_with(kernel))
            .unwrap_or_else(|| panic!("{kernel} not timed:\n{}", times.table()));
        assert!(k.dispatches >= 1 && k.seconds >= 0.0, "{k:?}");
    }
    assert!(times.total_seconds() > 0.0, "{}", times.table());
    assert_eq!(times.untimed_passes, 0);
    // What was read is cleared: nothing ran since.
    let again = profiled.kernel_times().unwrap().unwrap();
    assert!(again.kernels.is_empty(), "{again:?}");
}

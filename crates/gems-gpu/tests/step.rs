//! One GeMS training step with every image-sized quantity on the GPU — render the n virtual
//! views (GpuRenderer), blur mean + fused loss + dL/d(render_k) (BlurLoss), backward
//! (GpuRenderer), Adam (GpuAdam) on resident Gaussians — against the CPU chain of gems-train
//! (Renderer, blur mean, TrainingLoss, backward with d/n, AdamState).

#![allow(clippy::needless_range_loop)]

mod common;
#[path = "../../gems-splat/tests/common/mod.rs"]
mod splat_common;

use common::{ctx, max_abs, max_abs_diff, max_rounding_err};
use gems_gpu::{
    AdamConfig, BlurLoss, GaussianLrs, GpuAdam, GpuGaussians, GpuGradients, GpuRenderer, buffers,
};
use gems_splat::{RenderSettings, Renderer};
use gems_train::adam::AdamHyper;
use gems_train::adam::GaussianAdam;

#[test]
fn gpu_step_matches_the_cpu_chain() {
    let ctx = ctx();
    let (h, w, n, lambda) = (29u32, 36u32, 4usize, 0.3f32);
    let (g, cams, bgs) = splat_common::random_scene(5, 120, n, w, h, 1, (-3.0, -1.8));
    let len = (h * w * 3) as usize;
    // The target: the scene rendered from the first camera, darkened.
    let mut cpu_r = Renderer::new();
    let s = RenderSettings::default();
    let target: Vec<f32> = cpu_r
        .forward(&g, &cams[..1], &bgs[..1], &s)
        .unwrap()
        .rgb
        .iter()
        .map(|v| 0.8 * v)
        .collect();

    // CPU chain (gems-train blur.rs + TrainingLoss).
    let rgb = cpu_r.forward(&g, &cams, &bgs, &s).unwrap().rgb;
    let inv_n = 1.0 / n as f32;
    let mut blurred = vec![0.0f32; len];
    for view in rgb.chunks_exact(len) {
        for (b, v) in blurred.iter_mut().zip(view) {
            *b += v * inv_n;
        }
    }
    let mut d_blurred = vec![0.0; len];
    let cpu_loss = gems_metrics::TrainingLoss::new(h as usize, w as usize, lambda)
        .unwrap()
        .compute(&blurred, &target, &mut d_blurred)
        .unwrap();
    let d_rgb: Vec<f32> = (0..n)
        .flat_map(|_| d_blurred.iter().map(|d| d * inv_n))
        .collect();
    let cpu_grads = cpu_r.backward(&g, &cams, &bgs, &d_rgb, None).unwrap();

    // GPU chain: the renders and their gradient never leave the GPU.
    let mut gpu_r = GpuRenderer::new(ctx);
    let loss = BlurLoss::new(ctx, h as usize, w as usize, n, lambda).unwrap();
    let tb = buffers::upload(ctx, "target", &target).unwrap();
    let batch = gpu_r.forward_images(&g, &cams, &bgs, &s).unwrap();
    loss.run_batch(ctx, &batch, &tb).unwrap();
    let scalars = loss.read(ctx).unwrap();
    let wrong = gems_gpu::ImageBatch {
        count: n - 1,
        ..batch
    };
    assert!(loss.run_batch(ctx, &wrong, &tb).is_err());
    let gpu_grads = gpu_r
        .backward_images(&g, &cams, &bgs, &loss.d_renders_batch(), None)
        .unwrap();

    // The renderer's images match the CPU's to 1e-4 (its parity tolerance); the loss then
    // differs by at most that much times its Lipschitz constant (≤ 1 per value for L1 and SSIM).
    eprintln!("loss gpu {} cpu {}", scalars.loss, cpu_loss.loss);
    assert!((scalars.loss - cpu_loss.loss).abs() < 1e-4);
    let gpu_blurred: Vec<f32> = buffers::download(ctx, loss.blurred(), 0, len).unwrap();
    assert!(max_abs_diff(&gpu_blurred, &blurred) < 1e-4);
    // Gaussian and pose gradients: the two chains agree to ≤ 5e-6 of each group's largest
    // entry on lavapipe; 1e-4 is the renderer's own parity tolerance for images.
    let close = |what: &str, a: &[f32], b: &[f32]| {
        let scale = max_abs(b).max(1e-12);
        let d = max_abs_diff(a, b);
        eprintln!("{what}: max |gpu − cpu| = {d:e} of max {scale:e}");
        assert!(d <= 1e-4 * scale, "{what}: {d} vs scale {scale}");
    };
    close(
        "means",
        bytemuck::cast_slice(&gpu_grads.means),
        bytemuck::cast_slice(&cpu_grads.means),
    );
    close(
        "opacity",
        &gpu_grads.opacity_logits,
        &cpu_grads.opacity_logits,
    );
    close(
        "sh",
        bytemuck::cast_slice(&gpu_grads.sh),
        bytemuck::cast_slice(&cpu_grads.sh),
    );
    close(
        "pose R",
        bytemuck::cast_slice(&gpu_grads.cam_rotation),
        bytemuck::cast_slice(&cpu_grads.cam_rotation),
    );

    // Adam on the resident Gaussians with the GPU gradients, against the CPU Adam with the same
    // gradients: the same update up to the rounding Vulkan allows (see tests/adam.rs), so any
    // larger difference is the chain's.
    let lrs = GaussianLrs {
        means: 1e-3,
        quats: 1e-3,
        log_scales: 5e-3,
        opacity_logits: 5e-2,
        sh_dc: 2.5e-3,
        sh_rest: 1.25e-4,
    };
    let cfg = AdamConfig {
        beta1: 0.9,
        beta2: 0.999,
        eps: 1e-15,
        weight_decay: 0.0,
    };
    let mut resident = GpuGaussians::upload(ctx, &g, 0).unwrap();
    let grads = GpuGradients::upload(ctx, &gpu_grads, 0).unwrap();
    GpuAdam::new(ctx)
        .step_gaussians(ctx, &mut resident, &grads, &lrs, cfg)
        .unwrap();
    let stepped = resident.download(ctx).unwrap();
    let mut cpu_g = g.clone();
    let mut a = GaussianAdam::new(g.len());
    let hy = AdamHyper {
        beta1: cfg.beta1,
        beta2: cfg.beta2,
        eps: cfg.eps,
    };
    a.opacity_logits.step(
        &mut cpu_g.opacity_logits,
        &gpu_grads.opacity_logits,
        lrs.opacity_logits,
        0.0,
        hy,
    );
    // One step moves a parameter by exactly lr·sign(g) up to rounding: its scale is |p| + lr.
    let scale: Vec<f32> = g
        .opacity_logits
        .iter()
        .map(|p| p.abs() + lrs.opacity_logits)
        .collect();
    let e = max_rounding_err(&stepped.opacity_logits, &cpu_g.opacity_logits, &scale);
    eprintln!("Adam step of the opacity logits: {e:.2} ε");
    assert!(e <= 16.0, "{e} ε");
    assert_ne!(stepped.opacity_logits, g.opacity_logits);
}

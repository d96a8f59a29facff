//! The GPU training-step kernels next to the CPU code they replace, in one run: the blur mean +
//! fused loss + gradient at 400×270 with n = 15 views, Adam over 100k Gaussians, MCMC noise over
//! 100k, and the once-per-refine-period MCMC round trip (download opacities, CPU draws, GPU
//! relocation + growth). Each GPU sample submits and waits for completion. The adapter is
//! printed first (lavapipe on machines without a GPU); with none the bench stops with a message.

use std::sync::OnceLock;

use gems_gpu::{
    AdamConfig, BlurLoss, GaussianLrs, GpuAdam, GpuContext, GpuGaussians, GpuGradients, GpuMcmc,
    NoiseParams, buffers,
};
use gems_splat::Gaussians;
use gems_train::adam::{AdamHyper, GaussianAdam};
use gems_train::mcmc::{
    BinomialTable, add_new, growth_draws, inject_noise, relocate_dead, relocation_draws,
};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn main() {
    eprintln!("GPU benches on {}", ctx().adapter);
    divan::main();
}

const H: usize = 270;
const W: usize = 400;
const VIEWS: usize = 15;
const N: usize = 100_000;
const MIN_OPACITY: f32 = 0.005;

fn ctx() -> &'static GpuContext {
    static CTX: OnceLock<GpuContext> = OnceLock::new();
    CTX.get_or_init(|| {
        GpuContext::new().unwrap_or_else(|e| {
            panic!("no GPU adapter ({e}); install mesa-vulkan-drivers and set WGPU_BACKEND=vulkan")
        })
    })
}

fn image(seed: u64, len: usize) -> Vec<f32> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..len).map(|_| rng.random::<f32>()).collect()
}

/// 100k Gaussians; about 10 % below the MCMC opacity threshold (dead).
fn scene() -> Gaussians {
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let mut g = Gaussians::with_degree(3);
    for _ in 0..N {
        let sh = std::array::from_fn(|_| std::array::from_fn(|_| rng.random::<f32>() - 0.5));
        let l = if rng.random::<f32>() < 0.1 {
            -7.0
        } else {
            rng.random::<f32>() * 6.0 - 3.0
        };
        g.push(
            std::array::from_fn(|_| rng.random::<f32>() * 4.0 - 2.0),
            std::array::from_fn(|_| rng.random::<f32>()),
            std::array::from_fn(|_| rng.random::<f32>() * 3.0 - 6.0),
            l,
            sh,
        );
    }
    g
}

fn gradients(g: &Gaussians) -> gems_splat::Gradients {
    gems_splat::Gradients {
        means: g.means.iter().map(|m| m.map(|v| v * 1e-3)).collect(),
        quats: g.quats.iter().map(|q| q.map(|v| v * 1e-4)).collect(),
        log_scales: g.log_scales.iter().map(|s| s.map(|v| v * 1e-3)).collect(),
        opacity_logits: g.opacity_logits.iter().map(|v| v * 1e-3).collect(),
        sh: g.sh.clone(),
        ..Default::default()
    }
}

const LRS: GaussianLrs = GaussianLrs {
    means: 1.6e-4,
    quats: 1e-3,
    log_scales: 5e-3,
    opacity_logits: 5e-2,
    sh_dc: 2.5e-3,
    sh_rest: 1.25e-4,
};
const CFG: AdamConfig = AdamConfig {
    beta1: 0.9,
    beta2: 0.999,
    eps: 1e-15,
    weight_decay: 0.0,
};

mod loss_400x270_n15 {
    use super::*;

    #[divan::bench]
    fn gpu(b: divan::Bencher) {
        let ctx = ctx();
        let loss = BlurLoss::new(ctx, H, W, VIEWS, 0.3).unwrap();
        let r = buffers::upload(ctx, "renders", &image(1, H * W * 3 * VIEWS)).unwrap();
        let t = buffers::upload(ctx, "target", &image(2, H * W * 3)).unwrap();
        b.bench_local(|| {
            loss.run(ctx, &r, &t).unwrap();
            // The only per-step readback: the four scalars.
            loss.read(ctx).unwrap()
        });
    }

    /// gems-train's CPU path: blur mean, TrainingLoss::compute, dL/d(render_k) = d/n.
    #[divan::bench]
    fn cpu(b: divan::Bencher) {
        let renders = image(1, H * W * 3 * VIEWS);
        let target = image(2, H * W * 3);
        let mut loss = gems_metrics::TrainingLoss::new(H, W, 0.3).unwrap();
        let (mut blurred, mut d) = (vec![0.0f32; H * W * 3], vec![0.0f32; H * W * 3]);
        let mut d_rgb = Vec::with_capacity(renders.len());
        b.bench_local(|| {
            blurred.fill(0.0);
            let inv = 1.0 / VIEWS as f32;
            for view in renders.chunks_exact(H * W * 3) {
                for (o, v) in blurred.iter_mut().zip(view) {
                    *o += v * inv;
                }
            }
            let v = loss.compute(&blurred, &target, &mut d).unwrap();
            d_rgb.clear();
            for _ in 0..VIEWS {
                d_rgb.extend(d.iter().map(|x| x * inv));
            }
            v
        });
    }
}

mod adam_100k {
    use super::*;

    #[divan::bench]
    fn gpu(b: divan::Bencher) {
        let ctx = ctx();
        let g = scene();
        let mut gpu = GpuGaussians::upload(ctx, &g, N).unwrap();
        let grads = GpuGradients::upload(ctx, &gradients(&g), N).unwrap();
        let adam = GpuAdam::new(ctx);
        b.bench_local(|| {
            adam.step_gaussians(ctx, &mut gpu, &grads, &LRS, CFG)
                .unwrap();
            buffers::wait_idle(ctx).unwrap();
        });
    }

    /// The CPU trainer's Adam on every group (rayon).
    #[divan::bench]
    fn cpu(b: divan::Bencher) {
        let mut g = scene();
        let gr = gradients(&g);
        let mut a = GaussianAdam::new(N);
        let h = AdamHyper {
            beta1: CFG.beta1,
            beta2: CFG.beta2,
            eps: CFG.eps,
        };
        b.bench_local(|| a.step(&mut g, &gr, &LRS, h));
    }
}

mod mcmc_noise_100k {
    use super::*;

    #[divan::bench]
    fn gpu(b: divan::Bencher) {
        let ctx = ctx();
        let gpu = GpuGaussians::upload(ctx, &scene(), N).unwrap();
        let mcmc = GpuMcmc::new(ctx).unwrap();
        let mut step = 0;
        b.bench_local(|| {
            step += 1;
            let p = NoiseParams {
                seed: 7,
                step,
                scale: 1e-4,
                min_opacity: MIN_OPACITY,
            };
            let mut enc = ctx.device.create_command_encoder(&Default::default());
            mcmc.encode_noise(ctx, &mut enc, &gpu, &p);
            ctx.queue.submit([enc.finish()]);
            buffers::wait_idle(ctx).unwrap();
        });
    }

    /// gems-train's inject_noise (serial ChaCha8 draws).
    #[divan::bench]
    fn cpu(b: divan::Bencher) {
        let mut g = scene();
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        b.bench_local(|| inject_noise(&mut g, 1e-4, MIN_OPACITY, &mut rng));
    }
}

/// One refine period's MCMC (relocation of the ~10 % dead + 5 % growth) from 100k Gaussians.
mod mcmc_refine_100k {
    use super::*;

    /// The documented round trip: download 100k opacity logits, CPU draws, upload the rows,
    /// relocate and grow on the GPU. The container is re-uploaded outside the timed part.
    #[divan::bench(sample_count = 20)]
    fn gpu_round_trip(b: divan::Bencher) {
        let ctx = ctx();
        let g = scene();
        let mcmc = GpuMcmc::new(ctx).unwrap();
        let mut seed = 0;
        b.with_inputs(|| {
            let gpu = GpuGaussians::upload(ctx, &g, 2 * N).unwrap();
            buffers::wait_idle(ctx).unwrap();
            gpu
        })
        .bench_local_values(|mut gpu| {
            seed += 1;
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            let logits = mcmc.download_opacity_logits(ctx, &gpu).unwrap();
            let (dead, src) = relocation_draws(&logits, MIN_OPACITY, &mut rng);
            mcmc.relocate(ctx, &mut gpu, &dead, &src, MIN_OPACITY)
                .unwrap();
            let logits = mcmc.download_opacity_logits(ctx, &gpu).unwrap();
            let src = growth_draws(&logits, 1_000_000, 1.05, &mut rng);
            mcmc.grow(ctx, &mut gpu, &src, MIN_OPACITY).unwrap();
            buffers::wait_idle(ctx).unwrap();
            gpu
        });
    }

    /// Only the transfer part of the round trip: 100k opacity logits down (400 KB).
    #[divan::bench]
    fn gpu_download_opacities(b: divan::Bencher) {
        let ctx = ctx();
        let gpu = GpuGaussians::upload(ctx, &scene(), N).unwrap();
        let mcmc = GpuMcmc::new(ctx).unwrap();
        b.bench_local(|| mcmc.download_opacity_logits(ctx, &gpu).unwrap());
    }

    /// gems-train's relocate_dead + add_new on the CPU.
    #[divan::bench(sample_count = 20)]
    fn cpu(b: divan::Bencher) {
        let g = scene();
        let bt = BinomialTable::default();
        let mut seed = 0;
        b.with_inputs(|| (g.clone(), GaussianAdam::new(N)))
            .bench_local_values(|(mut g, mut a)| {
                seed += 1;
                let mut rng = ChaCha8Rng::seed_from_u64(seed);
                relocate_dead(&mut g, &mut a, MIN_OPACITY, &bt, &mut rng);
                add_new(&mut g, &mut a, 1_000_000, 1.05, MIN_OPACITY, &bt, &mut rng);
                (g, a)
            });
    }
}

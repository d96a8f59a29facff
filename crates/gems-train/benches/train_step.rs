//! Seconds per training step at 400×270 with 100k Gaussians and n = 15 virtual cameras
//! (render 15 views in one call, mean, fused loss, backward through the blur model, Adam on
//! every group, pose accumulation, SGLD noise). MCMC refinement is outside the timed window
//! (cap_max = N, so growth is a no-op; relocation runs only every 100 steps in the defaults).
//!
//! The count of virtual views is held fixed (`virtual_view_spacing_px = 0`); `…_fewer_views` runs
//! the CPU step with 1, 5 and 10; `…_backward_subset` backpropagates through 3, 5 or 8 of the 15.
//! `step_…` runs the CPU engine; `gpu_step_…` the same trainer on
//! the GPU engine (any adapter, lavapipe included: `WGPU_BACKEND=vulkan`), whose step is resident
//! (gems-gpu `ResidentStep`); its first step, which uploads the Gaussians and the image, is outside
//! the timed window. `…_workgroup_reduction` forces the backward rasterizer without subgroups;
//! `…_kernels` times one step's kernels with GPU timestamps and prints them.

use gems_gpu::DeviceChoice;
use gems_gpu::{Engine, GpuRenderer};
use gems_math::Intrinsics;
use gems_math::{Se3, Vector6};
use gems_splat::{Camera, Gaussians, RenderSettings, Renderer};
use gems_train::Normalization;
use gems_train::TrainConfig;
use gems_train::{TrainInput, TrainState, TrainView, Trainer};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn main() {
    divan::main();
}

const N: usize = 100_000;

fn scene() -> Gaussians {
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let mut g = Gaussians::with_degree(3);
    for _ in 0..N {
        let m = [
            (rng.random::<f32>() - 0.5) * 4.0,
            (rng.random::<f32>() - 0.5) * 3.0,
            2.0 + rng.random::<f32>() * 2.0,
        ];
        let mut sh = [[0.0f32; 3]; 16];
        for c in &mut sh {
            *c = std::array::from_fn(|_| (rng.random::<f32>() - 0.5) * 0.3);
        }
        let s = (0.005 + 0.02 * rng.random::<f32>()).ln();
        g.push(
            m,
            std::array::from_fn(|_| rng.random::<f32>()),
            [s; 3],
            0.0,
            sh,
        );
    }
    g
}

/// The trainer at step 3001 of 7000 rendering `views` virtual views every step (the count held
/// fixed: this view's path is a point, so counts following the blur would render one).
fn trainer_with_views(views: usize) -> Trainer {
    trainer_with(views, 0)
}

/// The trainer rendering `views` virtual views and backpropagating through `backward` of them
/// (`TrainConfig::backward_virtual_views`; 0 = all).
fn trainer_with(views: usize, backward: usize) -> Trainer {
    let g = scene();
    let k = Intrinsics {
        fx: 360.0,
        fy: 360.0,
        cx: 200.0,
        cy: 135.0,
        width: 400,
        height: 270,
    };
    let c2w = Se3::exp(&Vector6::zeros());
    let target = Renderer::new()
        .forward(
            &g,
            &[Camera::from_c2w(&k, &c2w)],
            &[[0.0; 3]],
            &RenderSettings::default(),
        )
        .unwrap()
        .rgb;
    let mut cfg = TrainConfig {
        steps: 7000,
        num_virtual_views: views,
        virtual_view_spacing_px: 0.0,
        backward_virtual_views: backward,
        ..TrainConfig::default()
    };
    cfg.mcmc.cap_max = N;
    let view = TrainView {
        name: "bench".into(),
        image: target,
        intrinsics: k,
        c2w_init: c2w * Se3::exp(&Vector6::from_element(1e-3)),
        c2w_gt: None,
        c2w_gt_subframes: Vec::new(),
    };
    let input = TrainInput {
        views: vec![view],
        gaussians: g,
        normalization: Normalization::identity(),
        scene_scale: 1.0,
        init_label: "bench".into(),
    };
    let mut fresh = Trainer::new(cfg.clone(), input).unwrap();
    // Start past the SH ramp (all 16 coefficients active, as in most of a run), off a refine step.
    let state = TrainState {
        step: 3001,
        ..fresh.state().unwrap().clone()
    };
    Trainer::from_state(
        cfg,
        fresh.views().to_vec(),
        Normalization::identity(),
        1.0,
        "bench".into(),
        state,
    )
    .unwrap()
}

fn trainer() -> Trainer {
    trainer_with_views(15)
}

#[divan::bench(sample_count = 3, sample_size = 1)]
fn step_400x270_100k_n15(bencher: divan::Bencher) {
    let mut t = trainer();
    bencher.bench_local(|| t.step().unwrap());
}

/// The same step with fewer virtual views, as `virtual_view_spacing_px` chooses for photos with
/// less blur: what a step costs besides its renders.
#[divan::bench(args = [1, 5, 10], sample_count = 3, sample_size = 1)]
fn step_400x270_100k_fewer_views(bencher: divan::Bencher, views: usize) {
    let mut t = trainer_with_views(views);
    bencher.bench_local(|| t.step().unwrap());
}

/// The n = 15 step backpropagating through one view in each of `backward` runs of the
/// exposure (`TrainConfig::backward_virtual_views`): what the stochastic backward saves.
#[divan::bench(args = [3, 5, 8], sample_count = 3, sample_size = 1)]
fn step_400x270_100k_n15_backward_subset(bencher: divan::Bencher, backward: usize) {
    let mut t = trainer_with(15, backward);
    bencher.bench_local(|| t.step().unwrap());
}

#[divan::bench(sample_count = 3, sample_size = 1)]
fn gpu_step_400x270_100k_n15(bencher: divan::Bencher) {
    let engine = Engine::select(DeviceChoice::Gpu).expect("a GPU adapter");
    gpu_step(bencher, engine);
}

/// The GPU step with the workgroup-memory backward rasterizer even where the adapter has
/// subgroups (gems-gpu `GpuContext::without_subgroups`), for the ratio.
#[divan::bench(sample_count = 3, sample_size = 1)]
fn gpu_step_400x270_100k_n15_workgroup_reduction(bencher: divan::Bencher) {
    let ctx = gems_gpu::select(DeviceChoice::Gpu)
        .expect("a GPU adapter")
        .expect("a context");
    let engine = Engine::Gpu(Box::new(GpuRenderer::new(&ctx.without_subgroups())));
    gpu_step(bencher, engine);
}

/// One GPU step with a GPU timestamp around every kernel (gems-gpu
/// `GpuContext::with_profiler`): prints where the step's GPU time goes, slowest kernel first,
/// and the step's wall time beside the kernels' sum (the difference is the host's work and the
/// GPU waiting for it: uploads, readbacks, the CPU's share of the step).
#[divan::bench(sample_count = 1, sample_size = 1)]
fn gpu_step_400x270_100k_n15_kernels(bencher: divan::Bencher) {
    let ctx = gems_gpu::select(DeviceChoice::Gpu)
        .expect("a GPU adapter")
        .expect("a context")
        .with_profiler()
        .expect("an adapter that can time compute passes");
    let mut t = trainer();
    t.set_engine(Engine::Gpu(Box::new(GpuRenderer::new(&ctx))));
    t.step().unwrap();
    // The first step's uploads and pipeline warm-up are not the step's.
    let _ = ctx.kernel_times();
    let mut wall = std::time::Duration::ZERO;
    bencher.bench_local(|| {
        let start = std::time::Instant::now();
        t.step().unwrap();
        wall = start.elapsed();
    });
    let times = ctx.kernel_times().unwrap().unwrap();
    println!("{}\n{}", ctx.adapter, times.table());
    println!(
        "step wall {:.2} ms; kernels {:.2} ms; the rest (host, transfers, idle GPU) {:.2} ms",
        wall.as_secs_f64() * 1e3,
        times.total_seconds() * 1e3,
        (wall.as_secs_f64() - times.total_seconds()) * 1e3
    );
}

fn gpu_step(bencher: divan::Bencher, engine: Engine) {
    let mut t = trainer();
    println!("{}", engine.describe());
    t.set_engine(engine);
    t.step().unwrap();
    bencher.bench_local(|| t.step().unwrap());
}

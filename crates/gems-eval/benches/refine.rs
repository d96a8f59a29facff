//! Cost of test-time pose refinement (100 forward+backward renders per view, 1 final render).
//!
//! `refine_100_steps_128x96_2k_gaussians` runs the CPU engine on a small scene. The `*_100k`
//! benches run 100k Gaussians at 400×270: the CPU engine; the GPU engine through
//! [`gems_gpu::FrozenScene`] (Gaussians resident, what the evaluation runs); and, for the
//! ratio, the same 100 steps through `Engine::forward`/`backward`, which upload every Gaussian
//! and read every gradient back per step (what the evaluation ran before). The GPU benches
//! need an adapter (`WGPU_BACKEND=vulkan`; on a software one such as lavapipe they take
//! minutes).

use gems_gpu::{DeviceChoice, Engine};
use gems_math::{Intrinsics, Se3, Vector6};
use gems_splat::{Camera, Gaussians, RenderSettings};

fn main() {
    divan::main();
}

#[divan::bench(sample_count = 3)]
fn refine_100_steps_128x96_2k_gaussians(bencher: divan::Bencher) {
    refine_bench(bencher, Engine::cpu(), 2000, 128, 96);
}

#[divan::bench(sample_count = 3)]
fn cpu_refine_100_steps_400x270_100k(bencher: divan::Bencher) {
    refine_bench(bencher, Engine::cpu(), 100_000, 400, 270);
}

#[divan::bench(sample_count = 3)]
fn gpu_refine_100_steps_400x270_100k(bencher: divan::Bencher) {
    refine_bench(bencher, gpu(), 100_000, 400, 270);
}

/// 100 forward + backward renders through `Engine::forward`/`backward` and one more render,
/// as the evaluation's refinement ran before `FrozenScene` (Adam on six numbers left out).
#[divan::bench(sample_count = 3)]
fn gpu_upload_each_step_100_steps_400x270_100k(bencher: divan::Bencher) {
    let (g, k, c2w) = scene(100_000, 400, 270);
    let mut engine = gpu();
    let cam = Camera::from_c2w(&k, &c2w);
    let s = RenderSettings::default();
    let d_rgb = vec![1e-6f32; 400 * 270 * 3];
    bencher.bench_local(|| {
        for _ in 0..100 {
            engine.forward(&g, &[cam], &[[0.0; 3]], &s).unwrap();
            engine
                .backward(&g, &[cam], &[[0.0; 3]], &d_rgb, None)
                .unwrap();
        }
        engine.forward(&g, &[cam], &[[0.0; 3]], &s).unwrap()
    });
}

fn gpu() -> Engine {
    let engine = Engine::select(DeviceChoice::Gpu).expect("a GPU adapter");
    println!("{}", engine.describe());
    engine
}

/// One view's refinement from a slightly perturbed pose (the Gaussians frozen once per view,
/// as the evaluation freezes them once per split).
fn refine_bench(bencher: divan::Bencher, mut engine: Engine, n: usize, w: u32, h: u32) {
    let (g, k, c2w) = scene(n, w, h);
    let mut frozen = engine.freeze(&g).unwrap();
    let gt = gems_eval::refine::render(&mut frozen, &c2w, &k).unwrap();
    drop(frozen);
    let start = c2w * Se3::exp(&Vector6::from([0.01, -0.01, 0.0, 0.0, 0.01, 0.0]));
    bencher.bench_local(|| {
        let mut frozen = engine.freeze(&g).unwrap();
        gems_eval::refine_pose(
            &mut frozen,
            &start,
            &k,
            &gt,
            &gems_eval::PoseRefineConfig::default(),
        )
        .unwrap()
    });
}

/// `n` Gaussians in a 4×3×2 box 6 units in front of a `w`×`h` camera, sized so that the
/// 100k scene covers the image about as densely as the 2k one (log-scale −2.5 at 2k).
fn scene(n: usize, w: u32, h: u32) -> (Gaussians, Intrinsics, Se3) {
    let mut g = Gaussians::with_degree(0);
    let log_scale = -2.5 - 0.5 * (n as f32 / 2000.0).ln() / 3.0;
    for i in 0..n as u32 {
        let f = |s: u32| {
            ((i.wrapping_mul(2654435761)
                .wrapping_add(s.wrapping_mul(40503))
                >> 8) as f32
                / (1u32 << 24) as f32)
                - 0.5
        };
        let mut sh = [[0.0f32; 3]; 16];
        sh[0] = [f(4) * 3.0, f(5) * 3.0, f(6) * 3.0];
        g.push(
            [f(1) * 4.0, f(2) * 3.0, f(3) * 2.0],
            [1.0, 0.0, 0.0, 0.0],
            [log_scale; 3],
            1.0,
            sh,
        );
    }
    let k = Intrinsics {
        fx: 110.0 * w as f64 / 128.0,
        fy: 110.0 * w as f64 / 128.0,
        cx: w as f64 / 2.0,
        cy: h as f64 / 2.0,
        width: w,
        height: h,
    };
    let c2w = gems_math::look_at_c2w(
        &gems_math::Vector3::new(0.0, 0.0, -6.0),
        &gems_math::Vector3::zeros(),
        &gems_math::Vector3::new(0.0, -1.0, 0.0),
    )
    .unwrap();
    (g, k, c2w)
}

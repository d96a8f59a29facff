//! Forward and forward+backward of 15 cameras at 400×270 (the GeMS blur model's batch) with
//! 10k, 100k and 300k Gaussians, on the GPU engine with the Gaussians resident
//! (`ResidentStep::render` / `backpropagate`: what a training step runs, split into camera
//! chunks where one call would exceed the adapter's binding limit) and, in the same run, on the
//! CPU engine.
//!
//! `cargo bench -p gems-gpu --bench render` runs every size; a filter such as `-- 10000` runs
//! fewer (it also matches 100000; the larger sizes take minutes on a software adapter such as
//! Mesa lavapipe). The GPU adapter and the cameras per call are printed; figures in
//! BENCHMARKS.md.

#[path = "../../gems-splat/tests/common/mod.rs"]
mod common;

use divan::Bencher;
use gems_gpu::{DeviceChoice, GpuContext, GpuRenderer, ResidentStep, buffers};
use gems_splat::{Camera, Gaussians, RenderSettings, Renderer};

const SIZES: &[usize] = &[10_000, 100_000, 300_000];
const CAMERAS: usize = 15;

fn main() {
    println!("GPU adapter: {}", context().adapter);
    divan::main();
}

fn scene(n: usize) -> (Gaussians, Vec<Camera>, Vec<[f32; 3]>) {
    common::random_scene(1, n, CAMERAS, 400, 270, 3, (-4.6, -3.2))
}

fn context() -> GpuContext {
    gems_gpu::select(DeviceChoice::Gpu)
        .expect("a GPU adapter (install mesa-vulkan-drivers for lavapipe)")
        .expect("a context")
}

/// The engine and the scene resident on it, after one warm-up render (which also settles the
/// cameras per call). `subgroups: false` compiles the workgroup-memory backward rasterizer
/// even where the adapter has subgroups.
fn resident(
    n: usize,
    subgroups: bool,
) -> (
    GpuContext,
    GpuRenderer,
    ResidentStep,
    Vec<Camera>,
    Vec<[f32; 3]>,
) {
    let (g, cams, bgs) = scene(n);
    let ctx = if subgroups {
        context()
    } else {
        context().without_subgroups()
    };
    let mut r = GpuRenderer::new(&ctx);
    let mut step = ResidentStep::new(&ctx, &g, None).unwrap();
    let s = RenderSettings::default();
    let d_rgb = buffers::upload(&ctx, "dL/dRGB", &vec![1e-3f32; CAMERAS * 400 * 270 * 3]).unwrap();
    step.render(&mut r, &cams, &bgs, &s).unwrap();
    step.backpropagate(&mut r, &cams, &bgs, &d_rgb, &s).unwrap();
    println!(
        "{n} Gaussians: {} cameras per call; subgroup backward: {}; GPU buffers after a \
         forward+backward: {} MiB",
        step.max_cameras_per_call().min(CAMERAS),
        ctx.subgroups,
        (r.allocated_bytes() + step.allocated_bytes()) >> 20
    );
    (ctx, r, step, cams, bgs)
}

#[divan::bench(args = SIZES, sample_count = 3, sample_size = 1)]
fn gpu_forward(bencher: Bencher, n: usize) {
    let (ctx, mut r, mut step, cams, bgs) = resident(n, true);
    let s = RenderSettings::default();
    bencher.bench_local(|| {
        step.render(&mut r, &cams, &bgs, &s).unwrap();
        buffers::wait_idle(&ctx).unwrap();
    });
}

/// What training runs: the subgroup backward rasterizer where the adapter has subgroups.
#[divan::bench(args = SIZES, sample_count = 3, sample_size = 1)]
fn gpu_forward_backward(bencher: Bencher, n: usize) {
    gpu_forward_backward_with(bencher, n, true);
}

/// The workgroup-memory backward rasterizer on the same adapter, for the ratio.
#[divan::bench(args = SIZES, sample_count = 3, sample_size = 1)]
fn gpu_forward_backward_workgroup_reduction(bencher: Bencher, n: usize) {
    gpu_forward_backward_with(bencher, n, false);
}

fn gpu_forward_backward_with(bencher: Bencher, n: usize, subgroups: bool) {
    let (ctx, mut r, mut step, cams, bgs) = resident(n, subgroups);
    let s = RenderSettings::default();
    let d_rgb = buffers::upload(&ctx, "dL/dRGB", &vec![1e-3f32; CAMERAS * 400 * 270 * 3]).unwrap();
    bencher.bench_local(|| {
        step.render(&mut r, &cams, &bgs, &s).unwrap();
        step.backpropagate(&mut r, &cams, &bgs, &d_rgb, &s).unwrap();
        buffers::wait_idle(&ctx).unwrap();
    });
}

#[divan::bench(args = SIZES, sample_count = 3, sample_size = 1)]
fn cpu_forward(bencher: Bencher, n: usize) {
    let (g, cams, bgs) = scene(n);
    let mut r = Renderer::new();
    let s = RenderSettings::default();
    bencher.bench_local(|| r.forward(&g, &cams, &bgs, &s).unwrap());
}

#[divan::bench(args = SIZES, sample_count = 3, sample_size = 1)]
fn cpu_forward_backward(bencher: Bencher, n: usize) {
    let (g, cams, bgs) = scene(n);
    let mut r = Renderer::new();
    let s = RenderSettings::default();
    let d_rgb = vec![1e-3f32; CAMERAS * 400 * 270 * 3];
    bencher.bench_local(|| {
        r.forward(&g, &cams, &bgs, &s).unwrap();
        r.backward(&g, &cams, &bgs, &d_rgb, None).unwrap()
    });
}

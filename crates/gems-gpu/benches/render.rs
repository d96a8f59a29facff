//! Forward and forward+backward of 15 cameras at 400×270 (the GeMS blur model's batch) with
//! 10k, 100k and 300k Gaussians, on the GPU engine and, in the same run, on the CPU engine.
//!
//! `cargo bench -p gems-gpu --bench render` runs every size; a filter such as `-- 10000` runs
//! fewer (it also matches 100000; the larger sizes take minutes on a software adapter such as
//! Mesa lavapipe). The GPU adapter is printed first; figures in BENCHMARKS.md.

#[path = "../../gems-splat/tests/common/mod.rs"]
mod common;

use divan::Bencher;
use gems_gpu::{DeviceChoice, GpuRenderer};
use gems_splat::{Camera, Gaussians, RenderSettings, Renderer};

const SIZES: &[usize] = &[10_000, 100_000, 300_000];
const CAMERAS: usize = 15;

fn main() {
    let ctx = gems_gpu::select(DeviceChoice::Gpu)
        .expect("a GPU adapter (install mesa-vulkan-drivers for lavapipe)")
        .expect("a context");
    println!("GPU adapter: {}", ctx.adapter);
    divan::main();
}

fn scene(n: usize) -> (Gaussians, Vec<Camera>, Vec<[f32; 3]>) {
    common::random_scene(1, n, CAMERAS, 400, 270, 3, (-4.6, -3.2))
}

fn gpu() -> GpuRenderer {
    let ctx = gems_gpu::select(DeviceChoice::Gpu).unwrap().unwrap();
    GpuRenderer::new(&ctx)
}

#[divan::bench(args = SIZES, sample_count = 3, sample_size = 1)]
fn gpu_forward(bencher: Bencher, n: usize) {
    let (g, cams, bgs) = scene(n);
    let mut r = gpu();
    let s = RenderSettings::default();
    r.forward(&g, &cams, &bgs, &s).unwrap();
    bencher.bench_local(|| r.forward(&g, &cams, &bgs, &s).unwrap());
}

#[divan::bench(args = SIZES, sample_count = 3, sample_size = 1)]
fn gpu_forward_backward(bencher: Bencher, n: usize) {
    let (g, cams, bgs) = scene(n);
    let mut r = gpu();
    let s = RenderSettings::default();
    let d_rgb = vec![1e-3f32; CAMERAS * 400 * 270 * 3];
    bencher.bench_local(|| {
        r.forward(&g, &cams, &bgs, &s).unwrap();
        r.backward(&g, &cams, &bgs, &d_rgb, None).unwrap()
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

//! Forward and forward+backward of the fast renderer on realistic synthetic scenes:
//! C = 15 cameras at 400×270 (one blurred view's virtual cameras) with 10k, 100k and 300k
//! Gaussians, and a single 800×540 view. Gaussian sizes scale with N so that about 30
//! Gaussians overlap the average pixel (where α ≥ 1/255), as in a trained scene.

use gems_math::Intrinsics;
use gems_splat::{Camera, Gaussians, RenderSettings, Renderer, SH_COEFFS};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn main() {
    divan::main();
}

struct Scene {
    g: Gaussians,
    cams: Vec<Camera>,
    bgs: Vec<[f32; 3]>,
    d_rgb: Vec<f32>,
    d_alpha: Vec<f32>,
}

fn scene(n: usize, nc: usize, w: u32, h: u32) -> Scene {
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let f = 0.9 * w as f32;
    let dist = 4.0f32;
    // Half extents of the view at the scene centre, in world units.
    let (hx, hy) = (0.5 * w as f32 / f * dist, 0.5 * h as f32 / f * dist);
    // Target overlap: N · π (3σ)² / (W·H) ≈ 30 at depth `dist`.
    let sigma_px = (30.0 * (w * h) as f32 / (n as f32 * std::f32::consts::PI * 9.0)).sqrt();
    let log_sigma = (sigma_px * dist / f).ln();
    let mut g = Gaussians::with_degree(3);
    for _ in 0..n {
        let mean = [
            rng.random_range(-hx..hx),
            rng.random_range(-hy..hy),
            rng.random_range(-1.0f32..1.0),
        ];
        let quat = [0; 4].map(|_| rng.random_range(-1.0f32..1.0));
        let ls = [0; 3].map(|_| log_sigma + rng.random_range(-0.4f32..0.4));
        let mut sh = [[0.0f32; 3]; SH_COEFFS];
        for (k, row) in sh.iter_mut().enumerate() {
            for v in row.iter_mut() {
                *v = if k == 0 {
                    rng.random_range(-1.5f32..1.5)
                } else {
                    rng.random_range(-0.1f32..0.1)
                };
            }
        }
        g.push(mean, quat, ls, rng.random_range(-1.0f32..2.0), sh);
    }
    // Virtual cameras along a short exposure trajectory.
    let cams: Vec<Camera> = (0..nc)
        .map(|c| {
            let s = c as f32 / nc.max(2) as f32 - 0.5;
            Camera::look_at(
                &Intrinsics {
                    fx: f64::from(f),
                    fy: f64::from(f),
                    cx: 0.5 * f64::from(w),
                    cy: 0.5 * f64::from(h),
                    width: w,
                    height: h,
                },
                [0.3 * s, 0.05 * s, -dist],
                [0.1 * s, 0.0, 0.0],
                [0.0, -1.0, 0.0],
            )
            .unwrap()
        })
        .collect();
    let npix = nc * (w * h) as usize;
    Scene {
        g,
        bgs: vec![[0.1, 0.2, 0.3]; nc],
        cams,
        d_rgb: (0..npix * 3)
            .map(|_| rng.random_range(-1.0f32..1.0))
            .collect(),
        d_alpha: (0..npix).map(|_| rng.random_range(-1.0f32..1.0)).collect(),
    }
}

const SIZES: [usize; 3] = [10_000, 100_000, 300_000];

#[divan::bench(args = SIZES, sample_count = 5, sample_size = 1)]
fn forward_15x400x270(bencher: divan::Bencher, n: usize) {
    let sc = scene(n, 15, 400, 270);
    let mut r = Renderer::new();
    let s = RenderSettings::default();
    bencher.bench_local(|| r.forward(&sc.g, &sc.cams, &sc.bgs, &s).unwrap());
}

#[divan::bench(args = SIZES, sample_count = 5, sample_size = 1)]
fn forward_backward_15x400x270(bencher: divan::Bencher, n: usize) {
    let sc = scene(n, 15, 400, 270);
    let mut r = Renderer::new();
    let s = RenderSettings::default();
    bencher.bench_local(|| {
        r.forward(&sc.g, &sc.cams, &sc.bgs, &s).unwrap();
        r.backward(&sc.g, &sc.cams, &sc.bgs, &sc.d_rgb, Some(&sc.d_alpha))
            .unwrap()
    });
}

#[divan::bench(args = [100_000], sample_count = 5, sample_size = 1)]
fn forward_1x800x540(bencher: divan::Bencher, n: usize) {
    let sc = scene(n, 1, 800, 540);
    let mut r = Renderer::new();
    let s = RenderSettings::default();
    bencher.bench_local(|| r.forward(&sc.g, &sc.cams, &sc.bgs, &s).unwrap());
}

#[divan::bench(args = [100_000], sample_count = 5, sample_size = 1)]
fn forward_backward_1x800x540(bencher: divan::Bencher, n: usize) {
    let sc = scene(n, 1, 800, 540);
    let mut r = Renderer::new();
    let s = RenderSettings::default();
    bencher.bench_local(|| {
        r.forward(&sc.g, &sc.cams, &sc.bgs, &s).unwrap();
        r.backward(&sc.g, &sc.cams, &sc.bgs, &sc.d_rgb, Some(&sc.d_alpha))
            .unwrap()
    });
}

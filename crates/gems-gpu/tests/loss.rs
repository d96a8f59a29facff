//! The GPU blur mean + fused loss against the CPU (gems-metrics `TrainingLoss`, the blur mean of
//! gems-train), finite differences of an f64 reference, and the SSIM reference vectors.

mod common;

use common::{ctx, image, max_abs, max_abs_diff};
use gems_gpu::{BlurLoss, GpuError, buffers};

/// Uploads `renders` (n stacked images) and `target`, runs the loss, reads everything back.
struct GpuOut {
    blurred: Vec<f32>,
    d_blurred: Vec<f32>,
    d_renders: Vec<f32>,
    scalars: gems_gpu::LossScalars,
}

fn run_gpu(h: usize, w: usize, n: usize, lambda: f32, renders: &[f32], target: &[f32]) -> GpuOut {
    let ctx = ctx();
    let loss = BlurLoss::new(ctx, h, w, n, lambda).unwrap();
    let r = buffers::upload(ctx, "renders", renders).unwrap();
    let t = buffers::upload(ctx, "target", target).unwrap();
    loss.run(ctx, &r, &t).unwrap();
    let len = h * w * 3;
    GpuOut {
        scalars: loss.read(ctx).unwrap(),
        blurred: buffers::download(ctx, loss.blurred(), 0, len).unwrap(),
        d_blurred: buffers::download(ctx, loss.d_blurred(), 0, len).unwrap(),
        d_renders: buffers::download(ctx, loss.d_renders(), 0, len * n).unwrap(),
    }
}

/// The CPU path of a training step: gems-train's blur mean, gems-metrics' TrainingLoss, the
/// per-render gradient d/n, and the trainer's PSNR.
struct CpuOut {
    blurred: Vec<f32>,
    d_blurred: Vec<f32>,
    d_renders: Vec<f32>,
    value: gems_metrics::LossValue,
    psnr: f32,
}

fn run_cpu(h: usize, w: usize, n: usize, lambda: f32, renders: &[f32], target: &[f32]) -> CpuOut {
    let len = h * w * 3;
    // gems_train::render_blurred: b += v · (1/n), view by view.
    let inv_n = 1.0 / n as f32;
    let mut blurred = vec![0.0f32; len];
    for view in renders.chunks_exact(len) {
        for (b, v) in blurred.iter_mut().zip(view) {
            *b += v * inv_n;
        }
    }
    let mut d_blurred = vec![0.0; len];
    let value = gems_metrics::TrainingLoss::new(h, w, lambda)
        .unwrap()
        .compute(&blurred, target, &mut d_blurred)
        .unwrap();
    // gems_train::backward_blurred: d_rgb_k = d_blurred · (1/n).
    let d_renders = (0..n)
        .flat_map(|_| d_blurred.iter().map(|d| d * inv_n))
        .collect();
    CpuOut {
        psnr: gems_metrics::psnr_capped(&blurred, target),
        blurred,
        d_blurred,
        d_renders,
        value,
    }
}

fn renders(h: usize, w: usize, n: usize, seed: u64) -> Vec<f32> {
    (0..n)
        .flat_map(|k| image(h, w, seed + 17 * k as u64))
        .collect()
}

#[test]
fn matches_cpu_loss_blur_mean_and_gradients() {
    // Not a multiple of 16 or of the workgroup size; n = 5 virtual views; GeMS λ = 0.3.
    let (h, w, n, lambda) = (37, 53, 5, 0.3);
    let r = renders(h, w, n, 11);
    let t = image(h, w, 99);
    let gpu = run_gpu(h, w, n, lambda, &r, &t);
    let cpu = run_cpu(h, w, n, lambda, &r, &t);

    // The blur mean is the same f32 recursion: at most one rounding apart per term.
    let db = max_abs_diff(&gpu.blurred, &cpu.blurred);
    eprintln!("blurred max |gpu − cpu| = {db:e}");
    assert!(db <= 4.0 * f32::EPSILON, "blurred differs by {db}");

    // Scalars: the CPU sums in f64, the GPU in fixed-order f32 trees over 5.9k (L1) and 4.2k
    // (SSIM) values in [0, 1]: relative error ≲ (8 + log2 256 + log2 #partials)·ε ≈ 2e-6.
    let s = gpu.scalars;
    eprintln!(
        "loss {} vs {}, l1 {} vs {}, ssim {} vs {}, psnr {} vs {}",
        s.loss, cpu.value.loss, s.l1, cpu.value.l1, s.ssim, cpu.value.ssim, s.psnr, cpu.psnr
    );
    assert!((s.loss - cpu.value.loss).abs() <= 2e-6 * cpu.value.loss.abs().max(1e-3));
    assert!((s.l1 - cpu.value.l1).abs() <= 2e-6 * cpu.value.l1);
    assert!((s.ssim - cpu.value.ssim).abs() <= 2e-6);
    // PSNR is −10·log10(mse): an mse relative error δ moves it by 4.34·δ dB.
    assert!(
        (s.psnr - cpu.psnr).abs() <= 1e-4,
        "{} vs {}",
        s.psnr,
        cpu.psnr
    );

    // Gradients: the same passes in the same order; each pass adds at most a few ulps of the
    // magnitudes it sums (f32 ε ≈ 1.2e-7 relative to the largest term). The L1 part is
    // ±(1−λ)/len exactly unless blurred − target changes sign, which the blurred check rules out
    // here (no |blurred − target| below 1e-6 in this data).
    assert!(
        cpu.blurred
            .iter()
            .zip(&t)
            .all(|(b, y)| (b - y).abs() > 1e-6)
    );
    let gmax = max_abs(&cpu.d_blurred);
    let dg = max_abs_diff(&gpu.d_blurred, &cpu.d_blurred);
    eprintln!("d_blurred max |gpu − cpu| = {dg:e} (max |g| {gmax:e})");
    assert!(dg <= 1e-5 * gmax, "d_blurred differs by {dg} (max {gmax})");
    let dr = max_abs_diff(&gpu.d_renders, &cpu.d_renders);
    assert!(dr <= 1e-5 * gmax / n as f32, "d_renders differ by {dr}");
}

/// Direct (non-separable) f64 SSIM-valid, independent of both implementations.
fn ssim_valid_f64(x: &[f64], y: &[f64], h: usize, w: usize) -> f64 {
    let mut g1 = [0.0f64; 11];
    for (k, v) in g1.iter_mut().enumerate() {
        let d = k as f64 - 5.0;
        *v = (-d * d / 4.5).exp();
    }
    let s: f64 = g1.iter().sum();
    let (c1, c2) = (1e-4, 9e-4);
    let mut sum = 0.0;
    for ch in 0..3 {
        for r in 5..h - 5 {
            for c in 5..w - 5 {
                let mut m = [0.0; 5];
                for a in 0..11 {
                    for b in 0..11 {
                        let i = ((r + a - 5) * w + (c + b - 5)) * 3 + ch;
                        let wt = g1[a] * g1[b] / (s * s);
                        m[0] += wt * x[i];
                        m[1] += wt * y[i];
                        m[2] += wt * x[i] * x[i];
                        m[3] += wt * y[i] * y[i];
                        m[4] += wt * x[i] * y[i];
                    }
                }
                let (mx, my) = (m[0], m[1]);
                sum += ((2.0 * mx * my + c1) * (2.0 * (m[4] - mx * my) + c2))
                    / ((mx * mx + my * my + c1) * ((m[2] - mx * mx) + (m[3] - my * my) + c2));
            }
        }
    }
    sum / (3 * (h - 10) * (w - 10)) as f64
}

/// L of the mean of the n stacked renders, in f64.
fn blur_loss_f64(renders: &[f64], y: &[f64], h: usize, w: usize, n: usize, lambda: f64) -> f64 {
    let len = h * w * 3;
    let x: Vec<f64> = (0..len)
        .map(|i| (0..n).map(|k| renders[k * len + i]).sum::<f64>() / n as f64)
        .collect();
    let l1 = x.iter().zip(y).map(|(a, b)| (a - b).abs()).sum::<f64>() / len as f64;
    (1.0 - lambda) * l1 + lambda * (1.0 - ssim_valid_f64(&x, y, h, w))
}

#[test]
fn gradient_matches_finite_differences() {
    let (h, w, n, lambda) = (14, 19, 3, 0.3);
    let r = renders(h, w, n, 5);
    let t = image(h, w, 6);
    let gpu = run_gpu(h, w, n, lambda, &r, &t);
    let r64: Vec<f64> = r.iter().map(|&v| v as f64).collect();
    let t64: Vec<f64> = t.iter().map(|&v| v as f64).collect();
    let reference = blur_loss_f64(&r64, &t64, h, w, n, lambda as f64);
    // f32 loss of O(0.1) from sums of ≤ 800 terms: 1e-6 absolute.
    assert!(
        (gpu.scalars.loss as f64 - reference).abs() < 1e-6,
        "{} vs {reference}",
        gpu.scalars.loss
    );
    let len = h * w * 3;
    let gmax = max_abs(&gpu.d_renders) as f64;
    let eps = 1e-6;
    // Corners, borders (outside the kept region but inside windows), interior; every view.
    let pixels = [
        (0, 0),
        (h - 1, w - 1),
        (2, 7),
        (5, 5),
        (h / 2, w / 2),
        (h - 6, 3),
    ];
    for k in 0..n {
        for &(row, col) in &pixels {
            for ch in 0..3 {
                let i = k * len + (row * w + col) * 3 + ch;
                let mut p = r64.clone();
                p[i] += eps;
                let mut m = r64.clone();
                m[i] -= eps;
                let fd = (blur_loss_f64(&p, &t64, h, w, n, lambda as f64)
                    - blur_loss_f64(&m, &t64, h, w, n, lambda as f64))
                    / (2.0 * eps);
                let g = gpu.d_renders[i] as f64;
                // f32 gradient vs f64 central difference (truncation O(eps²), L1 kink never
                // within eps here): 1e-3 relative plus 1e-4 of the largest entry.
                assert!(
                    (fd - g).abs() < 1e-3 * fd.abs() + 1e-4 * gmax,
                    "render {k} pixel ({row},{col}) ch {ch}: fd {fd} vs gpu {g}"
                );
            }
        }
    }
}

#[test]
fn ssim_matches_reference_vectors() {
    for name in ["small", "wide"] {
        let p = common::load_pair(name);
        // λ = 1, one view: loss = 1 − SSIM_valid and d_blurred = −dSSIM/d(render).
        let gpu = run_gpu(p.height, p.width, 1, 1.0, &p.render, &p.target);
        let ssim = gpu.scalars.ssim as f64;
        // The CPU (f64 sums) meets 2e-6; the f32 tree over ≤ 16k map values adds ≤ ~2e-6.
        assert!(
            (ssim - p.ssim_valid).abs() < 4e-6,
            "{name}: {ssim} vs {}",
            p.ssim_valid
        );
        assert!((gpu.scalars.loss as f64 - (1.0 - p.ssim_valid)).abs() < 4e-6);
        let gmax = p.grad_ssim_valid.iter().fold(0.0f64, |m, g| m.max(g.abs()));
        for (i, (&a, &b)) in gpu.d_blurred.iter().zip(&p.grad_ssim_valid).enumerate() {
            let err = (-a as f64 - b).abs();
            // The tolerance of gems-metrics' own reference test of its CPU gradient.
            assert!(
                err <= 1e-3 * b.abs() + 1e-4 * gmax,
                "{name} grad[{i}]: {} vs {b} (max {gmax})",
                -a
            );
        }
    }
}

#[test]
fn repeated_runs_are_bit_identical() {
    let (h, w, n) = (40, 41, 3);
    let r = renders(h, w, n, 21);
    let t = image(h, w, 22);
    let a = run_gpu(h, w, n, 0.3, &r, &t);
    let b = run_gpu(h, w, n, 0.3, &r, &t);
    assert_eq!(a.scalars, b.scalars);
    assert_eq!(a.d_renders, b.d_renders);
    assert_eq!(a.blurred, b.blurred);
}

#[test]
fn bad_sizes_are_errors() {
    let ctx = ctx();
    assert!(matches!(
        BlurLoss::new(ctx, 10, 40, 2, 0.3),
        Err(GpuError::Shape(_))
    ));
    assert!(matches!(
        BlurLoss::new(ctx, 20, 20, 0, 0.3),
        Err(GpuError::Shape(_))
    ));
    let loss = BlurLoss::new(ctx, 20, 20, 2, 0.3).unwrap();
    let short = buffers::upload(ctx, "renders", &vec![0.5f32; 20 * 20 * 3]).unwrap();
    let target = buffers::upload(ctx, "target", &vec![0.5f32; 20 * 20 * 3]).unwrap();
    let err = loss.run(ctx, &short, &target).unwrap_err();
    assert!(err.to_string().contains("renders"), "{err}");
}

#[test]
fn a_loss_made_for_more_views_gives_the_same_bits_for_fewer() {
    let ctx = ctx();
    let (h, w, lambda) = (23, 31, 0.3);
    let target = image(h, w, 5);
    let t = buffers::upload(ctx, "target", &target).unwrap();
    let len = h * w * 3;
    let mut shared = BlurLoss::new(ctx, h, w, 6, lambda).unwrap();
    assert_eq!((shared.views(), shared.capacity()), (6, 6));
    // Down to one view, up to the capacity again, then down to three.
    for n in [1, 6, 3] {
        shared.set_views(ctx, n).unwrap();
        assert_eq!(shared.views(), n);
        let stack = renders(h, w, n, 40 + n as u64);
        let r = buffers::upload(ctx, "renders", &stack).unwrap();
        shared.run(ctx, &r, &t).unwrap();
        let own = run_gpu(h, w, n, lambda, &stack, &target);
        assert_eq!(shared.read(ctx).unwrap(), own.scalars, "{n} views");
        let blurred: Vec<f32> = buffers::download(ctx, shared.blurred(), 0, len).unwrap();
        let d_renders: Vec<f32> = buffers::download(ctx, shared.d_renders(), 0, len * n).unwrap();
        assert_eq!(blurred, own.blurred, "{n} views");
        assert_eq!(d_renders, own.d_renders, "{n} views");
    }
    for bad in [0, 7] {
        assert!(matches!(
            shared.set_views(ctx, bad),
            Err(GpuError::Shape(_))
        ));
    }
}

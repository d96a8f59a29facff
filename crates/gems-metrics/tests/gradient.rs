//! The f32 separable SSIM-valid and fused loss against an independent direct f64 reference, with
//! central finite differences of that reference for the gradients.

use gems_metrics::*;
use proptest::prelude::*;

/// Direct (non-separable) f64 SSIM-valid: mean SSIM over windows fully inside the image.
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

fn loss_f64(x: &[f64], y: &[f64], h: usize, w: usize, lambda: f64) -> f64 {
    let l1 = x.iter().zip(y).map(|(a, b)| (a - b).abs()).sum::<f64>() / x.len() as f64;
    (1.0 - lambda) * l1 + lambda * (1.0 - ssim_valid_f64(x, y, h, w))
}

fn image(h: usize, w: usize, seed: u64) -> Vec<f64> {
    let mut s = seed;
    (0..h * w * 3)
        .map(|i| {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            // Smooth pattern plus noise, like a real image pair.
            let base = 0.5 + 0.3 * ((i / 3) as f64 * 0.07).sin();
            (base + 0.2 * ((s >> 11) as f64 / (1u64 << 53) as f64 - 0.5)).clamp(0.0, 1.0)
        })
        .collect()
}

fn to32(v: &[f64]) -> Vec<f32> {
    v.iter().map(|&a| a as f32).collect()
}

/// Pixels to finite-difference: corners, borders (outside the kept region but inside windows),
/// and the interior.
fn probe_pixels(h: usize, w: usize) -> Vec<usize> {
    let mut v = vec![];
    for (r, c) in [
        (0, 0),
        (h - 1, w - 1),
        (2, 7),
        (5, 5),
        (h / 2, w / 2),
        (h - 6, 3),
        (7, w - 1),
    ] {
        for ch in 0..3 {
            v.push((r * w + c) * 3 + ch);
        }
    }
    v
}

#[test]
fn ssim_valid_gradient_matches_finite_differences_of_f64_reference() {
    let (h, w) = (19, 23);
    let (x, y) = (image(h, w, 1), image(h, w, 2));
    let mut grad = vec![0.0; x.len()];
    let v = ssim_valid_with_grad(&to32(&x), &to32(&y), h, w, &mut grad).unwrap();
    let r = ssim_valid_f64(&x, &y, h, w);
    assert!((f64::from(v) - r).abs() < 1e-6, "{v} vs {r}");
    let gmax = grad.iter().fold(0.0f32, |m, g| m.max(g.abs())) as f64;
    let eps = 1e-5;
    for i in probe_pixels(h, w) {
        let mut xp = x.clone();
        xp[i] += eps;
        let mut xm = x.clone();
        xm[i] -= eps;
        let fd = (ssim_valid_f64(&xp, &y, h, w) - ssim_valid_f64(&xm, &y, h, w)) / (2.0 * eps);
        let err = (fd - f64::from(grad[i])).abs();
        assert!(
            err < 1e-3 * fd.abs() + 1e-4 * gmax,
            "pixel {i}: fd {fd} vs {}",
            grad[i]
        );
    }
}

#[test]
fn fused_loss_matches_finite_differences() {
    let (h, w) = (16, 21);
    let (x, y) = (image(h, w, 3), image(h, w, 4));
    let lambda = 0.3;
    let mut loss = TrainingLoss::new(h, w, lambda as f32).unwrap();
    let mut grad = vec![0.0; x.len()];
    let v = loss.compute(&to32(&x), &to32(&y), &mut grad).unwrap();
    let r = loss_f64(&x, &y, h, w, lambda);
    assert!((f64::from(v.loss) - r).abs() < 1e-6, "{} vs {r}", v.loss);
    assert!((v.loss - ((1.0 - 0.3) * v.l1 + 0.3 * (1.0 - v.ssim))).abs() < 1e-7);
    let eps = 1e-6;
    for i in probe_pixels(h, w) {
        if (x[i] - y[i]).abs() < 1e-4 {
            continue; // L1 kink
        }
        let mut xp = x.clone();
        xp[i] += eps;
        let mut xm = x.clone();
        xm[i] -= eps;
        let fd = (loss_f64(&xp, &y, h, w, lambda) - loss_f64(&xm, &y, h, w, lambda)) / (2.0 * eps);
        let err = (fd - f64::from(grad[i])).abs();
        assert!(
            err < 1e-3 * fd.abs() + 1e-7,
            "pixel {i}: fd {fd} vs {}",
            grad[i]
        );
    }
}

#[test]
fn buffers_are_reused_and_results_independent_of_threads() {
    let (h, w) = (40, 57);
    let (x, y) = (to32(&image(h, w, 5)), to32(&image(h, w, 6)));
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            let mut loss = TrainingLoss::new(h, w, 0.3).unwrap();
            let mut g1 = vec![0.0; x.len()];
            let mut g2 = vec![0.0; x.len()];
            // A different pair first: the second call must not see stale buffers.
            loss.compute(&y, &x, &mut g1).unwrap();
            let v = loss.compute(&x, &y, &mut g2).unwrap();
            (v, g2)
        })
    };
    let (v1, g1) = run(1);
    let (v3, g3) = run(3);
    assert_eq!(v1, v3);
    assert_eq!(g1, g3);
    let mut fresh = vec![0.0; x.len()];
    let v = TrainingLoss::new(h, w, 0.3)
        .unwrap()
        .compute(&x, &y, &mut fresh)
        .unwrap();
    assert_eq!(v, v1);
    assert_eq!(fresh, g1);
}

#[test]
fn bad_sizes_are_errors() {
    let a = vec![0.5f32; 12 * 12 * 3];
    let b = vec![0.5f32; 12 * 13 * 3];
    assert!(matches!(
        psnr(&a, &b, 12, 12),
        Err(MetricsError::Mismatch { .. })
    ));
    assert!(matches!(
        ssim(&a, &a, 12, 13),
        Err(MetricsError::BadSize { .. })
    ));
    let small = vec![0.5f32; 10 * 12 * 3];
    assert!(matches!(
        ssim_valid(&small, &small, 10, 12),
        Err(MetricsError::TooSmall { .. })
    ));
    assert!(TrainingLoss::new(8, 40, 0.3).is_err());
    let mut loss = TrainingLoss::new(12, 12, 0.3).unwrap();
    let mut g = vec![0.0; 12 * 12 * 3];
    assert!(loss.compute(&a, &b, &mut g).is_err());
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]
    #[test]
    fn ssim_properties(seed in 0u64..1000, h in 11usize..20, w in 11usize..20) {
        let (x, y) = (to32(&image(h, w, seed)), to32(&image(h, w, seed + 7)));
        // Identical images: SSIM 1, PSNR infinite, zero SSIM gradient.
        let mut g = vec![0.0; x.len()];
        let s = ssim_valid_with_grad(&x, &x, h, w, &mut g).unwrap();
        prop_assert!((s - 1.0).abs() < 1e-5);
        prop_assert!(g.iter().all(|v| v.abs() < 1e-4));
        prop_assert!((ssim(&x, &x, h, w).unwrap() - 1.0).abs() < 1e-12);
        prop_assert!(psnr(&x, &x, h, w).unwrap().is_infinite());
        // Symmetry and the bound.
        let a = ssim(&x, &y, h, w).unwrap();
        prop_assert!((a - ssim(&y, &x, h, w).unwrap()).abs() < 1e-12 && a < 1.0);
        let b = ssim_valid(&x, &y, h, w).unwrap();
        prop_assert!((b - ssim_valid(&y, &x, h, w).unwrap()).abs() < 1e-6 && b < 1.0);
    }
}

//! PSNR, SSIM (both variants) and the SSIM-valid gradient against the reference vectors.

mod common;

use gems_metrics::*;

#[test]
fn psnr_matches_torchmetrics() {
    for name in ["small", "wide"] {
        let p = common::load(name);
        let v = psnr(&p.render32(), &p.target32(), p.height, p.width).unwrap();
        let r = p.meta["psnr"];
        assert!((v - r).abs() < 1e-4, "{name}: {v} vs {r}");
    }
}

#[test]
fn ssim_matches_torchmetrics() {
    for name in ["small", "wide"] {
        let p = common::load(name);
        let v = ssim(&p.render32(), &p.target32(), p.height, p.width).unwrap();
        let r = p.meta["ssim_torchmetrics"];
        assert!((v - r).abs() < 2e-6, "{name}: {v} vs {r}");
    }
}

#[test]
fn ssim_valid_and_gradient_match_reference() {
    for name in ["small", "wide"] {
        let p = common::load(name);
        let mut grad = vec![0.0; p.render.len()];
        let v = ssim_valid_with_grad(&p.render32(), &p.target32(), p.height, p.width, &mut grad)
            .unwrap();
        let r = p.meta["ssim_valid"];
        assert!((f64::from(v) - r).abs() < 2e-6, "{name}: {v} vs {r}");
        let gmax = p.grad_ssim_valid.iter().fold(0.0f64, |m, g| m.max(g.abs()));
        for (i, (&a, &b)) in grad.iter().zip(&p.grad_ssim_valid).enumerate() {
            let err = (f64::from(a) - b).abs();
            assert!(
                err <= 1e-3 * b.abs() + 1e-4 * gmax,
                "{name} grad[{i}]: {a} vs {b} (max {gmax})"
            );
        }
    }
}

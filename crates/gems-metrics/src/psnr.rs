//! Peak signal-to-noise ratio with data range 1 (torchmetrics `PeakSignalNoiseRatio(data_range=1)`).

use crate::{MetricsError, check_pair};

/// PSNR in dB of `render` against `target` (interleaved RGB, [H, W, 3]); both are clamped to
/// [0, 1] first. Identical images give `f64::INFINITY`.
pub fn psnr(
    render: &[f32],
    target: &[f32],
    height: usize,
    width: usize,
) -> Result<f64, MetricsError> {
    check_pair(render, target, height, width)?;
    let mse = clamped_sse(render, target) / render.len() as f64;
    Ok(-10.0 * mse.log10())
}

/// PSNR in dB of two same-length buffers of any layout (both clamped to [0, 1], data range 1),
/// without [`psnr`]'s shape check, capped at 200 dB (the MSE is floored at 1e-20) and rounded
/// to f32: identical or empty buffers give a finite value, because the trainer logs it every
/// step into an f32 history saved as JSON, which has no infinity. Below the cap it is [`psnr`]
/// rounded to f32.
pub fn psnr_capped(a: &[f32], b: &[f32]) -> f32 {
    let mse = clamped_sse(a, b) / a.len().max(1) as f64;
    (-10.0 * mse.max(1e-20).log10()) as f32
}

/// Σ (clamp(a) − clamp(b))² in f64, summed in order (the value both PSNRs are made of).
fn clamped_sse(a: &[f32], b: &[f32]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(&x, &y)| {
            let d = f64::from(x.clamp(0.0, 1.0)) - f64::from(y.clamp(0.0, 1.0));
            d * d
        })
        .sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn psnr_capped_of_known_error() {
        let a = vec![0.5f32; 12];
        let b = vec![0.6f32; 12];
        assert!((psnr_capped(&a, &b) - 20.0).abs() < 1e-3);
    }

    #[test]
    fn psnr_capped_is_psnr_below_the_cap_and_finite_above() {
        let a: Vec<f32> = (0..48).map(|i| (i as f32 * 0.37).fract()).collect();
        let b: Vec<f32> = a.iter().map(|v| v * 0.9 + 0.05).collect();
        assert_eq!(psnr_capped(&a, &b), psnr(&a, &b, 4, 4).unwrap() as f32);
        assert_eq!(psnr(&a, &a, 4, 4).unwrap(), f64::INFINITY);
        assert_eq!(psnr_capped(&a, &a), 200.0);
        assert_eq!(psnr_capped(&[], &[]), 200.0);
    }
}

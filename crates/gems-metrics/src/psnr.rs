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
    let sse: f64 = render
        .iter()
        .zip(target)
        .map(|(&r, &t)| {
            let d = f64::from(r.clamp(0.0, 1.0)) - f64::from(t.clamp(0.0, 1.0));
            d * d
        })
        .sum();
    let mse = sse / render.len() as f64;
    Ok(-10.0 * mse.log10())
}

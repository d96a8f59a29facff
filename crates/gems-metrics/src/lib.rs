//! Image metrics for gems. Images are interleaved RGB `f32` in [0, 1], laid out [H, W, 3].
//!
//! - [`psnr`]: data range 1, inputs clamped (torchmetrics `PeakSignalNoiseRatio(data_range=1)`);
//!   [`psnr_capped`] is the same without the shape check, capped at 200 dB (the trainer's log).
//! - [`ssim`]: the evaluation SSIM, torchmetrics `StructuralSimilarityIndexMeasure(data_range=1)`
//!   (Gaussian 11×11, σ 1.5, K1 0.01, K2 0.03, reflect padding, mean over the full map).
//! - [`ssim_valid`] / [`ssim_valid_with_grad`]: the training-loss SSIM of fused-ssim with
//!   `padding="valid"` and its exact gradient w.r.t. the render (separable f32, rayon).
//! - [`TrainingLoss`]: the fused `(1−λ)·L1 + λ·(1 − SSIM_valid)` with its gradient, reusing its
//!   buffers between calls (the trainer calls it every step).
//! - [`lpips`]: LPIPS v0.1 with AlexNet (`normalize=True`), weights from safetensors or from the
//!   official PyTorch checkpoints; see that module for where to get the weights.

pub mod lpips;
mod psnr;
mod ssim;

pub use lpips::{Lpips, LpipsError};
pub use psnr::{psnr, psnr_capped};
pub use ssim::{LossValue, SSIM_WINDOW, TrainingLoss, ssim, ssim_valid, ssim_valid_with_grad};

/// Errors of the image metrics.
#[derive(Debug, thiserror::Error)]
pub enum MetricsError {
    #[error("image buffer holds {got} values but {height}x{width}x3 needs {expected}")]
    BadSize {
        got: usize,
        expected: usize,
        height: usize,
        width: usize,
    },
    #[error("render and target sizes differ ({render} vs {target} values)")]
    Mismatch { render: usize, target: usize },
    #[error("image {height}x{width} is too small for an 11x11 SSIM window (needs at least 11x11)")]
    TooSmall { height: usize, width: usize },
}

pub(crate) fn check_pair(
    render: &[f32],
    target: &[f32],
    height: usize,
    width: usize,
) -> Result<(), MetricsError> {
    if render.len() != target.len() {
        return Err(MetricsError::Mismatch {
            render: render.len(),
            target: target.len(),
        });
    }
    let expected = height * width * 3;
    if render.len() != expected {
        return Err(MetricsError::BadSize {
            got: render.len(),
            expected,
            height,
            width,
        });
    }
    Ok(())
}

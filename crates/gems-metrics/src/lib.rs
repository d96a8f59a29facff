//! Image metrics: PSNR, SSIM (the torchmetrics evaluation variant and the training-loss "valid"
//! variant with its gradient) and LPIPS (AlexNet v0.1).

// Shared by loss_forward.wgsl and loss_backward.wgsl. The 11-tap window GWIN and the SSIM
// constants C1, C2 are prepended by loss.rs (generated from the same f64 formula as the CPU).

struct Dims {
    h: u32,
    w: u32,
    views: u32,
    // Kept ("valid") rows and columns: h - 10, w - 10.
    hi: u32,
    wi: u32,
    // h * w * 3.
    len: u32,
    // 3 * hi * wi.
    ssim_len: u32,
    n_partials: u32,
    lambda: f32,
    inv_views: f32,
    inv_len: f32,
    ssim_scale: f32,
}

@group(0) @binding(0) var<uniform> dims: Dims;

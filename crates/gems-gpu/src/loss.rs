//! The blur model's mean and the fused training loss with its gradient, resident on the GPU.
//!
//! Given the n virtual renders `[n,H,W,3]` of one blurry view and its target `[H,W,3]` (f32,
//! sRGB, in GPU buffers), [`BlurLoss`] computes, without leaving the GPU:
//! * the blurred image, the mean of the renders (GeMS Eq. 1);
//! * L = (1−λ)·L1 + λ·(1 − SSIM_valid), the SSIM of fused-ssim `padding="valid"` (11×11 Gaussian
//!   window σ 1.5, only windows fully inside the image);
//! * dL/d(blurred) and dL/d(render_k) = dL/d(blurred)/n for every k;
//! * four scalars — loss, L1, SSIM and the PSNR of the blurred image against the target (the
//!   trainer's per-step curves) — the only values a step needs to read back ([`BlurLoss::read`]).
//!
//! The kernels mirror `gems_metrics::TrainingLoss` pass by pass in f32 and in the same summation
//! order (the CPU sums the SSIM map and L1 in f64; here the four sums are fixed-order f32
//! workgroup trees). So the outputs agree with the CPU to a few f32 ulps of each pass, not bit
//! for bit (the GPU compiler may contract a·b + c into a fused multiply-add). On one device every
//! output is the same from run to run: there are no atomics and every sum has a fixed order.

use bytemuck::{Pod, Zeroable};

use crate::buffers::{self, FLAT_INDEX_WGSL, Kernel, WORKGROUP};
use crate::{GpuContext, GpuError, ImageBatch};

const WIN: usize = 11;
const RAD: usize = WIN / 2;
/// Values reduced per workgroup by `reduce_partial` (256 threads × ITEMS in the shader).
const PER_PARTIAL: usize = WORKGROUP as usize * 8;

#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct Dims {
    h: u32,
    w: u32,
    views: u32,
    hi: u32,
    wi: u32,
    len: u32,
    ssim_len: u32,
    n_partials: u32,
    lambda: f32,
    inv_views: f32,
    inv_len: f32,
    ssim_scale: f32,
}

/// The scalars of one loss evaluation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LossScalars {
    /// (1−λ)·L1 + λ·(1 − SSIM).
    pub loss: f32,
    /// Mean absolute error of the blurred image over all pixels and channels.
    pub l1: f32,
    /// SSIM-valid of the blurred image.
    pub ssim: f32,
    /// PSNR (data range 1, both images clamped to [0, 1]) of the blurred image.
    pub psnr: f32,
}

/// WGSL constants shared by both loss modules: the window and C1, C2 as the CPU rounds them.
fn constants_wgsl() -> String {
    // Same construction as gems-metrics: f64 Gaussian, normalised, then rounded to f32.
    let mut g = [0.0f64; WIN];
    for (k, v) in g.iter_mut().enumerate() {
        let d = k as f64 - RAD as f64;
        *v = (-(d * d) / (2.0 * 1.5 * 1.5)).exp();
    }
    let s: f64 = g.iter().sum();
    // `{:e}` prints the shortest decimal that round-trips the f32; the `f` suffix makes WGSL
    // parse it as an f32 directly.
    let taps: Vec<String> = g.iter().map(|v| format!("{:e}f", (v / s) as f32)).collect();
    let (c1, c2) = ((0.01f64 * 0.01) as f32, (0.03f64 * 0.03) as f32);
    format!(
        "const GWIN = array<f32, 11>({});\nconst C1: f32 = {c1:e}f;\nconst C2: f32 = {c2:e}f;\n",
        taps.join(", ")
    )
}

/// Kernels and per-size buffers of the fused blur loss for one image size and up to a number of
/// views (the count of the next evaluations is [`BlurLoss::set_views`]'s).
pub struct BlurLoss {
    height: usize,
    width: usize,
    views: usize,
    /// The most views the buffers hold.
    capacity: usize,
    lambda: f32,
    dims_value: Dims,
    dims: wgpu::Buffer,
    blur_mean: Kernel,
    ssim_horiz: Kernel,
    ssim_map: Kernel,
    reduce_partial: Kernel,
    reduce_final: Kernel,
    ssim_back_vert: Kernel,
    loss_grad: Kernel,
    horiz: wgpu::Buffer,
    dmap: wgpu::Buffer,
    ssim_values: wgpu::Buffer,
    back: wgpu::Buffer,
    partials: wgpu::Buffer,
    n_partials: usize,
    blurred: wgpu::Buffer,
    d_blurred: wgpu::Buffer,
    d_renders: wgpu::Buffer,
    scalars: wgpu::Buffer,
}

impl BlurLoss {
    /// Kernels and buffers for `views` renders of `height`×`width`; `lambda` is the SSIM weight
    /// (GeMS: 0.3). The image must be at least 11×11 (the SSIM window).
    pub fn new(
        ctx: &GpuContext,
        height: usize,
        width: usize,
        views: usize,
        lambda: f32,
    ) -> Result<Self, GpuError> {
        if height < WIN || width < WIN {
            return Err(GpuError::Shape(format!(
                "image {height}x{width} is too small for an 11x11 SSIM window"
            )));
        }
        if views == 0 {
            return Err(GpuError::Shape(
                "the blur model needs at least one view".into(),
            ));
        }
        let len = height * width * 3;
        let total = len.checked_mul(views).filter(|&t| u32::try_from(t).is_ok());
        if total.is_none() {
            return Err(GpuError::Shape(format!(
                "{views} renders of {height}x{width} exceed 2^32 values"
            )));
        }
        let (hi, wi) = (height - 2 * RAD, width - 2 * RAD);
        let ssim_len = 3 * hi * wi;
        let n_partials = len.div_ceil(PER_PARTIAL);
        let dims = Dims {
            h: height as u32,
            w: width as u32,
            views: views as u32,
            hi: hi as u32,
            wi: wi as u32,
            len: len as u32,
            ssim_len: ssim_len as u32,
            n_partials: n_partials as u32,
            lambda,
            // As the CPU computes them: 1/n and 1/len in f32.
            inv_views: 1.0 / views as f32,
            inv_len: 1.0 / len as f32,
            ssim_scale: 1.0 / (3 * hi * wi) as f32,
        };
        let consts = constants_wgsl();
        let common = include_str!("../shaders/loss_common.wgsl");
        let fwd = buffers::module(
            ctx,
            "loss_forward",
            &[
                &consts,
                FLAT_INDEX_WGSL,
                common,
                include_str!("../shaders/loss_forward.wgsl"),
            ],
        );
        let bwd = buffers::module(
            ctx,
            "loss_backward",
            &[
                &consts,
                FLAT_INDEX_WGSL,
                common,
                include_str!("../shaders/loss_backward.wgsl"),
            ],
        );
        let sb = |label: &str, n: usize| buffers::storage_buffer(ctx, label, n);
        Ok(BlurLoss {
            height,
            width,
            views,
            capacity: views,
            lambda,
            dims_value: dims,
            dims: buffers::uniform(ctx, "loss dims", &dims),
            blur_mean: Kernel::new(ctx, &fwd, "blur_mean"),
            ssim_horiz: Kernel::new(ctx, &fwd, "ssim_horiz"),
            ssim_map: Kernel::new(ctx, &fwd, "ssim_map_pass"),
            reduce_partial: Kernel::new(ctx, &fwd, "reduce_partial"),
            reduce_final: Kernel::new(ctx, &fwd, "reduce_final"),
            ssim_back_vert: Kernel::new(ctx, &bwd, "ssim_back_vert"),
            loss_grad: Kernel::new(ctx, &bwd, "loss_grad"),
            horiz: sb("ssim horiz", 3 * height * 5 * wi)?,
            dmap: sb("ssim dmap", 3 * hi * 3 * wi)?,
            ssim_values: sb("ssim map", ssim_len)?,
            back: sb("ssim back", 3 * height * 3 * wi)?,
            partials: sb("loss partials", 3 * n_partials)?,
            n_partials,
            blurred: sb("blurred", len)?,
            d_blurred: sb("d_blurred", len)?,
            d_renders: sb("d_renders", len * views)?,
            scalars: sb("loss scalars", 4)?,
        })
    }

    pub fn height(&self) -> usize {
        self.height
    }

    pub fn width(&self) -> usize {
        self.width
    }

    pub fn views(&self) -> usize {
        self.views
    }

    /// The most views [`Self::set_views`] takes (the count it was made for).
    pub fn capacity(&self) -> usize {
        self.capacity
    }

    /// Evaluates `views` renders from now on (1 ≤ views ≤ [`Self::capacity`]): the mean and its
    /// gradient are over that many, with the buffers made for the capacity, so that a run whose
    /// view count changes from step to step keeps one loss per image size. The new count reaches
    /// the GPU with the next submission (after the work already submitted).
    pub fn set_views(&mut self, ctx: &GpuContext, views: usize) -> Result<(), GpuError> {
        if views == 0 || views > self.capacity {
            return Err(GpuError::Shape(format!(
                "{views} views for a loss made for 1 to {}",
                self.capacity
            )));
        }
        if views != self.views {
            self.views = views;
            self.dims_value.views = views as u32;
            self.dims_value.inv_views = 1.0 / views as f32;
            ctx.queue
                .write_buffer(&self.dims, 0, bytemuck::bytes_of(&self.dims_value));
        }
        Ok(())
    }

    pub fn lambda(&self) -> f32 {
        self.lambda
    }

    /// Bytes of GPU memory the loss's buffers hold.
    pub fn allocated_bytes(&self) -> u64 {
        [
            &self.horiz,
            &self.dmap,
            &self.ssim_values,
            &self.back,
            &self.partials,
            &self.blurred,
            &self.d_blurred,
            &self.d_renders,
            &self.scalars,
        ]
        .iter()
        .map(|b| b.size())
        .sum()
    }

    /// The blurred image `[H,W,3]` of the last evaluation.
    pub fn blurred(&self) -> &wgpu::Buffer {
        &self.blurred
    }

    /// dL/d(blurred) `[H,W,3]` of the last evaluation.
    pub fn d_blurred(&self) -> &wgpu::Buffer {
        &self.d_blurred
    }

    /// dL/d(render_k) `[n,H,W,3]` of the last evaluation (the rasterizer backward's input).
    pub fn d_renders(&self) -> &wgpu::Buffer {
        &self.d_renders
    }

    /// `[loss, l1, ssim, psnr]` of the last evaluation (4 f32).
    pub fn scalars(&self) -> &wgpu::Buffer {
        &self.scalars
    }

    /// Records the whole evaluation (mean, loss, gradients, scalars) into `enc`.
    pub fn encode(
        &self,
        ctx: &GpuContext,
        enc: &mut wgpu::CommandEncoder,
        renders: &wgpu::Buffer,
        target: &wgpu::Buffer,
    ) -> Result<(), GpuError> {
        let len = self.height * self.width * 3;
        let need = |b: &wgpu::Buffer, count: usize, what: &str| {
            if b.size() < count as u64 * 4 {
                Err(GpuError::Shape(format!(
                    "{what} buffer holds {} values, {} needed for {}x{}x3 (x{} views)",
                    b.size() / 4,
                    count,
                    self.height,
                    self.width,
                    self.views
                )))
            } else {
                Ok(())
            }
        };
        need(renders, len * self.views, "renders")?;
        need(target, len, "target")?;
        let (hi, wi) = (self.height - 2 * RAD, self.width - 2 * RAD);
        let d = &self.dims;
        let g = self
            .blur_mean
            .bind(ctx, &[(0, d), (1, renders), (3, &self.blurred)]);
        self.blur_mean.dispatch(enc, &g, len);
        let g = self.ssim_horiz.bind(
            ctx,
            &[(0, d), (2, target), (3, &self.blurred), (4, &self.horiz)],
        );
        self.ssim_horiz.dispatch(enc, &g, 3 * self.height * wi);
        let g = self.ssim_map.bind(
            ctx,
            &[
                (0, d),
                (4, &self.horiz),
                (5, &self.dmap),
                (6, &self.ssim_values),
            ],
        );
        self.ssim_map.dispatch(enc, &g, 3 * hi * wi);
        let g = self.reduce_partial.bind(
            ctx,
            &[
                (0, d),
                (2, target),
                (3, &self.blurred),
                (6, &self.ssim_values),
                (10, &self.partials),
            ],
        );
        self.reduce_partial
            .dispatch(enc, &g, self.n_partials * WORKGROUP as usize);
        let g = self
            .reduce_final
            .bind(ctx, &[(0, d), (10, &self.partials), (11, &self.scalars)]);
        self.reduce_final.dispatch(enc, &g, WORKGROUP as usize);
        let g = self
            .ssim_back_vert
            .bind(ctx, &[(0, d), (5, &self.dmap), (7, &self.back)]);
        self.ssim_back_vert.dispatch(enc, &g, 3 * self.height * wi);
        let g = self.loss_grad.bind(
            ctx,
            &[
                (0, d),
                (2, target),
                (3, &self.blurred),
                (7, &self.back),
                (8, &self.d_blurred),
                (9, &self.d_renders),
            ],
        );
        self.loss_grad.dispatch(enc, &g, len);
        Ok(())
    }

    /// Records and submits one evaluation (does not wait).
    pub fn run(
        &self,
        ctx: &GpuContext,
        renders: &wgpu::Buffer,
        target: &wgpu::Buffer,
    ) -> Result<(), GpuError> {
        let mut enc = buffers::encoder(ctx, "blur loss");
        self.encode(ctx, &mut enc, renders, target)?;
        ctx.queue.submit([enc.finish()]);
        Ok(())
    }

    /// [`Self::run`] on the renderer's output ([`crate::GpuRenderer::forward_images`]): checks
    /// that the batch holds this loss's view count and image size.
    pub fn run_batch(
        &self,
        ctx: &GpuContext,
        renders: &ImageBatch,
        target: &wgpu::Buffer,
    ) -> Result<(), GpuError> {
        if renders.count != self.views
            || renders.width as usize != self.width
            || renders.height as usize != self.height
        {
            return Err(GpuError::Shape(format!(
                "render batch of {} images of {}x{} for a loss over {} views of {}x{}",
                renders.count, renders.width, renders.height, self.views, self.width, self.height
            )));
        }
        self.run(ctx, &renders.buffer, target)
    }

    /// dL/d(render_k) as an [`ImageBatch`], the input of
    /// [`crate::GpuRenderer::backward_images`] (shares [`Self::d_renders`]).
    pub fn d_renders_batch(&self) -> ImageBatch {
        ImageBatch {
            buffer: self.d_renders.clone(),
            count: self.views,
            width: self.width as u32,
            height: self.height as u32,
        }
    }

    /// Reads back the four scalars of the last evaluation (16 bytes; waits for the GPU).
    pub fn read(&self, ctx: &GpuContext) -> Result<LossScalars, GpuError> {
        let s: Vec<f32> = buffers::download(ctx, &self.scalars, 0, 4)?;
        Ok(LossScalars {
            loss: s[0],
            l1: s[1],
            ssim: s[2],
            psnr: s[3],
        })
    }
}

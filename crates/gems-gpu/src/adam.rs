//! Adam over resident parameter groups ([`GpuGaussians`]), per-group learning rates.
//!
//! The update is gems-train's torch-semantics Adam (`AdamState::step_by_column`): same bias
//! correction (1/(1−β1ᵗ) and 1/√(1−β2ᵗ) computed in f64 on the CPU, rounded to f32), same eps
//! placement (added to √v̂, not inside the root), same f32 operation order. It differs from the
//! CPU only where the GPU's `sqrt`/division round differently or the compiler fuses a
//! multiply-add; on lavapipe the tests measure it. Elementwise, hence the same run to run.

use bytemuck::{Pod, Zeroable};

use crate::buffers::{self, FLAT_INDEX_WGSL, Kernel};
use crate::params::{GpuGaussians, GpuGradients, Group};
use crate::{GpuContext, GpuError};

/// β1, β2, eps and weight decay of one update.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AdamConfig {
    pub beta1: f32,
    pub beta2: f32,
    pub eps: f32,
    pub weight_decay: f32,
}

/// Learning rates of the Gaussian groups (the trainer's: means lr decays, SH rest = dc/20).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GaussianLrs {
    pub means: f32,
    pub quats: f32,
    pub log_scales: f32,
    pub opacity_logits: f32,
    /// SH columns 0..3 (the dc coefficient).
    pub sh_dc: f32,
    /// SH columns 3..48.
    pub sh_rest: f32,
}

#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct AdamUniform {
    len: u32,
    width: u32,
    split_col: u32,
    pad: u32,
    lr_lo: f32,
    lr_hi: f32,
    beta1: f32,
    beta2: f32,
    eps: f32,
    weight_decay: f32,
    inv_bc1: f32,
    inv_sqrt_bc2: f32,
}

/// The Adam kernel.
pub struct GpuAdam {
    kernel: Kernel,
}

/// One group's update: its buffers, its gradient, its rows and learning rates.
pub struct AdamGroupStep<'a> {
    pub param: &'a wgpu::Buffer,
    pub grad: &'a wgpu::Buffer,
    pub m: &'a wgpu::Buffer,
    pub v: &'a wgpu::Buffer,
    pub rows: usize,
    pub width: usize,
    /// Learning rate of columns `< split_col` of each row.
    pub lr_lo: f32,
    /// Learning rate of the other columns.
    pub lr_hi: f32,
    pub split_col: usize,
    /// The step number t ≥ 1 of this update (bias correction).
    pub t: u64,
}

impl GpuAdam {
    pub fn new(ctx: &GpuContext) -> Self {
        let module = buffers::module(
            ctx,
            "adam_update",
            &[FLAT_INDEX_WGSL, include_str!("../shaders/adam_update.wgsl")],
        );
        GpuAdam {
            kernel: Kernel::new(ctx, &module, "adam_update"),
        }
    }

    /// Records one update of one flat group (any buffers of `rows × width` f32 or more).
    pub fn encode_group(
        &self,
        ctx: &GpuContext,
        enc: &mut wgpu::CommandEncoder,
        s: &AdamGroupStep<'_>,
        cfg: AdamConfig,
    ) -> Result<(), GpuError> {
        let len = s.rows * s.width;
        for (b, what) in [(s.param, "param"), (s.grad, "grad"), (s.m, "m"), (s.v, "v")] {
            if b.size() < len as u64 * 4 {
                return Err(GpuError::Shape(format!(
                    "Adam {what} buffer holds {} values, {len} needed",
                    b.size() / 4
                )));
            }
        }
        if len == 0 {
            return Ok(());
        }
        if s.t == 0 || s.width == 0 || len > u32::MAX as usize {
            return Err(GpuError::Shape(format!(
                "Adam step t = {} of {} rows × {} (t ≥ 1, width ≥ 1, < 2^32 values)",
                s.t, s.rows, s.width
            )));
        }
        // As AdamState::step_by_column: the powers in f64, then rounded to f32.
        let t = s.t.min(i32::MAX as u64) as i32;
        let u = AdamUniform {
            len: len as u32,
            width: s.width as u32,
            split_col: s.split_col as u32,
            pad: 0,
            lr_lo: s.lr_lo,
            lr_hi: s.lr_hi,
            beta1: cfg.beta1,
            beta2: cfg.beta2,
            eps: cfg.eps,
            weight_decay: cfg.weight_decay,
            inv_bc1: (1.0 / (1.0 - (cfg.beta1 as f64).powi(t))) as f32,
            inv_sqrt_bc2: (1.0 / (1.0 - (cfg.beta2 as f64).powi(t)).sqrt()) as f32,
        };
        let ub = buffers::uniform(ctx, "adam uniform", &u);
        let g = self.kernel.bind(
            ctx,
            &[(0, &ub), (1, s.param), (2, s.grad), (3, s.m), (4, s.v)],
        );
        self.kernel.dispatch(enc, &g, len);
        Ok(())
    }

    /// Records one Adam step of every Gaussian group (advancing each group's step counter), as
    /// the CPU trainer's `adam_gaussians`: SH columns 0..3 at `sh_dc`, the rest at `sh_rest`.
    pub fn encode_gaussians(
        &self,
        ctx: &GpuContext,
        enc: &mut wgpu::CommandEncoder,
        gaussians: &mut GpuGaussians,
        grads: &GpuGradients,
        lrs: &GaussianLrs,
        cfg: AdamConfig,
    ) -> Result<(), GpuError> {
        if grads.capacity() < gaussians.len() {
            return Err(GpuError::Shape(format!(
                "gradients for {} Gaussians, {} resident",
                grads.capacity(),
                gaussians.len()
            )));
        }
        let rows = gaussians.len();
        for group in Group::ALL {
            let (lo, hi, split) = match group {
                Group::Means => (lrs.means, lrs.means, 0),
                Group::Quats => (lrs.quats, lrs.quats, 0),
                Group::LogScales => (lrs.log_scales, lrs.log_scales, 0),
                Group::OpacityLogits => (lrs.opacity_logits, lrs.opacity_logits, 0),
                Group::Sh => (lrs.sh_dc, lrs.sh_rest, 3),
            };
            let b = gaussians.group_mut(group);
            b.adam_step += 1;
            let step = AdamGroupStep {
                param: &b.param,
                grad: grads.group(group),
                m: &b.m,
                v: &b.v,
                rows,
                width: group.width(),
                lr_lo: lo,
                lr_hi: hi,
                split_col: split,
                t: b.adam_step,
            };
            self.encode_group(ctx, enc, &step, cfg)?;
        }
        Ok(())
    }

    /// [`Self::encode_gaussians`], submitted (does not wait).
    pub fn step_gaussians(
        &self,
        ctx: &GpuContext,
        gaussians: &mut GpuGaussians,
        grads: &GpuGradients,
        lrs: &GaussianLrs,
        cfg: AdamConfig,
    ) -> Result<(), GpuError> {
        let mut enc = buffers::encoder(ctx, "adam");
        self.encode_gaussians(ctx, &mut enc, gaussians, grads, lrs, cfg)?;
        ctx.queue.submit([enc.finish()]);
        Ok(())
    }
}

//! The 3DGS-MCMC regularisers on resident Gaussians: R = opacity_reg·mean(sigmoid(l)) +
//! scale_reg·mean(exp(log_scale)) (over all N·3 scale entries), their gradients added in place to
//! [`GpuGradients`] with gems-train's f32 formulas, and R summed in a fixed order (one f32 read
//! back only when the caller wants the loss curve).

use bytemuck::{Pod, Zeroable};

use crate::buffers::{self, Kernel, WORKGROUP};
use crate::params::{GpuGaussians, GpuGradients, Group};
use crate::{GpuContext, GpuError};

#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct RegUniform {
    n: u32,
    n_partials: u32,
    opacity_reg: f32,
    scale_reg: f32,
}

/// The regulariser kernels and the buffer of R.
pub struct GpuRegularizers {
    grad: Kernel,
    total: Kernel,
    value: wgpu::Buffer,
}

impl GpuRegularizers {
    pub fn new(ctx: &GpuContext) -> Result<Self, GpuError> {
        let module = buffers::module(
            ctx,
            "mcmc_regularize",
            &[include_str!("../shaders/mcmc_regularize.wgsl")],
        );
        Ok(GpuRegularizers {
            grad: Kernel::new(ctx, &module, "reg_grad"),
            total: Kernel::new(ctx, &module, "reg_final"),
            value: buffers::storage_buffer(ctx, "regularizer value", 1)?,
        })
    }

    /// R of the last [`Self::encode`] (one f32; 0 for no Gaussians).
    pub fn value(&self) -> &wgpu::Buffer {
        &self.value
    }

    /// Records: add dR/d(opacity logit) and dR/d(log scale) to `grads`, and R into
    /// [`Self::value`].
    pub fn encode(
        &self,
        ctx: &GpuContext,
        enc: &mut wgpu::CommandEncoder,
        g: &GpuGaussians,
        grads: &GpuGradients,
        opacity_reg: f32,
        scale_reg: f32,
    ) -> Result<(), GpuError> {
        let n = g.len();
        if grads.capacity() < n {
            return Err(GpuError::Shape(format!(
                "gradients for {} Gaussians, {n} resident",
                grads.capacity()
            )));
        }
        enc.clear_buffer(&self.value, 0, None);
        if n == 0 {
            return Ok(());
        }
        let n_partials = n.div_ceil(WORKGROUP as usize);
        let u = RegUniform {
            n: n as u32,
            n_partials: n_partials as u32,
            opacity_reg,
            scale_reg,
        };
        let ub = buffers::uniform(ctx, "regularizer uniform", &u);
        let partials = buffers::storage_buffer(ctx, "regularizer partials", 2 * n_partials)?;
        let bg = self.grad.bind(
            ctx,
            &[
                (0, &ub),
                (1, &g.group(Group::OpacityLogits).param),
                (2, &g.group(Group::LogScales).param),
                (3, grads.group(Group::OpacityLogits)),
                (4, grads.group(Group::LogScales)),
                (5, &partials),
            ],
        );
        self.grad.dispatch(enc, &bg, n);
        let bg = self
            .total
            .bind(ctx, &[(0, &ub), (5, &partials), (6, &self.value)]);
        self.total.dispatch(enc, &bg, WORKGROUP as usize);
        Ok(())
    }

    /// Reads R back (waits for the GPU).
    pub fn read(&self, ctx: &GpuContext) -> Result<f32, GpuError> {
        Ok(buffers::download::<f32>(ctx, &self.value, 0, 1)?[0])
    }
}

//! [`Engine`]: the splatting engine a run uses, the CPU one (`gems_splat::Renderer`) or the GPU
//! one (`gems_gpu::GpuRenderer`), chosen with `--device`.
//!
//! Both implement the same contract and are tested against each other (gems-gpu's parity
//! tests), so a run may switch engines between a checkpoint and its `--resume`. Renders of the
//! two engines differ by float rounding only; each engine alone is deterministic (the GPU one
//! on a given adapter and driver: it adds no floats atomically). With the GPU engine the
//! trainer (gems-train) keeps the training step resident on the GPU ([`crate::ResidentStep`]);
//! the calls here serve evaluation and the CPU engine's training step.

use gems_splat::{Camera, Gaussians, Gradients, RenderOutput, RenderSettings, Renderer};

use crate::{DeviceChoice, GpuError, GpuRenderer};

/// A splatting engine (both boxed: the CPU engine's buffers are kept inline).
pub enum Engine {
    Cpu(Box<Renderer>),
    Gpu(Box<GpuRenderer>),
}

impl Default for Engine {
    fn default() -> Self {
        Engine::cpu()
    }
}

impl std::fmt::Debug for Engine {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Engine({})", self.describe())
    }
}

impl Engine {
    /// The CPU engine.
    pub fn cpu() -> Self {
        Engine::Cpu(Box::new(Renderer::new()))
    }

    /// The engine for `--device`: `auto` takes a hardware GPU when there is one and the CPU
    /// otherwise; `gpu` with no adapter is an error.
    pub fn select(choice: DeviceChoice) -> Result<Self, GpuError> {
        Ok(match crate::select(choice)? {
            Some(ctx) => Engine::Gpu(Box::new(GpuRenderer::new(&ctx))),
            None => Engine::cpu(),
        })
    }

    /// What runs the renders, for the user: "CPU" or the GPU adapter.
    pub fn describe(&self) -> String {
        match self {
            Engine::Cpu(_) => format!("CPU ({} threads)", rayon::current_num_threads()),
            Engine::Gpu(r) => format!("GPU {}", r.adapter()),
        }
    }

    /// Renders C cameras of one scene (see `gems_splat::Renderer::forward`).
    pub fn forward(
        &mut self,
        g: &Gaussians,
        cams: &[Camera],
        bgs: &[[f32; 3]],
        s: &RenderSettings,
    ) -> Result<RenderOutput, GpuError> {
        Ok(match self {
            Engine::Cpu(r) => r.forward(g, cams, bgs, s)?,
            Engine::Gpu(r) => r.forward(g, cams, bgs, s)?,
        })
    }

    /// Backward of the last [`Engine::forward`] (see `gems_splat::Renderer::backward`).
    pub fn backward(
        &mut self,
        g: &Gaussians,
        cams: &[Camera],
        bgs: &[[f32; 3]],
        d_rgb: &[f32],
        d_alpha: Option<&[f32]>,
    ) -> Result<Gradients, GpuError> {
        Ok(match self {
            Engine::Cpu(r) => r.backward(g, cams, bgs, d_rgb, d_alpha)?,
            Engine::Gpu(r) => r.backward(g, cams, bgs, d_rgb, d_alpha)?,
        })
    }
}

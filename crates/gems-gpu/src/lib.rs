//! GPU backend of gems on wgpu (WGSL compute shaders; Vulkan, Metal, DX12).
//!
//! It implements the same contract as the CPU engine in `gems-splat`, and is tested against it.
//!
//! API overview:
//! * [`DeviceChoice`] — what the user asked for (`--device auto|cpu|gpu`).
//! * [`GpuContext`] — one wgpu device and queue, with the adapter it runs on ([`AdapterSummary`])
//!   and the optional features that the kernels use when the adapter has them.
//! * [`select`] — turns a [`DeviceChoice`] into a context, or `None` for the CPU engine.
//! * [`GpuRenderer`] — the splatting engine (forward and backward, pose gradients included)
//!   with the contract of `gems_splat::Renderer`; one WGSL compute shader per stage and
//!   direction under `shaders/`.
//! * [`ImageBatch`] — images resident on the GPU, for steps that keep `dL/dRGB` there.
//! * [`GpuContext::with_profiler`] / [`GpuContext::kernel_times`] — GPU timestamps around every
//!   kernel's pass, summed per kernel ([`KernelTimes`]).
//!
//! Reproducibility: no kernel adds floats atomically; every sum (per tile entry over the
//! tile's pixels, per Gaussian over its tile entries and cameras, per camera over Gaussians and
//! pixels) runs in a fixed order, so the same inputs on the same adapter and driver give the
//! same bits. Different adapters or drivers may differ in the last bits (`exp`, fused
//! multiply-adds chosen by the shader compiler).
//!
//! The training step resident on the GPU (everything but the rasterizer):
//! * [`BlurLoss`] — blur mean (GeMS Eq. 1), fused (1−λ)·L1 + λ·(1 − SSIM) and dL/d(render_k).
//! * [`GpuGaussians`] — the Gaussian parameters and Adam moments, resident (layout: [`params`]);
//!   [`GpuGradients`] — per-Gaussian gradients in the same layout.
//! * [`GpuAdam`] — torch-semantics Adam over the resident groups, per-group learning rates.
//! * [`GpuMcmc`] — 3DGS-MCMC: SGLD noise (Philox, [`rng`]), relocation and growth;
//!   [`GpuRegularizers`] — its opacity and scale regularisers with their gradients.
//! * [`buffers`] — uploads, readbacks and storage buffers shared by the kernels.
//! * [`ResidentStep`] — the whole step over those parts: Gaussians, Adam moments and training
//!   images stay on the GPU; per step the virtual cameras go up and only their pose gradients
//!   and the loss scalars come back (gems-train's trainer uses it on the GPU engine). Batches
//!   larger than the adapter's storage bindings run in camera chunks ([`CameraChunk`]).
//!
//! The training-step kernels follow the same rule: elementwise updates (Adam, noise, splits,
//! copies) and fixed-order workgroup trees for every sum (loss, SSIM, PSNR, regularisers), so
//! a step is bit-reproducible on one adapter and driver; the MCMC noise is a pure function of
//! (seed, step, row). Against the CPU engine they agree to a few f32 ulps per pass (Adam: 0 ulp
//! on lavapipe), not bit for bit: the GPU's `exp`/`log`/`sin`/`cos` differ from Rust's, and the
//! CPU sums some scalars in f64.
//!
//! What is and is not bit-reproducible:
//! * Bit-reproducible on one adapter and driver: every forward and backward, a whole
//!   [`ResidentStep`], hence a whole GPU training run for a seed, and a run resumed from a
//!   checkpoint (tested on lavapipe). Splitting a batch into camera chunks does not change a
//!   bit (the per-Gaussian sums continue across chunks in camera order; tested).
//! * Not bit-identical across adapters or drivers (the last bits of `exp`, `log`, `sqrt`, and
//!   the multiply-adds the shader compiler fuses), nor to the CPU engine: a GPU run also draws
//!   its SGLD noise from Philox on the GPU rather than from the CPU trainer's ChaCha8 stream,
//!   so its backgrounds, view order and MCMC draws diverge from a CPU run's after the first
//!   step. The two engines end at the same fit on average (gems-train `tests/gpu_engine.rs`),
//!   not at the same parameters.

mod adam;
pub mod buffers;
mod context;
mod engine;
mod kernels;
mod loss;
mod mcmc;
pub mod params;
mod profiler;
mod regularize;
mod renderer;
pub mod rng;
mod step;

pub use adam::{AdamConfig, AdamGroupStep, GaussianLrs, GpuAdam};
pub use context::{AdapterSummary, DeviceChoice, GpuContext, select};
pub use engine::{Engine, FrozenScene};
pub use loss::{BlurLoss, LossScalars};
pub use mcmc::{GpuMcmc, N_MAX, NoiseParams};
pub use params::{GpuGaussians, GpuGradients, Group, GroupMoments};
pub use profiler::{KernelTime, KernelTimes};
pub use regularize::GpuRegularizers;
pub use renderer::{CameraChunk, GpuRenderer};
pub use step::{ResidentStep, StepResult, StepSettings};

/// A batch of `count` RGB images of `width`×`height` on the GPU.
///
/// Layout of `buffer`: `[count, height, width, 3]` little-endian `f32`, rows top to bottom,
/// channels interleaved (the layout of `gems_splat::RenderOutput::rgb`); the buffer may be
/// longer than that. [`GpuRenderer::forward_images`] returns the rendered images this way
/// (sharing the engine's output buffer, valid until its next forward call), and
/// [`GpuRenderer::backward_images`] takes `dL/dRGB` this way. A buffer passed in needs
/// `STORAGE` usage.
#[derive(Clone, Debug)]
pub struct ImageBatch {
    pub buffer: wgpu::Buffer,
    pub count: usize,
    pub width: u32,
    pub height: u32,
}

/// Errors of the GPU backend.
#[derive(Debug, thiserror::Error)]
pub enum GpuError {
    /// `--device gpu` was asked for and no adapter could be opened.
    #[error("no GPU adapter is available ({0}); use --device cpu, or install a Vulkan driver")]
    NoAdapter(String),
    /// The adapter was found but a device could not be created on it.
    #[error("could not open a device on adapter {adapter}: {reason}")]
    Device { adapter: String, reason: String },
    /// A readback or submission failed.
    #[error("GPU operation failed: {0}")]
    Operation(String),
    /// Inputs that do not fit together (or exceed the adapter's limits).
    #[error("shape mismatch: {0}")]
    Shape(String),
    /// One render call needs a buffer larger than the adapter can bind: fewer cameras per
    /// call (see [`ResidentStep`], which splits its batches into camera chunks) or fewer
    /// Gaussians.
    #[error(
        "too large for the adapter: {what} needs {needed}, the adapter allows {limit}; render \
         fewer cameras or Gaussians per call"
    )]
    Capacity {
        /// What did not fit, with its unit.
        what: String,
        needed: u64,
        limit: u64,
    },
    /// The CPU-side validation of the inputs failed (same rules as the CPU engine).
    #[error(transparent)]
    Splat(#[from] gems_splat::SplatError),
}

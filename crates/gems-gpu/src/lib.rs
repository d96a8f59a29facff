//! GPU backend of gems on wgpu (WGSL compute shaders; Vulkan, Metal, DX12).
//!
//! It implements the same contract as the CPU engine in `gems-splat`, and is tested against it.
//!
//! API overview:
//! * [`DeviceChoice`] — what the user asked for (`--device auto|cpu|gpu`).
//! * [`GpuContext`] — one wgpu device and queue, with the adapter it runs on ([`AdapterSummary`])
//!   and the optional features that the kernels use when the adapter has them.
//! * [`select`] — turns a [`DeviceChoice`] into a context, or `None` for the CPU engine.

mod context;

pub use context::{AdapterSummary, DeviceChoice, GpuContext, select};

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
    /// The CPU-side validation of the inputs failed (same rules as the CPU engine).
    #[error(transparent)]
    Splat(#[from] gems_splat::SplatError),
}

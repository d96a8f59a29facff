//! Buffer and kernel plumbing shared by the training-step kernels (loss, Adam, MCMC): storage
//! buffers, uploads, blocking readbacks, compute pipelines and 1-D dispatches of any length.

use wgpu::util::DeviceExt;

use crate::{GpuContext, GpuError};

/// Threads per workgroup of every 1-D kernel of this crate's training step.
pub(crate) const WORKGROUP: u32 = 256;

/// Usage of every resident storage buffer: read/write in kernels, copy in and out.
pub(crate) const STORAGE: wgpu::BufferUsages = wgpu::BufferUsages::STORAGE
    .union(wgpu::BufferUsages::COPY_SRC)
    .union(wgpu::BufferUsages::COPY_DST);

/// Bytes of `count` f32/u32 values, checked against the device's buffer limits.
pub(crate) fn checked_bytes(ctx: &GpuContext, count: usize, what: &str) -> Result<u64, GpuError> {
    let bytes = (count as u64).saturating_mul(4);
    let max_binding = ctx.limits.max_storage_buffer_binding_size;
    if bytes > ctx.limits.max_buffer_size || bytes > max_binding {
        return Err(GpuError::Shape(format!(
            "{what} needs {bytes} bytes; the adapter allows at most {} per storage buffer",
            ctx.limits.max_buffer_size.min(max_binding)
        )));
    }
    Ok(bytes)
}

/// A zeroed storage buffer of `count` 32-bit values (at least one, as wgpu forbids empty
/// bindings).
pub fn storage_buffer(
    ctx: &GpuContext,
    label: &str,
    count: usize,
) -> Result<wgpu::Buffer, GpuError> {
    let bytes = checked_bytes(ctx, count.max(1), label)?;
    Ok(ctx.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size: bytes,
        usage: STORAGE,
        mapped_at_creation: false,
    }))
}

/// A storage buffer holding `data` (32-bit values; at least one value is allocated).
pub fn upload<T: bytemuck::Pod>(
    ctx: &GpuContext,
    label: &str,
    data: &[T],
) -> Result<wgpu::Buffer, GpuError> {
    assert_eq!(size_of::<T>() % 4, 0, "32-bit element types only");
    let count = size_of_val(data) / 4;
    checked_bytes(ctx, count.max(1), label)?;
    if data.is_empty() {
        return storage_buffer(ctx, label, 1);
    }
    Ok(ctx
        .device
        .create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some(label),
            contents: bytemuck::cast_slice(data),
            usage: STORAGE,
        }))
}

/// A uniform buffer holding `value`.
pub(crate) fn uniform<T: bytemuck::Pod>(ctx: &GpuContext, label: &str, value: &T) -> wgpu::Buffer {
    ctx.device
        .create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some(label),
            contents: bytemuck::bytes_of(value),
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
        })
}

/// Copies `count` 32-bit values starting at value `offset` of `buffer` back to the CPU (blocks
/// until the GPU has finished everything submitted before).
pub fn download<T: bytemuck::Pod>(
    ctx: &GpuContext,
    buffer: &wgpu::Buffer,
    offset: usize,
    count: usize,
) -> Result<Vec<T>, GpuError> {
    assert_eq!(size_of::<T>(), 4, "32-bit element types only");
    if count == 0 {
        return Ok(Vec::new());
    }
    let (start, bytes) = (offset as u64 * 4, count as u64 * 4);
    if start + bytes > buffer.size() {
        return Err(GpuError::Shape(format!(
            "reading values {offset}..{} of a buffer of {} values",
            offset + count,
            buffer.size() / 4
        )));
    }
    let staging = ctx.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("readback"),
        size: bytes,
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let mut enc = ctx
        .device
        .create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("readback"),
        });
    enc.copy_buffer_to_buffer(buffer, start, &staging, 0, bytes);
    ctx.queue.submit([enc.finish()]);
    let (tx, rx) = std::sync::mpsc::channel();
    staging.map_async(wgpu::MapMode::Read, .., move |r| {
        // The receiver lives until recv() below returns.
        let _ = tx.send(r);
    });
    ctx.device
        .poll(wgpu::PollType::wait_indefinitely())
        .map_err(|e| GpuError::Operation(format!("waiting for a readback: {e}")))?;
    rx.recv()
        .map_err(|e| GpuError::Operation(format!("readback callback dropped: {e}")))?
        .map_err(|e| GpuError::Operation(format!("mapping a readback buffer: {e}")))?;
    let out = {
        let view = staging
            .get_mapped_range(..)
            .map_err(|e| GpuError::Operation(format!("reading a mapped buffer: {e}")))?;
        bytemuck::cast_slice::<u8, T>(&view).to_vec()
    };
    staging.unmap();
    Ok(out)
}

/// Blocks until all submitted work is done (for timings and tests).
pub fn wait_idle(ctx: &GpuContext) -> Result<(), GpuError> {
    ctx.device
        .poll(wgpu::PollType::wait_indefinitely())
        .map(|_| ())
        .map_err(|e| GpuError::Operation(format!("waiting for the GPU: {e}")))
}

/// One compute entry point with its automatic bind-group layout (group 0).
pub(crate) struct Kernel {
    pipeline: wgpu::ComputePipeline,
    layout: wgpu::BindGroupLayout,
    label: &'static str,
    profiler: Option<crate::profiler::SharedProfiler>,
}

impl Kernel {
    pub(crate) fn new(ctx: &GpuContext, module: &wgpu::ShaderModule, entry: &'static str) -> Self {
        let pipeline = ctx
            .device
            .create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(entry),
                layout: None,
                module,
                entry_point: Some(entry),
                compilation_options: Default::default(),
                cache: None,
            });
        let layout = pipeline.get_bind_group_layout(0);
        Kernel {
            pipeline,
            layout,
            label: entry,
            profiler: ctx.profiler.clone(),
        }
    }

    /// A bind group of `(binding, buffer)` pairs: exactly the bindings the entry point uses.
    pub(crate) fn bind(
        &self,
        ctx: &GpuContext,
        entries: &[(u32, &wgpu::Buffer)],
    ) -> wgpu::BindGroup {
        let entries: Vec<wgpu::BindGroupEntry> = entries
            .iter()
            .map(|&(binding, b)| wgpu::BindGroupEntry {
                binding,
                resource: b.as_entire_binding(),
            })
            .collect();
        ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some(self.label),
            layout: &self.layout,
            entries: &entries,
        })
    }

    /// Records a dispatch covering `threads` invocations of [`WORKGROUP`] threads each, folded
    /// into two dimensions when one is not enough (kernels rebuild the flat index from
    /// `workgroup_id` and `num_workgroups`).
    pub(crate) fn dispatch(
        &self,
        enc: &mut wgpu::CommandEncoder,
        group: &wgpu::BindGroup,
        threads: usize,
    ) {
        if threads == 0 {
            return;
        }
        let (x, y) = grid(threads);
        let mut pass = crate::profiler::begin_pass(self.profiler.as_ref(), enc, self.label);
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, group, &[]);
        pass.dispatch_workgroups(x, y, 1);
    }
}

/// Workgroup grid (x, y) for `threads` invocations; x ≤ 65535, the WebGPU default limit.
pub(crate) fn grid(threads: usize) -> (u32, u32) {
    const MAX_X: usize = 65_535;
    let groups = threads.div_ceil(WORKGROUP as usize);
    if groups <= MAX_X {
        (groups as u32, 1)
    } else {
        (MAX_X as u32, groups.div_ceil(MAX_X) as u32)
    }
}

/// WGSL helper shared by the kernels: the flat invocation index of a folded 2-D dispatch.
pub(crate) const FLAT_INDEX_WGSL: &str = "
fn flat_index(wg: vec3<u32>, nwg: vec3<u32>, lid: u32) -> u32 {
    return (wg.y * nwg.x + wg.x) * 256u + lid;
}
";

/// A WGSL module from the given sources, concatenated.
pub(crate) fn module(ctx: &GpuContext, label: &str, sources: &[&str]) -> wgpu::ShaderModule {
    let code = sources.concat();
    ctx.device
        .create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some(label),
            source: wgpu::ShaderSource::Wgsl(code.into()),
        })
}

/// A new command encoder.
pub(crate) fn encoder(ctx: &GpuContext, label: &str) -> wgpu::CommandEncoder {
    ctx.device
        .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some(label) })
}

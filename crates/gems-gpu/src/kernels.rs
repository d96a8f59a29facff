//! The compute pipelines (one WGSL file per stage and direction under `shaders/`), the uniform
//! block they share, and small helpers to encode a dispatch, grow a resident buffer and read
//! buffers back.

use wgpu::util::DeviceExt;

use crate::GpuError;

const COMMON: &str = include_str!("../shaders/common.wgsl");
const PROJECTION: &str = include_str!("../shaders/projection.wgsl");
const BACKWARD_PIXEL: &str = include_str!("../shaders/rasterize_backward_pixel.wgsl");

/// Invocations per workgroup in every kernel.
pub(crate) const WG: u32 = 256;
/// Most workgroups along one dispatch dimension (WebGPU's guaranteed limit); larger dispatches
/// are split over y and the kernels rebuild the linear index.
const MAX_DIM: u32 = 65_535;

/// Mirrors `struct Params` in `shaders/common.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub(crate) struct Params {
    pub num_gaussians: u32,
    pub num_cameras: u32,
    pub width: u32,
    pub height: u32,
    pub tiles_x: u32,
    pub tiles_y: u32,
    pub sh_degree: u32,
    pub antialiased: u32,
    pub eps2d: f32,
    pub near_plane: f32,
    pub far_plane: f32,
    pub alpha_max: f32,
    pub alpha_min: f32,
    pub t_min: f32,
    pub radius_extent: f32,
    pub has_d_alpha: u32,
    pub n: u32,
    pub shift: u32,
    pub use_hi: u32,
    pub num_blocks: u32,
    pub seg_len: u32,
    pub seg_width: u32,
    pub carry: u32,
    pub pad1: u32,
}

/// A compiled kernel and the name its passes are labelled (and profiled) by.
pub(crate) struct Pipeline {
    pub pipeline: wgpu::ComputePipeline,
    pub label: &'static str,
}

pub(crate) struct Kernels {
    pub project_forward: Pipeline,
    pub scan_blocks: Pipeline,
    pub add_offsets: Pipeline,
    pub map_intersections: Pipeline,
    pub sort_histogram: Pipeline,
    pub sort_scatter: Pipeline,
    pub tile_ranges: Pipeline,
    pub rasterize_forward: Pipeline,
    pub rasterize_backward: Pipeline,
    pub sum_intersections: Pipeline,
    pub project_backward: Pipeline,
    pub reduce_segments: Pipeline,
    pub background_backward: Pipeline,
    pub pack_gaussians: Pipeline,
    pub unpack_grads: Pipeline,
}

impl Kernels {
    /// Compiles every kernel; `subgroups` picks the backward rasterizer that reduces with
    /// subgroup adds (the device must have `Features::SUBGROUP`, see `GpuContext::subgroups`).
    pub fn new(device: &wgpu::Device, subgroups: bool) -> Self {
        let make = |name: &'static str, projection: bool, body: &str, entry: &str| {
            let mut src = String::from(COMMON);
            if projection {
                src.push_str(PROJECTION);
            }
            src.push_str(body);
            let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some(name),
                source: wgpu::ShaderSource::Wgsl(src.into()),
            });
            let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(name),
                layout: None,
                module: &module,
                entry_point: Some(entry),
                compilation_options: Default::default(),
                cache: None,
            });
            Pipeline {
                pipeline,
                label: name,
            }
        };
        let scan = include_str!("../shaders/prefix_sum.wgsl");
        let resident = include_str!("../shaders/resident.wgsl");
        Kernels {
            project_forward: make(
                "project_forward",
                true,
                include_str!("../shaders/project_forward.wgsl"),
                "main",
            ),
            scan_blocks: make("scan_blocks", false, scan, "scan_blocks"),
            add_offsets: make("add_offsets", false, scan, "add_offsets"),
            map_intersections: make(
                "map_intersections",
                false,
                include_str!("../shaders/map_intersections.wgsl"),
                "main",
            ),
            sort_histogram: make(
                "sort_histogram",
                false,
                include_str!("../shaders/sort_histogram.wgsl"),
                "main",
            ),
            sort_scatter: make(
                "sort_scatter",
                false,
                include_str!("../shaders/sort_scatter.wgsl"),
                "main",
            ),
            tile_ranges: make(
                "tile_ranges",
                false,
                include_str!("../shaders/tile_ranges.wgsl"),
                "main",
            ),
            rasterize_forward: make(
                "rasterize_forward",
                false,
                include_str!("../shaders/rasterize_forward.wgsl"),
                "main",
            ),
            rasterize_backward: if subgroups {
                make(
                    "rasterize_backward_subgroup",
                    false,
                    &format!(
                        "{BACKWARD_PIXEL}{}",
                        include_str!("../shaders/rasterize_backward_subgroup.wgsl")
                    ),
                    "main",
                )
            } else {
                make(
                    "rasterize_backward",
                    false,
                    &format!(
                        "{BACKWARD_PIXEL}{}",
                        include_str!("../shaders/rasterize_backward.wgsl")
                    ),
                    "main",
                )
            },
            sum_intersections: make(
                "sum_intersections",
                false,
                include_str!("../shaders/sum_intersections.wgsl"),
                "main",
            ),
            project_backward: make(
                "project_backward",
                true,
                include_str!("../shaders/project_backward.wgsl"),
                "main",
            ),
            reduce_segments: make(
                "reduce_segments",
                false,
                include_str!("../shaders/reduce_segments.wgsl"),
                "main",
            ),
            background_backward: make(
                "background_backward",
                false,
                include_str!("../shaders/background_backward.wgsl"),
                "main",
            ),
            pack_gaussians: make("pack_gaussians", false, resident, "pack_gaussians"),
            unpack_grads: make("unpack_grads", false, resident, "unpack_grads"),
        }
    }
}

/// Encodes one dispatch of `groups` workgroups of `pipeline`, with `params` at binding 0 and
/// `buffers` at bindings 1, 2, …
pub(crate) fn dispatch(
    ctx: &crate::GpuContext,
    encoder: &mut wgpu::CommandEncoder,
    pipeline: &Pipeline,
    params: &Params,
    buffers: &[&wgpu::Buffer],
    groups: u32,
) {
    let device = &ctx.device;
    if groups == 0 {
        return;
    }
    let uniform = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("params"),
        contents: bytemuck::bytes_of(params),
        usage: wgpu::BufferUsages::UNIFORM,
    });
    let mut entries = vec![wgpu::BindGroupEntry {
        binding: 0,
        resource: uniform.as_entire_binding(),
    }];
    for (k, b) in buffers.iter().enumerate() {
        entries.push(wgpu::BindGroupEntry {
            binding: k as u32 + 1,
            resource: b.as_entire_binding(),
        });
    }
    let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: None,
        layout: &pipeline.pipeline.get_bind_group_layout(0),
        entries: &entries,
    });
    let mut pass = crate::profiler::begin_pass(ctx.profiler.as_ref(), encoder, pipeline.label);
    pass.set_pipeline(&pipeline.pipeline);
    pass.set_bind_group(0, &bind_group, &[]);
    let x = groups.min(MAX_DIM);
    pass.dispatch_workgroups(x, groups.div_ceil(x), 1);
}

/// Workgroups for one invocation per element.
pub(crate) fn groups_for(elements: usize) -> u32 {
    elements.div_ceil(WG as usize) as u32
}

/// A storage buffer that grows (never shrinks) as calls need more.
pub(crate) struct Resident {
    label: &'static str,
    buffer: Option<wgpu::Buffer>,
}

impl Resident {
    pub const fn new(label: &'static str) -> Self {
        Resident {
            label,
            buffer: None,
        }
    }

    /// The buffer, at least `bytes` long (and at least 256 bytes: empty bindings are invalid, and a binding must hold at least one element of its array).
    pub fn ensure(
        &mut self,
        device: &wgpu::Device,
        limits: &wgpu::Limits,
        bytes: u64,
    ) -> Result<&wgpu::Buffer, GpuError> {
        let bytes = bytes.max(256).next_multiple_of(16);
        let max = limits
            .max_storage_buffer_binding_size
            .min(limits.max_buffer_size);
        if bytes > max {
            return Err(GpuError::Capacity {
                what: format!("{} (bytes)", self.label),
                needed: bytes,
                limit: max,
            });
        }
        if self.buffer.as_ref().is_none_or(|b| b.size() < bytes) {
            // Grow with headroom so that slowly growing scenes do not reallocate every call.
            let size = (bytes + bytes / 4).min(max).next_multiple_of(16).min(max);
            self.buffer = Some(device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(self.label),
                size,
                usage: wgpu::BufferUsages::STORAGE
                    | wgpu::BufferUsages::COPY_SRC
                    | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            }));
        }
        Ok(self.get())
    }

    /// Bytes allocated (0 before the first [`Resident::ensure`]).
    pub fn allocated(&self) -> u64 {
        self.buffer.as_ref().map_or(0, |b| b.size())
    }

    /// The buffer; only after [`Resident::ensure`].
    pub fn get(&self) -> &wgpu::Buffer {
        self.buffer.as_ref().expect("ensure() is called first")
    }
}

/// Copies `[offset, offset + bytes)` of each source into staging buffers in one submission and
/// returns their contents.
pub(crate) fn read_back(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    mut encoder: wgpu::CommandEncoder,
    sources: &[(&wgpu::Buffer, u64, u64)],
) -> Result<Vec<Vec<u8>>, GpuError> {
    let staging: Vec<Option<wgpu::Buffer>> = sources
        .iter()
        .map(|&(src, offset, bytes)| {
            (bytes > 0).then(|| {
                let st = device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("readback"),
                    size: bytes.next_multiple_of(4),
                    usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                    mapped_at_creation: false,
                });
                encoder.copy_buffer_to_buffer(src, offset, &st, 0, bytes.next_multiple_of(4));
                st
            })
        })
        .collect();
    queue.submit([encoder.finish()]);
    let (tx, rx) = std::sync::mpsc::channel();
    for st in staging.iter().flatten() {
        let tx = tx.clone();
        st.map_async(wgpu::MapMode::Read, .., move |r| {
            // The receiver outlives every callback (it waits for all of them below).
            let _ = tx.send(r);
        });
    }
    drop(tx);
    device
        .poll(wgpu::PollType::wait_indefinitely())
        .map_err(|e| GpuError::Operation(format!("waiting for the GPU: {e}")))?;
    for r in &rx {
        r.map_err(|e| GpuError::Operation(format!("reading back a buffer: {e}")))?;
    }
    let mut out = Vec::with_capacity(sources.len());
    for (st, &(_, _, bytes)) in staging.iter().zip(sources) {
        match st {
            Some(st) => {
                let view = st
                    .get_mapped_range(..)
                    .map_err(|e| GpuError::Operation(format!("mapping a buffer: {e}")))?;
                out.push(view[..bytes as usize].to_vec());
                drop(view);
                st.unmap();
            }
            None => out.push(Vec::new()),
        }
    }
    Ok(out)
}

/// Little-endian bytes → `f32`s / `u32`s.
pub(crate) fn f32s(bytes: &[u8]) -> Vec<f32> {
    bytes
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect()
}

pub(crate) fn u32s(bytes: &[u8]) -> Vec<u32> {
    bytes
        .chunks_exact(4)
        .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect()
}

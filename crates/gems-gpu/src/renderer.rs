//! [`GpuRenderer`]: the splatting engine on the GPU, with the CPU engine's contract.
//!
//! Forward: `project_forward` (per camera × Gaussian: splat, radii, tile count) → exclusive
//! prefix sum of the tile counts → `map_intersections` (one entry per overlapped tile, key =
//! (camera·tiles + tile, depth bits)) → stable LSD radix sort, 8 bits per pass, depth bits
//! first and the tile bits last, so entries end up by (camera, tile, depth, Gaussian index), the
//! CPU engine's order → `tile_ranges` → `rasterize_forward` (a workgroup per camera × tile,
//! splats staged in workgroup memory).
//!
//! Backward: `rasterize_backward` replays each tile back to front and writes each tile entry's
//! gradient (summed over the tile's pixels in workgroup memory) to its own slot →
//! `sum_intersections` adds each Gaussian's entries in tile order → `project_backward`
//! (per Gaussian over the cameras; SH, covariance, quaternion, pose shares) →
//! `reduce_segments` (pose and focal gradient per camera) and `background_backward`.
//!
//! No stage uses atomics on floats: every sum has a fixed order, so the same inputs on the
//! same adapter and driver give the same bits. Results differ from the CPU engine by float
//! rounding (f32 projection here, f64 there; `exp` of the driver) within the parity tolerances.

use gems_splat::{
    Camera, Gaussians, Gradients, RenderOutput, RenderSettings, SH_COEFFS, SplatError, check_inputs,
};

use crate::kernels::{Kernels, Params, Resident, WG, dispatch, f32s, groups_for, read_back, u32s};
use crate::params::{GpuGaussians, GpuGradients, Group};
use crate::{AdapterSummary, GpuContext, GpuError, ImageBatch};

/// Floats per Gaussian in the packed parameter buffer (see `shaders/common.wgsl`).
const GP: usize = 59;
/// Floats per camera in the packed camera buffer.
const CAMF: usize = 24;
/// Floats per screen-space gradient.
const SG: u64 = 9;
/// Bytes per splat (`struct Splat`).
const SPLAT_BYTES: u64 = 64;
/// Tile edge in pixels.
const TILE: u32 = 16;
/// Floats per Gaussian of the accumulators carried between camera chunks
/// (`CARRY` in `shaders/project_backward.wgsl`).
const CARRY: usize = 63;
/// Floats of one camera's pose and focal gradient (dL/dR row-major, dL/dt, dL/dfx, dL/dfy), as
/// `project_backward.wgsl` writes them.
pub(crate) const POSE_FLOATS: usize = 14;

/// Where the Gaussians of a forward call come from.
#[derive(Clone, Copy)]
enum Source<'a> {
    /// On the CPU: packed and uploaded.
    Host(&'a Gaussians),
    /// Resident on the GPU: packed by a kernel, nothing crosses the bus.
    Resident(&'a GpuGaussians),
}

impl Source<'_> {
    fn len(&self) -> usize {
        match self {
            Source::Host(g) => g.len(),
            Source::Resident(g) => g.len(),
        }
    }

    fn sh_degree(&self) -> u32 {
        match self {
            Source::Host(g) => g.sh_degree,
            Source::Resident(g) => g.sh_degree,
        }
    }
}

/// The position of one call in a batch split into camera chunks (see
/// [`GpuRenderer::backward_resident`]): a whole batch is `{ first: true, last: true }`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CameraChunk {
    /// The first chunk: the per-Gaussian sums start from zero.
    pub first: bool,
    /// The last chunk: the per-Gaussian gradients are final and written out.
    pub last: bool,
}

impl CameraChunk {
    /// A batch in one call.
    pub const WHOLE: CameraChunk = CameraChunk {
        first: true,
        last: true,
    };
}

/// What `backward` needs from the last `forward`.
#[derive(Clone, Copy, Default)]
struct Saved {
    valid: bool,
    num_gaussians: usize,
    num_cameras: usize,
    width: u32,
    height: u32,
    intersections: u64,
    settings: Option<RenderSettings>,
}

/// Resident buffers, reused (grown when needed) across calls.
struct Buffers {
    gaussians: Resident,
    cams: Resident,
    splats: Resident,
    radii: Resident,
    offsets: Resident,
    scan_levels: Vec<Resident>,
    key_lo: [Resident; 2],
    key_hi: [Resident; 2],
    vals: [Resident; 2],
    owner: Resident,
    histogram: Resident,
    ranges: Resident,
    sorted_splat: Resident,
    sorted_pos: Resident,
    rgb: Resident,
    aux: Resident,
    d_rgb: Resident,
    d_alpha: Resident,
    entry_grads: Resident,
    splat_grads: Resident,
    grads: Resident,
    stats: Resident,
    pose_parts: Resident,
    pose: Resident,
    bg_grads: Resident,
    carry: Resident,
}

impl Buffers {
    fn allocated(&self) -> u64 {
        let all = [
            &self.gaussians,
            &self.cams,
            &self.splats,
            &self.radii,
            &self.offsets,
            &self.key_lo[0],
            &self.key_lo[1],
            &self.key_hi[0],
            &self.key_hi[1],
            &self.vals[0],
            &self.vals[1],
            &self.owner,
            &self.histogram,
            &self.ranges,
            &self.sorted_splat,
            &self.sorted_pos,
            &self.rgb,
            &self.aux,
            &self.d_rgb,
            &self.d_alpha,
            &self.entry_grads,
            &self.splat_grads,
            &self.grads,
            &self.stats,
            &self.pose_parts,
            &self.pose,
            &self.bg_grads,
            &self.carry,
        ];
        all.iter()
            .chain(self.scan_levels.iter().collect::<Vec<_>>().iter())
            .map(|r| r.allocated())
            .sum()
    }

    fn new() -> Self {
        Buffers {
            gaussians: Resident::new("gaussians"),
            cams: Resident::new("cameras"),
            splats: Resident::new("splats"),
            radii: Resident::new("radii"),
            offsets: Resident::new("tile offsets"),
            scan_levels: Vec::new(),
            key_lo: [Resident::new("keys lo"), Resident::new("keys lo (2)")],
            key_hi: [Resident::new("keys hi"), Resident::new("keys hi (2)")],
            vals: [Resident::new("values"), Resident::new("values (2)")],
            owner: Resident::new("entry owner"),
            histogram: Resident::new("radix histogram"),
            ranges: Resident::new("tile ranges"),
            sorted_splat: Resident::new("sorted splat"),
            sorted_pos: Resident::new("sorted position"),
            rgb: Resident::new("rgb"),
            aux: Resident::new("pixel state"),
            d_rgb: Resident::new("dL/dRGB"),
            d_alpha: Resident::new("dL/dalpha"),
            entry_grads: Resident::new("tile entry gradients"),
            splat_grads: Resident::new("splat gradients"),
            grads: Resident::new("gaussian gradients"),
            stats: Resident::new("densification statistics"),
            pose_parts: Resident::new("pose gradient parts"),
            pose: Resident::new("pose gradients"),
            bg_grads: Resident::new("background gradients"),
            carry: Resident::new("camera-chunk carry"),
        }
    }
}

/// The GPU splatting engine: same inputs, outputs and rules as [`gems_splat::Renderer`].
///
/// [`GpuRenderer::forward`] renders C cameras of one scene (all of one size) and remembers
/// what [`GpuRenderer::backward`] needs; the buffer-level variants
/// ([`GpuRenderer::forward_images`], [`GpuRenderer::backward_images`]) keep the images and
/// `dL/dRGB` on the GPU as [`ImageBatch`]es.
pub struct GpuRenderer {
    ctx: GpuContext,
    kernels: Kernels,
    bufs: Buffers,
    saved: Saved,
    /// Bytes copied back to the CPU by every call so far.
    bytes_read: u64,
}

impl std::fmt::Debug for GpuRenderer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GpuRenderer")
            .field("adapter", &self.ctx.adapter)
            .finish_non_exhaustive()
    }
}

fn params_for(
    n: usize,
    nc: usize,
    width: u32,
    height: u32,
    sh_degree: u32,
    s: &RenderSettings,
) -> Params {
    Params {
        num_gaussians: n as u32,
        num_cameras: nc as u32,
        width,
        height,
        tiles_x: width.div_ceil(TILE),
        tiles_y: height.div_ceil(TILE),
        sh_degree,
        antialiased: s.antialiased as u32,
        eps2d: s.eps2d,
        near_plane: s.near_plane,
        far_plane: s.far_plane,
        alpha_max: s.alpha_max,
        alpha_min: s.alpha_min,
        t_min: s.transmittance_min,
        radius_extent: s.radius_extent,
        ..Params::default()
    }
}

impl GpuRenderer {
    /// Compiles the kernels on `ctx`'s device.
    pub fn new(ctx: &GpuContext) -> Self {
        GpuRenderer {
            ctx: ctx.clone(),
            kernels: Kernels::new(&ctx.device, ctx.subgroups),
            bufs: Buffers::new(),
            saved: Saved::default(),
            bytes_read: 0,
        }
    }

    /// The device and queue the engine runs on.
    pub fn context(&self) -> &GpuContext {
        &self.ctx
    }

    /// Bytes of GPU memory the engine's buffers hold now (they grow to the largest call so
    /// far and are kept).
    pub fn allocated_bytes(&self) -> u64 {
        self.bufs.allocated()
    }

    /// Bytes this engine has copied back to the CPU so far (images, gradients, and the one
    /// intersection count per forward call that sizes the sort).
    pub fn bytes_read_back(&self) -> u64 {
        self.bytes_read
    }

    /// Number of (camera, Gaussian, tile) entries the last forward call sorted and rasterised.
    pub fn intersections(&self) -> u64 {
        self.saved.intersections
    }

    /// The adapter the engine runs on.
    pub fn adapter(&self) -> &AdapterSummary {
        &self.ctx.adapter
    }

    /// Renders `g` from every camera over its background; mirrors
    /// [`gems_splat::Renderer::forward`].
    pub fn forward(
        &mut self,
        g: &Gaussians,
        cams: &[Camera],
        backgrounds: &[[f32; 3]],
        s: &RenderSettings,
    ) -> Result<RenderOutput, GpuError> {
        self.run_forward(Source::Host(g), cams, backgrounds, s)?;
        let sv = self.saved;
        let (nc, n) = (sv.num_cameras, sv.num_gaussians);
        let pixels = (nc * sv.width as usize * sv.height as usize) as u64;
        let encoder = self.ctx.device.create_command_encoder(&Default::default());
        let b = &self.bufs;
        let (rgb_b, aux_b, radii_b) = (
            b.rgb.get().clone(),
            b.aux.get().clone(),
            b.radii.get().clone(),
        );
        let bytes = self.read(
            encoder,
            &[
                (&rgb_b, 0, pixels * 12),
                (&aux_b, 0, pixels * 16),
                (&radii_b, 0, (nc * n) as u64 * 8),
            ],
        )?;
        let rgb = f32s(&bytes[0]);
        let aux = f32s(&bytes[1]);
        let radii_flat = u32s(&bytes[2]);
        let alpha = aux.chunks_exact(4).map(|p| p[0]).collect();
        let depth = s
            .compute_depth
            .then(|| aux.chunks_exact(4).map(|p| p[1]).collect());
        let radii = radii_flat
            .chunks_exact(2)
            .map(|r| [r[0] as i32, r[1] as i32])
            .collect();
        Ok(RenderOutput {
            width: sv.width,
            height: sv.height,
            num_cameras: nc,
            rgb,
            alpha,
            depth,
            radii,
        })
    }

    /// Like [`GpuRenderer::forward`] but leaves the RGB images on the GPU. The batch shares
    /// the engine's output buffer: it is valid until the next forward call.
    pub fn forward_images(
        &mut self,
        g: &Gaussians,
        cams: &[Camera],
        backgrounds: &[[f32; 3]],
        s: &RenderSettings,
    ) -> Result<ImageBatch, GpuError> {
        self.run_forward(Source::Host(g), cams, backgrounds, s)?;
        Ok(self.images())
    }

    /// Renders the resident Gaussians `g` (their parameters are gathered on the GPU; only the
    /// cameras go up and the intersection count comes back) and leaves the RGB images on the
    /// GPU, like [`GpuRenderer::forward_images`]. A batch whose buffers would exceed the
    /// adapter's binding limit fails with [`GpuError::Capacity`]: split its cameras into
    /// chunks ([`CameraChunk`]).
    pub fn forward_resident(
        &mut self,
        g: &GpuGaussians,
        cams: &[Camera],
        backgrounds: &[[f32; 3]],
        s: &RenderSettings,
    ) -> Result<ImageBatch, GpuError> {
        self.run_forward(Source::Resident(g), cams, backgrounds, s)?;
        Ok(self.images())
    }

    fn images(&self) -> ImageBatch {
        ImageBatch {
            buffer: self.bufs.rgb.get().clone(),
            count: self.saved.num_cameras,
            width: self.saved.width,
            height: self.saved.height,
        }
    }

    /// Copies buffer ranges back (one submission) and counts the bytes.
    fn read(
        &mut self,
        encoder: wgpu::CommandEncoder,
        sources: &[(&wgpu::Buffer, u64, u64)],
    ) -> Result<Vec<Vec<u8>>, GpuError> {
        self.bytes_read += sources.iter().map(|s| s.2).sum::<u64>();
        read_back(&self.ctx.device, &self.ctx.queue, encoder, sources)
    }

    fn run_forward(
        &mut self,
        src: Source<'_>,
        cams: &[Camera],
        backgrounds: &[[f32; 3]],
        s: &RenderSettings,
    ) -> Result<(), GpuError> {
        self.saved.valid = false;
        let (width, height) = match src {
            Source::Host(g) => check_inputs(g, cams, backgrounds)?,
            Source::Resident(_) => check_cameras(cams, backgrounds)?,
        };
        let (n, nc) = (src.len(), cams.len());
        let mut p = params_for(n, nc, width, height, src.sh_degree(), s);
        let tiles = (p.tiles_x * p.tiles_y) as usize;
        let pairs = nc * n;
        let indices = pairs.max(nc * tiles) as u64;
        if indices >= u32::MAX as u64 {
            return Err(GpuError::Capacity {
                what: format!("{nc} cameras × {n} Gaussians (32-bit indices)"),
                needed: indices,
                limit: u32::MAX as u64 - 1,
            });
        }
        let pixels = (nc * width as usize * height as usize) as u64;
        let (dev, lim) = (&self.ctx.device, &self.ctx.limits);
        let b = &mut self.bufs;
        let mut enc = dev.create_command_encoder(&Default::default());

        // The Gaussians in the packed layout.
        let gauss = b.gaussians.ensure(dev, lim, (n * GP * 4) as u64)?;
        match src {
            Source::Host(g) => {
                let mut packed = Vec::with_capacity(n * GP);
                for i in 0..n {
                    packed.extend_from_slice(&g.means[i]);
                    packed.extend_from_slice(&g.quats[i]);
                    packed.extend_from_slice(&g.log_scales[i]);
                    packed.push(g.opacity_logits[i]);
                    packed.extend(g.sh[i].iter().flatten());
                }
                if !packed.is_empty() {
                    self.ctx
                        .queue
                        .write_buffer(gauss, 0, bytemuck::cast_slice(&packed));
                }
            }
            Source::Resident(g) => {
                let pp = Params {
                    n: (n * GP) as u32,
                    ..Params::default()
                };
                let groups: Vec<&wgpu::Buffer> =
                    Group::ALL.iter().map(|&gr| &g.group(gr).param).collect();
                dispatch(
                    &self.ctx,
                    &mut enc,
                    &self.kernels.pack_gaussians,
                    &pp,
                    &[groups[0], groups[1], groups[2], groups[3], groups[4], gauss],
                    groups_for(n * GP),
                );
            }
        }
        let mut cam_data = Vec::with_capacity(nc * CAMF);
        for (c, bg) in cams.iter().zip(backgrounds) {
            cam_data.extend_from_slice(&[c.fx, c.fy, c.cx, c.cy]);
            cam_data.extend(c.rotation.iter().flatten());
            cam_data.extend_from_slice(&c.translation);
            cam_data.extend_from_slice(bg);
            cam_data.extend_from_slice(&[0.0; 5]);
        }
        let camb = b.cams.ensure(dev, lim, (nc * CAMF * 4) as u64)?;
        self.ctx
            .queue
            .write_buffer(camb, 0, bytemuck::cast_slice(&cam_data));

        // Projection and tile counts, prefix sum, total read back to size the sort.
        b.splats.ensure(dev, lim, pairs as u64 * SPLAT_BYTES)?;
        b.radii.ensure(dev, lim, pairs as u64 * 8)?;
        b.offsets.ensure(dev, lim, (pairs as u64 + 1) * 4)?;
        dispatch(
            &self.ctx,
            &mut enc,
            &self.kernels.project_forward,
            &p,
            &[
                b.gaussians.get(),
                b.cams.get(),
                b.splats.get(),
                b.radii.get(),
                b.offsets.get(),
            ],
            groups_for(pairs + 1),
        );
        encode_scan(
            &self.ctx,
            &self.kernels,
            &mut enc,
            &mut b.scan_levels,
            b.offsets.get(),
            pairs + 1,
        )?;
        self.bytes_read += 4;
        let total_bytes = read_back(
            dev,
            &self.ctx.queue,
            enc,
            &[(b.offsets.get(), pairs as u64 * 4, 4)],
        )?;
        let total = u32s(&total_bytes[0])[0] as u64;
        // The backward's per-entry gradients (SG floats per entry) are the largest
        // entry-sized buffer: refuse here, before anything is sorted, when they cannot be bound.
        let max_binding = lim.max_storage_buffer_binding_size.min(lim.max_buffer_size);
        if total * SG * 4 > max_binding {
            return Err(GpuError::Capacity {
                what: format!("the gradients of {total} tile entries of {nc} cameras (bytes)"),
                needed: total * SG * 4,
                limit: max_binding,
            });
        }

        let mut enc = dev.create_command_encoder(&Default::default());
        b.ranges.ensure(dev, lim, (nc * tiles) as u64 * 8)?;
        enc.clear_buffer(b.ranges.get(), 0, None);
        b.sorted_splat.ensure(dev, lim, total * 4)?;
        b.sorted_pos.ensure(dev, lim, total * 4)?;
        if total > 0 {
            for k in 0..2 {
                b.key_lo[k].ensure(dev, lim, total * 4)?;
                b.key_hi[k].ensure(dev, lim, total * 4)?;
                b.vals[k].ensure(dev, lim, total * 4)?;
            }
            b.owner.ensure(dev, lim, total * 4)?;
            p.n = pairs as u32;
            dispatch(
                &self.ctx,
                &mut enc,
                &self.kernels.map_intersections,
                &p,
                &[
                    b.splats.get(),
                    b.offsets.get(),
                    b.key_lo[0].get(),
                    b.key_hi[0].get(),
                    b.vals[0].get(),
                    b.owner.get(),
                ],
                groups_for(pairs),
            );
            let cur = encode_sort(
                &self.ctx,
                &self.kernels,
                &mut enc,
                b,
                total as usize,
                (nc * tiles) as u32,
            )?;
            p.n = total as u32;
            dispatch(
                &self.ctx,
                &mut enc,
                &self.kernels.tile_ranges,
                &p,
                &[
                    b.key_hi[cur].get(),
                    b.vals[cur].get(),
                    b.owner.get(),
                    b.ranges.get(),
                    b.sorted_splat.get(),
                    b.sorted_pos.get(),
                ],
                groups_for(total as usize),
            );
        }
        b.rgb.ensure(dev, lim, pixels * 12)?;
        b.aux.ensure(dev, lim, pixels * 16)?;
        dispatch(
            &self.ctx,
            &mut enc,
            &self.kernels.rasterize_forward,
            &p,
            &[
                b.splats.get(),
                b.sorted_splat.get(),
                b.ranges.get(),
                b.cams.get(),
                b.rgb.get(),
                b.aux.get(),
            ],
            (nc * tiles) as u32,
        );
        self.ctx.queue.submit([enc.finish()]);
        self.saved = Saved {
            valid: true,
            num_gaussians: n,
            num_cameras: nc,
            width,
            height,
            intersections: total,
            settings: Some(*s),
        };
        Ok(())
    }

    /// Backward of the last forward call (same `g`, `cams`, `backgrounds`); mirrors
    /// [`gems_splat::Renderer::backward`]. `d_rgb` is `[C,H,W,3]`, `d_alpha` `[C,H,W]`.
    pub fn backward(
        &mut self,
        g: &Gaussians,
        cams: &[Camera],
        backgrounds: &[[f32; 3]],
        d_rgb: &[f32],
        d_alpha: Option<&[f32]>,
    ) -> Result<Gradients, GpuError> {
        let sv = self.check_saved(g, cams, backgrounds)?;
        let pixels = sv.num_cameras * sv.width as usize * sv.height as usize;
        if d_rgb.len() != pixels * 3 {
            return Err(SplatError::Shape(format!(
                "d_rgb has {} values, expected C·H·W·3 = {}",
                d_rgb.len(),
                pixels * 3
            ))
            .into());
        }
        let buf = self
            .bufs
            .d_rgb
            .ensure(&self.ctx.device, &self.ctx.limits, pixels as u64 * 12)?;
        self.ctx
            .queue
            .write_buffer(buf, 0, bytemuck::cast_slice(d_rgb));
        let batch = ImageBatch {
            buffer: buf.clone(),
            count: sv.num_cameras,
            width: sv.width,
            height: sv.height,
        };
        self.backward_images(g, cams, backgrounds, &batch, d_alpha)
    }

    /// Backward of the last forward call with `dL/dRGB` already on the GPU.
    pub fn backward_images(
        &mut self,
        g: &Gaussians,
        cams: &[Camera],
        backgrounds: &[[f32; 3]],
        d_rgb: &ImageBatch,
        d_alpha: Option<&[f32]>,
    ) -> Result<Gradients, GpuError> {
        let sv = self.check_saved(g, cams, backgrounds)?;
        let enc = self.encode_backward(&sv, g.sh_degree, d_rgb, d_alpha, CameraChunk::WHOLE)?;
        let (n, nc) = (sv.num_gaussians, sv.num_cameras);
        let b = &self.bufs;
        let (grads_b, stats_b, pose_b, bg_b) = (
            b.grads.get().clone(),
            b.stats.get().clone(),
            b.pose.get().clone(),
            b.bg_grads.get().clone(),
        );
        let bytes = self.read(
            enc,
            &[
                (&grads_b, 0, (n * GP * 4) as u64),
                (&stats_b, 0, n as u64 * 8),
                (&pose_b, 0, (nc * POSE_FLOATS * 4) as u64),
                (&bg_b, 0, nc as u64 * 12),
            ],
        )?;
        let grads = f32s(&bytes[0]);
        let stats = f32s(&bytes[1]);
        let pose = f32s(&bytes[2]);
        let bg = f32s(&bytes[3]);
        let mut out = Gradients {
            means: Vec::with_capacity(n),
            quats: Vec::with_capacity(n),
            log_scales: Vec::with_capacity(n),
            opacity_logits: Vec::with_capacity(n),
            sh: Vec::with_capacity(n),
            backgrounds: bg.chunks_exact(3).map(|v| [v[0], v[1], v[2]]).collect(),
            cam_rotation: Vec::with_capacity(nc),
            cam_translation: Vec::with_capacity(nc),
            cam_focal: Vec::with_capacity(nc),
            mean2d_grad_norm: Vec::with_capacity(n),
            visible_count: Vec::with_capacity(n),
        };
        for gi in grads.chunks_exact(GP) {
            out.means.push([gi[0], gi[1], gi[2]]);
            out.quats.push([gi[3], gi[4], gi[5], gi[6]]);
            out.log_scales.push([gi[7], gi[8], gi[9]]);
            out.opacity_logits.push(gi[10]);
            let mut sh = [[0.0f32; 3]; SH_COEFFS];
            for (k, row) in sh.iter_mut().enumerate() {
                *row = [gi[11 + 3 * k], gi[12 + 3 * k], gi[13 + 3 * k]];
            }
            out.sh.push(sh);
        }
        for st in stats.chunks_exact(2) {
            out.mean2d_grad_norm.push(st[0]);
            out.visible_count.push(st[1].to_bits());
        }
        for pc in pose.chunks_exact(POSE_FLOATS) {
            out.cam_rotation.push([
                [pc[0], pc[1], pc[2]],
                [pc[3], pc[4], pc[5]],
                [pc[6], pc[7], pc[8]],
            ]);
            out.cam_translation.push([pc[9], pc[10], pc[11]]);
            out.cam_focal.push([pc[12], pc[13]]);
        }
        Ok(out)
    }

    /// Backward of the last [`GpuRenderer::forward_resident`] (same `g`, `cams`,
    /// `backgrounds`) with `dL/dRGB` on the GPU; nothing is read back. On the last chunk of a
    /// batch the Gaussian gradients of the whole batch are written to `out` (as
    /// [`GpuRenderer::backward`] computes them, bit for bit: the sums over cameras continue
    /// across chunks in camera order). Every call leaves this chunk's per-camera pose
    /// gradients in [`GpuRenderer::pose_gradients`].
    pub fn backward_resident(
        &mut self,
        g: &GpuGaussians,
        cams: &[Camera],
        backgrounds: &[[f32; 3]],
        d_rgb: &ImageBatch,
        out: &GpuGradients,
        chunk: CameraChunk,
    ) -> Result<(), GpuError> {
        let sv = self.check_saved_shape(g.len(), cams, backgrounds)?;
        if out.capacity() < g.len() {
            return Err(GpuError::Shape(format!(
                "gradient buffers for {} Gaussians, {} resident",
                out.capacity(),
                g.len()
            )));
        }
        let mut enc = self.encode_backward(&sv, g.sh_degree, d_rgb, None, chunk)?;
        if chunk.last {
            let n = sv.num_gaussians;
            let p = Params {
                n: (n * GP) as u32,
                ..Params::default()
            };
            let b = &self.bufs;
            dispatch(
                &self.ctx,
                &mut enc,
                &self.kernels.unpack_grads,
                &p,
                &[
                    out.group(Group::Means),
                    out.group(Group::Quats),
                    out.group(Group::LogScales),
                    out.group(Group::OpacityLogits),
                    out.group(Group::Sh),
                    b.grads.get(),
                ],
                groups_for(n * GP),
            );
        }
        self.ctx.queue.submit([enc.finish()]);
        Ok(())
    }

    /// The per-camera pose and focal gradients of the last backward call, `[C, POSE_FLOATS]`
    /// f32: dL/dR row-major, dL/dt (world-to-camera), then dL/dfx and dL/dfy of each camera.
    pub fn pose_gradients(&self) -> Result<&wgpu::Buffer, GpuError> {
        if !self.saved.valid {
            return Err(SplatError::NoForward("no successful forward call".into()).into());
        }
        Ok(self.bufs.pose.get())
    }

    /// Records the backward of the last forward (everything up to the pose and background
    /// gradients) into a new encoder.
    fn encode_backward(
        &mut self,
        sv: &Saved,
        sh_degree: u32,
        d_rgb: &ImageBatch,
        d_alpha: Option<&[f32]>,
        chunk: CameraChunk,
    ) -> Result<wgpu::CommandEncoder, GpuError> {
        let s = sv.settings.unwrap_or_default();
        let (n, nc) = (sv.num_gaussians, sv.num_cameras);
        let pixels = nc * sv.width as usize * sv.height as usize;
        if d_rgb.count != nc || d_rgb.width != sv.width || d_rgb.height != sv.height {
            return Err(GpuError::Shape(format!(
                "dL/dRGB holds {} images of {}x{}, the forward rendered {nc} of {}x{}",
                d_rgb.count, d_rgb.width, d_rgb.height, sv.width, sv.height
            )));
        }
        if d_rgb.buffer.size() < pixels as u64 * 12 {
            return Err(GpuError::Shape(format!(
                "dL/dRGB buffer has {} bytes, expected at least {}",
                d_rgb.buffer.size(),
                pixels * 12
            )));
        }
        if let Some(da) = d_alpha
            && da.len() != pixels
        {
            return Err(SplatError::Shape(format!(
                "d_alpha has {} values, expected C·H·W = {pixels}",
                da.len()
            ))
            .into());
        }
        let (dev, lim) = (&self.ctx.device, &self.ctx.limits);
        let b = &mut self.bufs;
        let mut p = params_for(n, nc, sv.width, sv.height, sh_degree, &s);
        let tiles = (p.tiles_x * p.tiles_y) as usize;
        let da_buf = b
            .d_alpha
            .ensure(dev, lim, d_alpha.map_or(4, |d| d.len() as u64 * 4))?;
        if let Some(da) = d_alpha {
            p.has_d_alpha = 1;
            self.ctx
                .queue
                .write_buffer(da_buf, 0, bytemuck::cast_slice(da));
        }
        let total = sv.intersections;
        b.entry_grads.ensure(dev, lim, total * SG * 4)?;
        b.splat_grads.ensure(dev, lim, (nc * n) as u64 * SG * 4)?;
        b.grads.ensure(dev, lim, (n * GP * 4) as u64)?;
        b.stats.ensure(dev, lim, n as u64 * 8)?;
        b.pose_parts
            .ensure(dev, lim, (nc * n * POSE_FLOATS * 4) as u64)?;
        b.pose.ensure(dev, lim, (nc * POSE_FLOATS * 4) as u64)?;
        b.bg_grads.ensure(dev, lim, nc as u64 * 12)?;
        let chunked = chunk != CameraChunk::WHOLE;
        b.carry
            .ensure(dev, lim, if chunked { (n * CARRY * 4) as u64 } else { 0 })?;
        p.carry = u32::from(!chunk.first) | (u32::from(!chunk.last) << 1);

        let mut enc = dev.create_command_encoder(&Default::default());
        enc.clear_buffer(b.entry_grads.get(), 0, None);
        dispatch(
            &self.ctx,
            &mut enc,
            &self.kernels.rasterize_backward,
            &p,
            &[
                b.splats.get(),
                b.sorted_splat.get(),
                b.ranges.get(),
                b.cams.get(),
                b.aux.get(),
                &d_rgb.buffer,
                b.d_alpha.get(),
                b.entry_grads.get(),
            ],
            (nc * tiles) as u32,
        );
        p.n = (nc * n) as u32;
        dispatch(
            &self.ctx,
            &mut enc,
            &self.kernels.sum_intersections,
            &p,
            &[
                b.offsets.get(),
                b.sorted_pos.get(),
                b.entry_grads.get(),
                b.splat_grads.get(),
            ],
            groups_for(nc * n),
        );
        dispatch(
            &self.ctx,
            &mut enc,
            &self.kernels.project_backward,
            &p,
            &[
                b.gaussians.get(),
                b.cams.get(),
                b.radii.get(),
                b.splat_grads.get(),
                b.grads.get(),
                b.stats.get(),
                b.pose_parts.get(),
                b.carry.get(),
            ],
            groups_for(n),
        );
        p.num_blocks = nc as u32;
        p.seg_len = n as u32;
        p.seg_width = POSE_FLOATS as u32;
        dispatch(
            &self.ctx,
            &mut enc,
            &self.kernels.reduce_segments,
            &p,
            &[b.pose_parts.get(), b.pose.get()],
            nc as u32,
        );
        dispatch(
            &self.ctx,
            &mut enc,
            &self.kernels.background_backward,
            &p,
            &[&d_rgb.buffer, b.aux.get(), b.bg_grads.get()],
            nc as u32,
        );
        Ok(enc)
    }

    fn check_saved(
        &self,
        g: &Gaussians,
        cams: &[Camera],
        backgrounds: &[[f32; 3]],
    ) -> Result<Saved, GpuError> {
        check_inputs(g, cams, backgrounds)?;
        self.check_saved_shape(g.len(), cams, backgrounds)
    }

    fn check_saved_shape(
        &self,
        gaussians: usize,
        cams: &[Camera],
        backgrounds: &[[f32; 3]],
    ) -> Result<Saved, GpuError> {
        let (width, height) = check_cameras(cams, backgrounds)?;
        let sv = self.saved;
        if !sv.valid {
            return Err(SplatError::NoForward("no successful forward call".into()).into());
        }
        gems_splat::check_same_batch(
            gems_splat::BatchShape {
                gaussians: sv.num_gaussians,
                cameras: sv.num_cameras,
                width: sv.width as usize,
                height: sv.height as usize,
            },
            gems_splat::BatchShape {
                gaussians,
                cameras: cams.len(),
                width: width as usize,
                height: height as usize,
            },
        )?;
        Ok(sv)
    }
}

/// The camera half of [`check_inputs`] (the resident Gaussians were checked when uploaded).
fn check_cameras(cams: &[Camera], backgrounds: &[[f32; 3]]) -> Result<(u32, u32), SplatError> {
    check_inputs(&Gaussians::with_degree(0), cams, backgrounds)
}

/// Encodes an in-place exclusive prefix sum of the first `n` u32 of `data`: blocks of 256,
/// then the block totals scanned the same way (recursively) and added back.
fn encode_scan(
    ctx: &GpuContext,
    k: &Kernels,
    enc: &mut wgpu::CommandEncoder,
    levels: &mut Vec<Resident>,
    data: &wgpu::Buffer,
    n: usize,
) -> Result<(), GpuError> {
    let gpu = ScanGpu { ctx, k };
    encode_scan_level(&gpu, enc, levels, 0, data, n)
}

/// The device and the kernels, as one argument of the recursive scan.
struct ScanGpu<'a> {
    ctx: &'a GpuContext,
    k: &'a Kernels,
}

fn encode_scan_level(
    gpu: &ScanGpu<'_>,
    enc: &mut wgpu::CommandEncoder,
    levels: &mut Vec<Resident>,
    level: usize,
    data: &wgpu::Buffer,
    n: usize,
) -> Result<(), GpuError> {
    let ScanGpu { ctx, k } = *gpu;
    let (dev, lim) = (&ctx.device, &ctx.limits);
    let blocks = n.div_ceil(WG as usize);
    while levels.len() <= level {
        levels.push(Resident::new("prefix-sum block totals"));
    }
    let sums = levels[level].ensure(dev, lim, blocks as u64 * 4)?.clone();
    let p = Params {
        n: n as u32,
        num_blocks: blocks as u32,
        ..Params::default()
    };
    dispatch(ctx, enc, &k.scan_blocks, &p, &[data, &sums], blocks as u32);
    if blocks > 1 {
        encode_scan_level(gpu, enc, levels, level + 1, &sums, blocks)?;
        dispatch(ctx, enc, &k.add_offsets, &p, &[data, &sums], blocks as u32);
    }
    Ok(())
}

/// Encodes the stable LSD radix sort of the `total` entries in slot 0 of the key/value
/// buffers: 4 passes over the depth bits, then enough passes over the (camera, tile) index for
/// `tile_keys` values. Returns the slot that holds the result.
fn encode_sort(
    ctx: &GpuContext,
    k: &Kernels,
    enc: &mut wgpu::CommandEncoder,
    b: &mut Buffers,
    total: usize,
    tile_keys: u32,
) -> Result<usize, GpuError> {
    let (dev, lim) = (&ctx.device, &ctx.limits);
    let blocks = total.div_ceil(WG as usize);
    let hist = b
        .histogram
        .ensure(dev, lim, blocks as u64 * 256 * 4)?
        .clone();
    let tile_bits = 32 - tile_keys.saturating_sub(1).leading_zeros();
    let mut passes: Vec<(u32, u32)> = (0..4).map(|d| (0, d * 8)).collect();
    passes.extend((0..tile_bits.div_ceil(8)).map(|d| (1, d * 8)));
    let mut cur = 0;
    for (use_hi, shift) in passes {
        let p = Params {
            n: total as u32,
            num_blocks: blocks as u32,
            shift,
            use_hi,
            ..Params::default()
        };
        let src_keys = if use_hi == 1 {
            b.key_hi[cur].get()
        } else {
            b.key_lo[cur].get()
        };
        dispatch(
            ctx,
            enc,
            &k.sort_histogram,
            &p,
            &[src_keys, &hist],
            blocks as u32,
        );
        encode_scan(ctx, k, enc, &mut b.scan_levels, &hist, blocks * 256)?;
        let nxt = 1 - cur;
        dispatch(
            ctx,
            enc,
            &k.sort_scatter,
            &p,
            &[
                b.key_lo[cur].get(),
                b.key_hi[cur].get(),
                b.vals[cur].get(),
                b.key_lo[nxt].get(),
                b.key_hi[nxt].get(),
                b.vals[nxt].get(),
                &hist,
            ],
            blocks as u32,
        );
        cur = nxt;
    }
    Ok(cur)
}

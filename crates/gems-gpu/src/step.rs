//! [`ResidentStep`]: the GeMS training step with the Gaussians and their Adam moments resident
//! on the GPU.
//!
//! Per step ([`ResidentStep::step`]): the n virtual cameras of one view go up (n × 24 floats);
//! the resident Gaussians are rendered from them ([`GpuRenderer::forward_resident`]), the blur
//! mean, fused loss and dL/d(render_k) are computed against the view's image, resident since
//! the view's first step ([`BlurLoss`]); the backward writes the Gaussian gradients into
//! resident buffers ([`GpuRenderer::backward_resident`]); the MCMC regularisers add theirs
//! ([`GpuRegularizers`]) and Adam updates every group ([`GpuAdam`]). What comes back is the
//! per-camera pose gradients (48 bytes per camera, for the trajectory update that stays on the
//! CPU), the loss, PSNR and regulariser value (12 bytes) and, per renderer call, the 4-byte
//! intersection count that sizes the sort ([`ResidentStep::bytes_read_back`] counts them all).
//! MCMC noise ([`ResidentStep::noise`]) runs on the GPU; relocation and growth
//! ([`ResidentStep::relocate`], [`ResidentStep::grow`]) take draws made on the CPU from
//! [`ResidentStep::opacity_logits`] (4 bytes per Gaussian, once per refine period).
//!
//! Camera chunks: when one call over all n cameras needs a buffer larger than the adapter can
//! bind ([`GpuError::Capacity`]; lavapipe binds 128 MiB), the cameras are rendered in chunks of
//! at most [`ResidentStep::max_cameras_per_call`] (shrunk in proportion to the overflow until a
//! call fits, then kept). The forward renders the chunks last to first into one image batch;
//! the backward runs them first to last, re-rendering every chunk but the first (whose forward
//! state the renderer still holds), with the per-Gaussian sums carried between chunks in camera
//! order ([`CameraChunk`]): the result is bit-identical to one call over all cameras, at the
//! cost of one extra forward per extra chunk. The Gaussians themselves are not split: one call
//! needs about 250 bytes per Gaussian in a single binding (about 530k Gaussians on lavapipe).
//!
//! Memory: each training image is uploaded at its view's first step and stays resident
//! (H·W·12 bytes: 1.3 MB at 400×270, 32 MB for 25 views); [`ResidentStep::allocated_bytes`]
//! and [`GpuRenderer::allocated_bytes`] report what the step and the renderer hold.

use gems_splat::{Camera, Gaussians, RenderSettings};

use crate::adam::{AdamConfig, GaussianLrs, GpuAdam};
use crate::buffers;
use crate::kernels::{f32s, read_back};
use crate::loss::BlurLoss;
use crate::mcmc::{GpuMcmc, NoiseParams};
use crate::params::{GpuGaussians, GpuGradients, Group, GroupMoments};
use crate::regularize::GpuRegularizers;
use crate::renderer::{CameraChunk, GpuRenderer, POSE_FLOATS};
use crate::{GpuContext, GpuError, ImageBatch};

/// The constants of a step that are not per view.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepSettings {
    /// λ of (1−λ)·L1 + λ·(1 − SSIM).
    pub ssim_lambda: f32,
    /// MCMC opacity and scale regulariser weights.
    pub opacity_reg: f32,
    pub scale_reg: f32,
    /// This step's learning rates (the means lr already decayed).
    pub lrs: GaussianLrs,
    pub adam: AdamConfig,
    pub render: RenderSettings,
}

/// What one step reads back.
#[derive(Clone, Debug, PartialEq)]
pub struct StepResult {
    /// Fused loss plus the regularisers (the trainer's loss curve).
    pub loss: f32,
    /// The fused loss alone, (1−λ)·L1 + λ·(1−SSIM) of the blur model against the view's image.
    pub photometric_loss: f32,
    /// PSNR of the blurred render against the view's image.
    pub psnr: f32,
    /// dL/dR (row-major) of each virtual camera (world-to-camera).
    pub cam_rotation: Vec<[[f32; 3]; 3]>,
    /// dL/dt of each virtual camera.
    pub cam_translation: Vec<[f32; 3]>,
    /// (dL/dfx, dL/dfy) per camera.
    pub cam_focal: Vec<[f32; 2]>,
}

/// The Gaussians, their Adam moments, the training images and every per-step buffer,
/// resident on one GPU (module docs).
pub struct ResidentStep {
    ctx: GpuContext,
    gaussians: GpuGaussians,
    grads: GpuGradients,
    adam: GpuAdam,
    mcmc: GpuMcmc,
    reg: GpuRegularizers,
    /// One loss per (height, width, λ bits), made for the most views a step there has had.
    losses: Vec<((usize, usize, u32), BlurLoss)>,
    /// Each view's image, uploaded at its first step.
    targets: Vec<Option<wgpu::Buffer>>,
    /// The renders of a chunked batch, `[n,H,W,3]`.
    renders: Option<wgpu::Buffer>,
    /// One chunk's dL/d(render).
    d_chunk: Option<wgpu::Buffer>,
    /// Pose gradients of the batch, `[n,12]`.
    pose: Option<wgpu::Buffer>,
    max_cameras: usize,
    bytes_read: u64,
}

impl ResidentStep {
    /// Uploads `g` and, when given, the Adam moments of its groups (in [`Group::ALL`] order;
    /// zero moments otherwise).
    pub fn new(
        ctx: &GpuContext,
        g: &Gaussians,
        moments: Option<&[GroupMoments; 5]>,
    ) -> Result<Self, GpuError> {
        let mut gaussians = GpuGaussians::upload(ctx, g, g.len())?;
        if let Some(ms) = moments {
            for (group, m) in Group::ALL.into_iter().zip(ms) {
                gaussians.set_moments(ctx, group, m)?;
            }
        }
        Ok(ResidentStep {
            grads: GpuGradients::new(ctx, gaussians.capacity())?,
            gaussians,
            adam: GpuAdam::new(ctx),
            mcmc: GpuMcmc::new(ctx)?,
            reg: GpuRegularizers::new(ctx)?,
            ctx: ctx.clone(),
            losses: Vec::new(),
            targets: Vec::new(),
            renders: None,
            d_chunk: None,
            pose: None,
            max_cameras: usize::MAX,
            bytes_read: 0,
        })
    }

    /// The device the state lives on.
    pub fn context(&self) -> &GpuContext {
        &self.ctx
    }

    /// Live Gaussians.
    pub fn len(&self) -> usize {
        self.gaussians.len()
    }

    pub fn is_empty(&self) -> bool {
        self.gaussians.is_empty()
    }

    /// Sets the active SH degree (the trainer's schedule).
    pub fn set_sh_degree(&mut self, degree: u32) {
        self.gaussians.sh_degree = degree;
    }

    /// The most cameras one renderer call takes (unlimited until a call exceeds the adapter's
    /// buffer limits).
    pub fn max_cameras_per_call(&self) -> usize {
        self.max_cameras
    }

    /// Caps the cameras per renderer call (at least 1): forces the chunked path (tests) or
    /// bounds memory.
    pub fn set_max_cameras_per_call(&mut self, cameras: usize) {
        self.max_cameras = cameras.max(1);
    }

    /// Bytes copied back to the CPU by this state's steps, MCMC round trips and downloads.
    pub fn bytes_read_back(&self) -> u64 {
        self.bytes_read
    }

    /// One training step on view `view` (module docs): `target` (`[H,W,3]`, the view's blurry
    /// image) is uploaded at the view's first step and kept; `cams` are its n virtual cameras,
    /// all over `background`.
    pub fn step(
        &mut self,
        r: &mut GpuRenderer,
        view: usize,
        target: &[f32],
        cams: &[Camera],
        background: [f32; 3],
        s: &StepSettings,
    ) -> Result<StepResult, GpuError> {
        if r.context().device != self.ctx.device {
            return Err(GpuError::Shape(
                "the renderer and the resident state are on different devices".into(),
            ));
        }
        let first = cams
            .first()
            .ok_or_else(|| GpuError::Shape("a step needs at least one camera".into()))?;
        let (w, h, nc) = (first.width as usize, first.height as usize, cams.len());
        let len = w * h * 3;
        if target.len() != len {
            return Err(GpuError::Shape(format!(
                "view {view}: image has {} values, the cameras are {w}x{h}x3",
                target.len()
            )));
        }
        let read_before = r.bytes_read_back();
        let li = self.loss_for(h, w, nc, s.ssim_lambda)?;
        let target_buf = self.target(view, target)?;
        let bgs = vec![background; nc];

        let renders = self.render(r, cams, &bgs, &s.render)?;
        let loss = &self.losses[li].1;
        loss.run(&self.ctx, &renders, &target_buf)?;
        let d_renders = loss.d_renders().clone();
        let pose = self.backpropagate(r, cams, &bgs, &d_renders, &s.render)?;

        // Regularisers and Adam, then the one read-back of the step.
        let mut enc = buffers::encoder(&self.ctx, "resident step");
        self.reg.encode(
            &self.ctx,
            &mut enc,
            &self.gaussians,
            &self.grads,
            s.opacity_reg,
            s.scale_reg,
        )?;
        self.adam.encode_gaussians(
            &self.ctx,
            &mut enc,
            &mut self.gaussians,
            &self.grads,
            &s.lrs,
            s.adam,
        )?;
        let loss = &self.losses[li].1;
        let sources = [
            (&pose, 0, (nc * POSE_FLOATS * 4) as u64),
            (loss.scalars(), 0, 16),
            (self.reg.value(), 0, 4),
        ];
        let bytes = read_back(&self.ctx.device, &self.ctx.queue, enc, &sources)?;
        self.bytes_read += sources.iter().map(|s| s.2).sum::<u64>();
        self.bytes_read += r.bytes_read_back() - read_before;
        let pose = f32s(&bytes[0]);
        let scalars = f32s(&bytes[1]);
        let reg = f32s(&bytes[2])[0];
        Ok(StepResult {
            loss: scalars[0] + reg,
            photometric_loss: scalars[0],
            psnr: scalars[3],
            cam_rotation: pose
                .chunks_exact(POSE_FLOATS)
                .map(|p| [[p[0], p[1], p[2]], [p[3], p[4], p[5]], [p[6], p[7], p[8]]])
                .collect(),
            cam_translation: pose
                .chunks_exact(POSE_FLOATS)
                .map(|p| [p[9], p[10], p[11]])
                .collect(),
            cam_focal: pose
                .chunks_exact(POSE_FLOATS)
                .map(|p| [p[12], p[13]])
                .collect(),
        })
    }

    /// The forward half of [`Self::step`]: renders the resident Gaussians from every camera
    /// into one `[n,H,W,3]` batch (valid until the next call), in camera chunks when one call
    /// exceeds the adapter's limits (module docs). Exposed for benchmarks.
    pub fn render(
        &mut self,
        r: &mut GpuRenderer,
        cams: &[Camera],
        bgs: &[[f32; 3]],
        s: &RenderSettings,
    ) -> Result<wgpu::Buffer, GpuError> {
        let nc = cams.len();
        loop {
            let chunk = self.max_cameras.min(nc);
            match self.forward_all(r, cams, bgs, s) {
                Err(GpuError::Capacity {
                    what,
                    needed,
                    limit,
                }) if chunk > 1 => {
                    // Every size that can overflow grows about linearly with the cameras per
                    // call: scale the chunk by limit/needed, and shrink it by at least one.
                    let scaled = (chunk as u128 * limit as u128 / needed.max(1) as u128) as usize;
                    self.max_cameras = scaled.clamp(1, chunk - 1);
                    tracing::debug!(
                        cameras = self.max_cameras,
                        "{what} needs {needed}, the adapter allows {limit}: fewer cameras per call"
                    );
                }
                other => return other,
            }
        }
    }

    /// The backward half of [`Self::step`], right after [`Self::render`] of the same cameras:
    /// writes the Gaussian gradients of `dL/d(render)` (`d_renders`, `[n,H,W,3]`) to the
    /// resident gradient buffers and returns the buffer of the per-camera pose gradients
    /// (`[n,12]`: dL/dR row-major, dL/dt). Chunked like the render, first chunk first (its
    /// forward state is the renderer's; the others are rendered again). Exposed for
    /// benchmarks.
    pub fn backpropagate(
        &mut self,
        r: &mut GpuRenderer,
        cams: &[Camera],
        bgs: &[[f32; 3]],
        d_renders: &wgpu::Buffer,
        s: &RenderSettings,
    ) -> Result<wgpu::Buffer, GpuError> {
        let nc = cams.len();
        let first = cams
            .first()
            .ok_or_else(|| GpuError::Shape("a step needs at least one camera".into()))?;
        let (w, h) = (first.width, first.height);
        let len = (w * h * 3) as usize;
        if d_renders.size() < (nc * len * 4) as u64 {
            return Err(GpuError::Shape(format!(
                "dL/drender holds {} values, {nc} images of {w}x{h} need {}",
                d_renders.size() / 4,
                nc * len
            )));
        }
        if self.grads.capacity() < self.gaussians.len() {
            self.grads = GpuGradients::new(&self.ctx, self.gaussians.capacity())?;
        }
        let pose = sized(
            &self.ctx,
            &mut self.pose,
            "pose gradients",
            nc * POSE_FLOATS,
        )?;
        let chunk = self.max_cameras.min(nc);
        if chunk == nc {
            let d = ImageBatch {
                buffer: d_renders.clone(),
                count: nc,
                width: w,
                height: h,
            };
            r.backward_resident(
                &self.gaussians,
                cams,
                bgs,
                &d,
                &self.grads,
                CameraChunk::WHOLE,
            )?;
            self.copy(r.pose_gradients()?, 0, &pose, 0, nc * POSE_FLOATS);
            return Ok(pose);
        }
        let d_chunk = sized(
            &self.ctx,
            &mut self.d_chunk,
            "chunk dL/drender",
            chunk * len,
        )?;
        let starts: Vec<usize> = (0..nc).step_by(chunk).collect();
        for (k, &a) in starts.iter().enumerate() {
            let b = (a + chunk).min(nc);
            if k > 0 {
                r.forward_resident(&self.gaussians, &cams[a..b], &bgs[a..b], s)?;
            }
            self.copy(d_renders, a * len, &d_chunk, 0, (b - a) * len);
            let batch = ImageBatch {
                buffer: d_chunk.clone(),
                count: b - a,
                width: w,
                height: h,
            };
            let part = CameraChunk {
                first: k == 0,
                last: b == nc,
            };
            r.backward_resident(
                &self.gaussians,
                &cams[a..b],
                &bgs[a..b],
                &batch,
                &self.grads,
                part,
            )?;
            self.copy(
                r.pose_gradients()?,
                0,
                &pose,
                a * POSE_FLOATS,
                (b - a) * POSE_FLOATS,
            );
        }
        Ok(pose)
    }

    /// Renders every camera into one batch, in chunks of at most `max_cameras` (last chunk
    /// first, so that the renderer keeps the first chunk's state for the backward).
    fn forward_all(
        &mut self,
        r: &mut GpuRenderer,
        cams: &[Camera],
        bgs: &[[f32; 3]],
        s: &RenderSettings,
    ) -> Result<wgpu::Buffer, GpuError> {
        let nc = cams.len();
        let chunk = self.max_cameras.min(nc);
        if chunk == nc {
            return Ok(r.forward_resident(&self.gaussians, cams, bgs, s)?.buffer);
        }
        let len = (cams[0].width * cams[0].height * 3) as usize;
        let renders = sized(&self.ctx, &mut self.renders, "chunked renders", nc * len)?;
        let starts: Vec<usize> = (0..nc).step_by(chunk).collect();
        for &a in starts.iter().rev() {
            let b = (a + chunk).min(nc);
            let batch = r.forward_resident(&self.gaussians, &cams[a..b], &bgs[a..b], s)?;
            self.copy(&batch.buffer, 0, &renders, a * len, (b - a) * len);
        }
        Ok(renders)
    }

    /// Submits a copy of `count` f32 from value `src_at` of `src` to value `dst_at` of `dst`.
    fn copy(
        &self,
        src: &wgpu::Buffer,
        src_at: usize,
        dst: &wgpu::Buffer,
        dst_at: usize,
        count: usize,
    ) {
        let mut enc = buffers::encoder(&self.ctx, "chunk copy");
        enc.copy_buffer_to_buffer(
            src,
            src_at as u64 * 4,
            dst,
            dst_at as u64 * 4,
            count as u64 * 4,
        );
        self.ctx.queue.submit([enc.finish()]);
    }

    fn loss_for(
        &mut self,
        h: usize,
        w: usize,
        views: usize,
        lambda: f32,
    ) -> Result<usize, GpuError> {
        // One loss per image size, made for the most views seen at that size: a run whose view
        // count adapts per step (gems-train's `virtual_view_spacing_px`) reuses it.
        let key = (h, w, lambda.to_bits());
        match self.losses.iter().position(|(k, _)| *k == key) {
            Some(i) if self.losses[i].1.capacity() >= views => {
                self.losses[i].1.set_views(&self.ctx, views)?;
                Ok(i)
            }
            found => {
                let loss = BlurLoss::new(&self.ctx, h, w, views, lambda)?;
                match found {
                    Some(i) => {
                        self.losses[i].1 = loss;
                        Ok(i)
                    }
                    None => {
                        self.losses.push((key, loss));
                        Ok(self.losses.len() - 1)
                    }
                }
            }
        }
    }

    /// The resident image of `view`, uploaded now if this is its first step at this size.
    fn target(&mut self, view: usize, image: &[f32]) -> Result<wgpu::Buffer, GpuError> {
        if self.targets.len() <= view {
            self.targets.resize(view + 1, None);
        }
        // A view's image is uploaded again when its size changes (coarse-to-fine training).
        if let Some(b) = &self.targets[view]
            && b.size() == size_of_val(image) as u64
        {
            return Ok(b.clone());
        }
        let b = buffers::upload(&self.ctx, "training image", image)?;
        self.targets[view] = Some(b.clone());
        Ok(b)
    }

    /// Bytes of GPU memory held by the training images uploaded so far.
    pub fn image_bytes(&self) -> u64 {
        self.targets.iter().flatten().map(|b| b.size()).sum()
    }

    /// Bytes of GPU memory this state holds: the Gaussians with their moments and gradients,
    /// the images, the losses' and the chunks' buffers (the renderer's own are
    /// [`GpuRenderer::allocated_bytes`]).
    pub fn allocated_bytes(&self) -> u64 {
        let per_row: u64 = Group::ALL.iter().map(|g| g.width() as u64 * 4).sum();
        let params = self.gaussians.capacity() as u64 * per_row * 3;
        let grads = self.grads.capacity() as u64 * per_row;
        let extra: u64 = [&self.renders, &self.d_chunk, &self.pose]
            .iter()
            .filter_map(|b| b.as_ref().map(|b| b.size()))
            .sum();
        let losses: u64 = self.losses.iter().map(|(_, l)| l.allocated_bytes()).sum();
        params + grads + self.image_bytes() + extra + losses
    }

    /// Records and submits one SGLD noise step (Philox noise keyed by `p.seed`, `p.step`).
    pub fn noise(&mut self, p: &NoiseParams) {
        let mut enc = buffers::encoder(&self.ctx, "mcmc noise");
        self.mcmc
            .encode_noise(&self.ctx, &mut enc, &self.gaussians, p);
        self.ctx.queue.submit([enc.finish()]);
    }

    /// The opacity logits (the input of the CPU's relocation and growth draws).
    pub fn opacity_logits(&mut self) -> Result<Vec<f32>, GpuError> {
        let out = self
            .mcmc
            .download_opacity_logits(&self.ctx, &self.gaussians)?;
        self.bytes_read += out.len() as u64 * 4;
        Ok(out)
    }

    /// MCMC relocation given the CPU's draws (see [`GpuMcmc::relocate`]).
    pub fn relocate(
        &mut self,
        dead: &[usize],
        sources: &[usize],
        min_opacity: f32,
    ) -> Result<usize, GpuError> {
        self.mcmc
            .relocate(&self.ctx, &mut self.gaussians, dead, sources, min_opacity)
    }

    /// MCMC growth given the CPU's draws (see [`GpuMcmc::grow`]).
    pub fn grow(&mut self, sources: &[usize], min_opacity: f32) -> Result<usize, GpuError> {
        self.mcmc
            .grow(&self.ctx, &mut self.gaussians, sources, min_opacity)
    }

    /// Downloads the Gaussians and the Adam moments of every group ([`Group::ALL`] order).
    pub fn download(&mut self) -> Result<(Gaussians, [GroupMoments; 5]), GpuError> {
        let (ctx, res) = (&self.ctx, &self.gaussians);
        let g = res.download(ctx)?;
        let moments = [
            res.moments(ctx, Group::Means)?,
            res.moments(ctx, Group::Quats)?,
            res.moments(ctx, Group::LogScales)?,
            res.moments(ctx, Group::OpacityLogits)?,
            res.moments(ctx, Group::Sh)?,
        ];
        // Parameters, m and v: three values per parameter.
        let per_gaussian: usize = Group::ALL.iter().map(|g| g.width()).sum();
        self.bytes_read += (g.len() * per_gaussian * 3 * 4) as u64;
        Ok((g, moments))
    }
}

/// `slot`'s buffer, (re)allocated to hold at least `count` f32.
fn sized(
    ctx: &GpuContext,
    slot: &mut Option<wgpu::Buffer>,
    label: &str,
    count: usize,
) -> Result<wgpu::Buffer, GpuError> {
    if let Some(b) = slot
        && b.size() >= count as u64 * 4
    {
        return Ok(b.clone());
    }
    let b = buffers::storage_buffer(ctx, label, count)?;
    *slot = Some(b.clone());
    Ok(b)
}

//! Gaussian parameters and their Adam moments, resident on the GPU.
//!
//! Layout (what the rasterizer and every training kernel read): one structure-of-arrays group per
//! parameter, exactly the row layout of `gems_splat::Gaussians` and of gems-train's Adam groups,
//! each a flat `array<f32>` of `capacity × width` values of which the first `len` rows are live:
//!
//! | group            | width | row i holds                                   |
//! |------------------|-------|-----------------------------------------------|
//! | `means`          | 3     | x, y, z at `3i..3i+3`                          |
//! | `quats`          | 4     | w, x, y, z (not normalised) at `4i..4i+4`      |
//! | `log_scales`     | 3     | ln sx, ln sy, ln sz at `3i..3i+3`              |
//! | `opacity_logits` | 1     | logit(o) at `i`                               |
//! | `sh`             | 48    | coefficient k, channel c at `48i + 3k + c`; columns 0..3 are the dc term |
//!
//! (vec3 groups are three packed f32, not WGSL `vec3<f32>`, whose stride would be 16 bytes.)
//! Each group has its parameter buffer, its Adam first and second moments `m`, `v` (same layout)
//! and a CPU-side Adam step counter. All 16 SH coefficients are stored whatever the active degree
//! (`sh_degree` is kept on the CPU side), as on the CPU. Capacity can exceed `len` so that MCMC
//! growth appends rows without reallocating; [`GpuGaussians::reserve`] grows it by copying.

use gems_splat::{Gaussians, SH_COEFFS};

use crate::buffers;
use crate::{GpuContext, GpuError};

/// One parameter group of the Gaussians.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Group {
    Means,
    Quats,
    LogScales,
    OpacityLogits,
    Sh,
}

impl Group {
    /// All groups, in the order of [`GpuGaussians::groups`].
    pub const ALL: [Group; 5] = [
        Group::Means,
        Group::Quats,
        Group::LogScales,
        Group::OpacityLogits,
        Group::Sh,
    ];

    /// f32 values per Gaussian.
    pub fn width(self) -> usize {
        match self {
            Group::Means | Group::LogScales => 3,
            Group::Quats => 4,
            Group::OpacityLogits => 1,
            Group::Sh => 3 * SH_COEFFS,
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Group::Means => "means",
            Group::Quats => "quats",
            Group::LogScales => "log_scales",
            Group::OpacityLogits => "opacity_logits",
            Group::Sh => "sh",
        }
    }

    fn index(self) -> usize {
        self as usize
    }
}

/// The buffers of one group: parameters and Adam moments, `capacity × width` f32 each.
pub struct GroupBuffers {
    pub param: wgpu::Buffer,
    pub m: wgpu::Buffer,
    pub v: wgpu::Buffer,
    /// Adam steps taken by this group (bias correction), as `AdamState::step` on the CPU.
    pub adam_step: u64,
}

/// Adam state of one group, on the CPU (to move it to and from gems-train's `AdamState`).
#[derive(Clone, Debug, PartialEq)]
pub struct GroupMoments {
    pub m: Vec<f32>,
    pub v: Vec<f32>,
    pub step: u64,
}

/// The Gaussians of a scene and their Adam state, resident on the GPU (layout: module docs).
pub struct GpuGaussians {
    len: usize,
    capacity: usize,
    /// Active SH degree (the CPU `Gaussians::sh_degree`).
    pub sh_degree: u32,
    groups: [GroupBuffers; 5],
}

fn group_slice(g: &Gaussians, group: Group) -> &[f32] {
    match group {
        Group::Means => bytemuck::cast_slice(&g.means),
        Group::Quats => bytemuck::cast_slice(&g.quats),
        Group::LogScales => bytemuck::cast_slice(&g.log_scales),
        Group::OpacityLogits => &g.opacity_logits,
        Group::Sh => bytemuck::cast_slice(&g.sh),
    }
}

impl GpuGaussians {
    /// Uploads `g` with zero Adam moments, room for `capacity` Gaussians (at least `g.len()`).
    pub fn upload(ctx: &GpuContext, g: &Gaussians, capacity: usize) -> Result<Self, GpuError> {
        g.validate()?;
        let len = g.len();
        let capacity = capacity.max(len).max(1);
        let make = |group: Group| -> Result<GroupBuffers, GpuError> {
            let w = group.width();
            let name = group.name();
            let param = buffers::storage_buffer(ctx, name, capacity * w)?;
            if len > 0 {
                ctx.queue
                    .write_buffer(&param, 0, bytemuck::cast_slice(group_slice(g, group)));
            }
            Ok(GroupBuffers {
                param,
                m: buffers::storage_buffer(ctx, name, capacity * w)?,
                v: buffers::storage_buffer(ctx, name, capacity * w)?,
                adam_step: 0,
            })
        };
        Ok(GpuGaussians {
            len,
            capacity,
            sh_degree: g.sh_degree,
            groups: [
                make(Group::Means)?,
                make(Group::Quats)?,
                make(Group::LogScales)?,
                make(Group::OpacityLogits)?,
                make(Group::Sh)?,
            ],
        })
    }

    /// Live Gaussians.
    pub fn len(&self) -> usize {
        self.len
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Rows allocated in every buffer.
    pub fn capacity(&self) -> usize {
        self.capacity
    }

    pub fn group(&self, group: Group) -> &GroupBuffers {
        &self.groups[group.index()]
    }

    pub fn group_mut(&mut self, group: Group) -> &mut GroupBuffers {
        &mut self.groups[group.index()]
    }

    /// All groups, in [`Group::ALL`] order.
    pub fn groups(&self) -> &[GroupBuffers; 5] {
        &self.groups
    }

    /// Sets the live row count (rows between the old and new count must have been written).
    pub(crate) fn set_len(&mut self, len: usize) {
        assert!(
            len <= self.capacity,
            "len {len} over capacity {}",
            self.capacity
        );
        self.len = len;
    }

    /// Downloads the live Gaussians (waits for the GPU).
    pub fn download(&self, ctx: &GpuContext) -> Result<Gaussians, GpuError> {
        let n = self.len;
        let read = |group: Group| -> Result<Vec<f32>, GpuError> {
            buffers::download(ctx, &self.group(group).param, 0, n * group.width())
        };
        Ok(Gaussians {
            means: bytemuck::cast_slice(&read(Group::Means)?).to_vec(),
            quats: bytemuck::cast_slice(&read(Group::Quats)?).to_vec(),
            log_scales: bytemuck::cast_slice(&read(Group::LogScales)?).to_vec(),
            opacity_logits: read(Group::OpacityLogits)?,
            sh: bytemuck::cast_slice(&read(Group::Sh)?).to_vec(),
            sh_degree: self.sh_degree,
        })
    }

    /// Overwrites the live parameters with `g` (same count; e.g. after a CPU-side edit).
    pub fn write(&mut self, ctx: &GpuContext, g: &Gaussians) -> Result<(), GpuError> {
        g.validate()?;
        if g.len() != self.len {
            return Err(GpuError::Shape(format!(
                "writing {} Gaussians over {} resident ones",
                g.len(),
                self.len
            )));
        }
        for group in Group::ALL {
            if self.len > 0 {
                ctx.queue.write_buffer(
                    &self.group(group).param,
                    0,
                    bytemuck::cast_slice(group_slice(g, group)),
                );
            }
        }
        self.sh_degree = g.sh_degree;
        Ok(())
    }

    /// Downloads the Adam state of one group (live rows only).
    pub fn moments(&self, ctx: &GpuContext, group: Group) -> Result<GroupMoments, GpuError> {
        let b = self.group(group);
        let n = self.len * group.width();
        Ok(GroupMoments {
            m: buffers::download(ctx, &b.m, 0, n)?,
            v: buffers::download(ctx, &b.v, 0, n)?,
            step: b.adam_step,
        })
    }

    /// Uploads the Adam state of one group (e.g. from a CPU checkpoint).
    pub fn set_moments(
        &mut self,
        ctx: &GpuContext,
        group: Group,
        moments: &GroupMoments,
    ) -> Result<(), GpuError> {
        let n = self.len * group.width();
        if moments.m.len() != n || moments.v.len() != n {
            return Err(GpuError::Shape(format!(
                "{} moments hold {}/{} values, {} Gaussians need {n}",
                group.name(),
                moments.m.len(),
                moments.v.len(),
                self.len
            )));
        }
        let b = self.group_mut(group);
        if n > 0 {
            ctx.queue
                .write_buffer(&b.m, 0, bytemuck::cast_slice(&moments.m));
            ctx.queue
                .write_buffer(&b.v, 0, bytemuck::cast_slice(&moments.v));
        }
        b.adam_step = moments.step;
        Ok(())
    }

    /// Grows every buffer to hold `capacity` Gaussians, keeping the live rows and moments.
    pub fn reserve(&mut self, ctx: &GpuContext, capacity: usize) -> Result<(), GpuError> {
        if capacity <= self.capacity {
            return Ok(());
        }
        let mut enc = buffers::encoder(ctx, "reserve gaussians");
        for group in Group::ALL {
            let w = group.width();
            let bytes = (self.len * w * 4) as u64;
            let b = &mut self.groups[group.index()];
            for old in [&mut b.param, &mut b.m, &mut b.v] {
                let new = buffers::storage_buffer(ctx, group.name(), capacity * w)?;
                if bytes > 0 {
                    enc.copy_buffer_to_buffer(old, 0, &new, 0, bytes);
                }
                *old = new;
            }
        }
        ctx.queue.submit([enc.finish()]);
        self.capacity = capacity;
        Ok(())
    }
}

/// Per-Gaussian gradients in the layout of [`GpuGaussians`] (one buffer per group, `capacity ×
/// width` f32): what the rasterizer backward writes and [`crate::GpuAdam`] reads.
pub struct GpuGradients {
    buffers: [wgpu::Buffer; 5],
    capacity: usize,
}

impl GpuGradients {
    /// Zeroed gradient buffers for `capacity` Gaussians.
    pub fn new(ctx: &GpuContext, capacity: usize) -> Result<Self, GpuError> {
        let capacity = capacity.max(1);
        let make = |g: Group| buffers::storage_buffer(ctx, g.name(), capacity * g.width());
        Ok(GpuGradients {
            buffers: [
                make(Group::Means)?,
                make(Group::Quats)?,
                make(Group::LogScales)?,
                make(Group::OpacityLogits)?,
                make(Group::Sh)?,
            ],
            capacity,
        })
    }

    /// Gradient buffers holding the Gaussian part of CPU `gems_splat::Gradients`.
    pub fn upload(
        ctx: &GpuContext,
        g: &gems_splat::Gradients,
        capacity: usize,
    ) -> Result<Self, GpuError> {
        let n = g.means.len();
        let lens = [
            g.quats.len(),
            g.log_scales.len(),
            g.opacity_logits.len(),
            g.sh.len(),
        ];
        if lens.iter().any(|&l| l != n) {
            return Err(GpuError::Shape(format!(
                "gradient groups disagree in length: {n} means, {lens:?} others"
            )));
        }
        let out = Self::new(ctx, capacity.max(n))?;
        let slices: [&[f32]; 5] = [
            bytemuck::cast_slice(&g.means),
            bytemuck::cast_slice(&g.quats),
            bytemuck::cast_slice(&g.log_scales),
            &g.opacity_logits,
            bytemuck::cast_slice(&g.sh),
        ];
        for (b, s) in out.buffers.iter().zip(slices) {
            if !s.is_empty() {
                ctx.queue.write_buffer(b, 0, bytemuck::cast_slice(s));
            }
        }
        Ok(out)
    }

    pub fn capacity(&self) -> usize {
        self.capacity
    }

    pub fn group(&self, group: Group) -> &wgpu::Buffer {
        &self.buffers[group.index()]
    }
}

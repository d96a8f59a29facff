//! 3DGS-MCMC on resident Gaussians: SGLD position noise, relocation and growth.
//!
//! * Noise ([`GpuMcmc::encode_noise`]): μ += R S² Rᵀ ε · sigmoid(−100(o − min_opacity)) · scale
//!   for every Gaussian, gems-train's `mcmc::apply_noise` in the same f32 order. ε comes from
//!   Philox4x32-10 keyed by the run's seed at counter (row, step, stream) ([`crate::rng`]), so
//!   the noise of a row depends only on (seed, step, row): reproducible for a seed on any
//!   device, up to the few-ulp differences of each GPU's `log`/`cos`/`sin`/`exp`. It is not the
//!   CPU trainer's ChaCha8 stream, so a GPU run does not retrace a CPU run draw for draw.
//! * Relocation and growth ([`GpuMcmc::relocate`], [`GpuMcmc::grow`]): the multinomial draws of
//!   which rows to copy stay on the CPU (gems-train's `mcmc::relocation_draws` /
//!   `growth_draws`, so a seeded run draws exactly the CPU's samples). Once per refine period
//!   the caller downloads the opacity logits (4 bytes per Gaussian,
//!   [`GpuMcmc::download_opacity_logits`]), draws, and hands the rows back; the update itself —
//!   the binomial-table split of each source, the row copies, the Adam-moment resets — runs on
//!   the GPU. Only the opacities go down and the row indices go up (4–8 bytes per drawn row);
//!   BENCHMARKS.md has the measured cost of the round trip.
//!
//! Adam state follows gsplat (and gems-train): relocation zeroes the moments of the SOURCE rows
//! only (dead rows keep their stale moments); growth appends rows with zero moments.

use std::collections::BTreeMap;

use bytemuck::{Pod, Zeroable};

use crate::buffers::{self, FLAT_INDEX_WGSL, Kernel};
use crate::params::{GpuGaussians, Group};
use crate::{GpuContext, GpuError};

/// Largest split count of the binomial table (gsplat: n_max = 51).
pub const N_MAX: usize = 51;

/// Parameters of one noise step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NoiseParams {
    /// The run's seed (Philox key).
    pub seed: u64,
    /// Training step (Philox counter).
    pub step: u64,
    /// lr_means · noise_lr (the trainer's decayed means learning rate times 5e5).
    pub scale: f32,
    /// Opacity below which the gate opens (gsplat: 0.005).
    pub min_opacity: f32,
}

#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct NoiseUniform {
    len: u32,
    seed_lo: u32,
    seed_hi: u32,
    step_lo: u32,
    step_hi: u32,
    pad0: u32,
    scale: f32,
    min_opacity: f32,
}

#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct SplitUniform {
    count: u32,
    pad0: u32,
    min_opacity: f32,
    one_minus_eps: f32,
}

#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct RowsUniform {
    count: u32,
    width: u32,
    zero_dst: u32,
    pad0: u32,
}

/// The MCMC kernels and the binomial table.
pub struct GpuMcmc {
    noise_philox: Kernel,
    noise_from_buffer: Kernel,
    split: Kernel,
    copy_rows: Kernel,
    zero_rows: Kernel,
    binoms: wgpu::Buffer,
}

/// C(n, k) for 0 ≤ k ≤ n < N_MAX, row-major N_MAX × N_MAX (Pascal's rule in f64, as gems-train,
/// then rounded to f32; C(50, 25) ≈ 1.3e14 is rounded to 24 bits).
fn binomial_table() -> Vec<f32> {
    let mut t = vec![0.0f64; N_MAX * N_MAX];
    for n in 0..N_MAX {
        t[n * N_MAX] = 1.0;
        for k in 1..=n {
            t[n * N_MAX + k] = t[(n - 1) * N_MAX + k - 1] + t[(n - 1) * N_MAX + k];
        }
    }
    t.into_iter().map(|v| v as f32).collect()
}

fn rows_u32(rows: &[usize], len: usize, what: &str) -> Result<Vec<u32>, GpuError> {
    rows.iter()
        .map(|&r| {
            if r < len {
                Ok(r as u32)
            } else {
                Err(GpuError::Shape(format!(
                    "{what} row {r} is out of range ({len} Gaussians)"
                )))
            }
        })
        .collect()
}

impl GpuMcmc {
    pub fn new(ctx: &GpuContext) -> Result<Self, GpuError> {
        let noise = buffers::module(
            ctx,
            "mcmc_noise",
            &[
                FLAT_INDEX_WGSL,
                include_str!("../shaders/philox.wgsl"),
                include_str!("../shaders/mcmc_noise.wgsl"),
            ],
        );
        let reloc = buffers::module(
            ctx,
            "mcmc_relocate",
            &[
                FLAT_INDEX_WGSL,
                include_str!("../shaders/mcmc_relocate.wgsl"),
            ],
        );
        Ok(GpuMcmc {
            noise_philox: Kernel::new(ctx, &noise, "noise_philox"),
            noise_from_buffer: Kernel::new(ctx, &noise, "noise_from_buffer"),
            split: Kernel::new(ctx, &reloc, "split_sources"),
            copy_rows: Kernel::new(ctx, &reloc, "copy_rows"),
            zero_rows: Kernel::new(ctx, &reloc, "zero_rows"),
            binoms: buffers::upload(ctx, "binomials", &binomial_table())?,
        })
    }

    fn noise_uniform(g: &GpuGaussians, p: &NoiseParams) -> NoiseUniform {
        NoiseUniform {
            len: g.len() as u32,
            seed_lo: p.seed as u32,
            seed_hi: (p.seed >> 32) as u32,
            step_lo: p.step as u32,
            step_hi: (p.step >> 32) as u32,
            pad0: 0,
            scale: p.scale,
            min_opacity: p.min_opacity,
        }
    }

    fn encode_noise_with(
        &self,
        ctx: &GpuContext,
        enc: &mut wgpu::CommandEncoder,
        g: &GpuGaussians,
        p: &NoiseParams,
        eps: Option<&wgpu::Buffer>,
    ) {
        let ub = buffers::uniform(ctx, "noise uniform", &Self::noise_uniform(g, p));
        let mut entries = vec![
            (0, &ub),
            (1, &g.group(Group::Means).param),
            (2, &g.group(Group::Quats).param),
            (3, &g.group(Group::LogScales).param),
            (4, &g.group(Group::OpacityLogits).param),
        ];
        let kernel = match eps {
            Some(e) => {
                entries.push((5, e));
                &self.noise_from_buffer
            }
            None => &self.noise_philox,
        };
        let bg = kernel.bind(ctx, &entries);
        kernel.dispatch(enc, &bg, g.len());
    }

    /// Records one SGLD noise step of every resident Gaussian, ε from Philox(seed; row, step).
    pub fn encode_noise(
        &self,
        ctx: &GpuContext,
        enc: &mut wgpu::CommandEncoder,
        g: &GpuGaussians,
        p: &NoiseParams,
    ) {
        self.encode_noise_with(ctx, enc, g, p, None);
    }

    /// Records the noise step with ε taken from `eps` (`[len, 3]` f32) instead of Philox: the
    /// deterministic part alone, for tests against the CPU on the same samples.
    pub fn encode_noise_from(
        &self,
        ctx: &GpuContext,
        enc: &mut wgpu::CommandEncoder,
        g: &GpuGaussians,
        eps: &wgpu::Buffer,
        scale: f32,
        min_opacity: f32,
    ) -> Result<(), GpuError> {
        if eps.size() < g.len() as u64 * 12 {
            return Err(GpuError::Shape(format!(
                "noise buffer holds {} values, {} Gaussians need {}",
                eps.size() / 4,
                g.len(),
                3 * g.len()
            )));
        }
        let p = NoiseParams {
            seed: 0,
            step: 0,
            scale,
            min_opacity,
        };
        self.encode_noise_with(ctx, enc, g, &p, Some(eps));
        Ok(())
    }

    /// The opacity logits of the resident Gaussians (the input of the CPU-side draws).
    pub fn download_opacity_logits(
        &self,
        ctx: &GpuContext,
        g: &GpuGaussians,
    ) -> Result<Vec<f32>, GpuError> {
        buffers::download(ctx, &g.group(Group::OpacityLogits).param, 0, g.len())
    }

    /// Records the split of each distinct source (count = draws + 1).
    fn encode_split(
        &self,
        ctx: &GpuContext,
        enc: &mut wgpu::CommandEncoder,
        g: &GpuGaussians,
        sources: &[u32],
        min_opacity: f32,
    ) -> Result<(), GpuError> {
        // Distinct sources and their draw counts, as gems-train's split_sources.
        let mut counts = BTreeMap::<u32, u32>::new();
        for &s in sources {
            *counts.entry(s).or_insert(0) += 1;
        }
        let rows: Vec<u32> = counts.keys().copied().collect();
        let ns: Vec<u32> = counts.values().map(|&c| c + 1).collect();
        let u = SplitUniform {
            count: rows.len() as u32,
            pad0: 0,
            min_opacity,
            one_minus_eps: 1.0 - f32::EPSILON,
        };
        let ub = buffers::uniform(ctx, "split uniform", &u);
        let rb = buffers::upload(ctx, "split rows", &rows)?;
        let cb = buffers::upload(ctx, "split counts", &ns)?;
        let bg = self.split.bind(
            ctx,
            &[
                (0, &ub),
                (1, &rb),
                (2, &cb),
                (3, &self.binoms),
                (4, &g.group(Group::OpacityLogits).param),
                (5, &g.group(Group::LogScales).param),
            ],
        );
        self.split.dispatch(enc, &bg, rows.len());
        Ok(())
    }

    /// Records row copies `pairs` = [dst, src]… in every group; `zero_dst` zeroes the copies'
    /// Adam moments.
    fn encode_copies(
        &self,
        ctx: &GpuContext,
        enc: &mut wgpu::CommandEncoder,
        g: &GpuGaussians,
        pairs: &[u32],
        zero_dst: bool,
    ) -> Result<(), GpuError> {
        let n = pairs.len() / 2;
        let pb = buffers::upload(ctx, "copy pairs", pairs)?;
        for group in Group::ALL {
            let b = g.group(group);
            let u = RowsUniform {
                count: n as u32,
                width: group.width() as u32,
                zero_dst: u32::from(zero_dst),
                pad0: 0,
            };
            let ub = buffers::uniform(ctx, "copy uniform", &u);
            let bg = self.copy_rows.bind(
                ctx,
                &[(6, &ub), (7, &pb), (8, &b.param), (9, &b.m), (10, &b.v)],
            );
            self.copy_rows.dispatch(enc, &bg, n * group.width());
        }
        Ok(())
    }

    /// Records zeroing of the Adam moments of `rows` in every group.
    fn encode_zero_moments(
        &self,
        ctx: &GpuContext,
        enc: &mut wgpu::CommandEncoder,
        g: &GpuGaussians,
        rows: &[u32],
    ) -> Result<(), GpuError> {
        let rb = buffers::upload(ctx, "zeroed rows", rows)?;
        for group in Group::ALL {
            let b = g.group(group);
            let u = RowsUniform {
                count: rows.len() as u32,
                width: group.width() as u32,
                zero_dst: 0,
                pad0: 0,
            };
            let ub = buffers::uniform(ctx, "zero uniform", &u);
            let bg = self
                .zero_rows
                .bind(ctx, &[(6, &ub), (7, &rb), (9, &b.m), (10, &b.v)]);
            self.zero_rows
                .dispatch(enc, &bg, rows.len() * group.width());
        }
        Ok(())
    }

    /// Relocation (gems-train `relocate_dead` given its draws): splits every source, copies each
    /// source row onto its dead row, zeroes the sources' Adam moments. `dead` and `sources` are
    /// `mcmc::relocation_draws`' output (same length). Submits; returns the number relocated.
    pub fn relocate(
        &self,
        ctx: &GpuContext,
        g: &mut GpuGaussians,
        dead: &[usize],
        sources: &[usize],
        min_opacity: f32,
    ) -> Result<usize, GpuError> {
        if dead.len() != sources.len() {
            return Err(GpuError::Shape(format!(
                "{} dead rows but {} sources",
                dead.len(),
                sources.len()
            )));
        }
        if dead.is_empty() {
            return Ok(0);
        }
        let d = rows_u32(dead, g.len(), "dead")?;
        let s = rows_u32(sources, g.len(), "source")?;
        let pairs: Vec<u32> = d.iter().zip(&s).flat_map(|(&a, &b)| [a, b]).collect();
        let mut enc = buffers::encoder(ctx, "mcmc relocate");
        self.encode_split(ctx, &mut enc, g, &s, min_opacity)?;
        self.encode_copies(ctx, &mut enc, g, &pairs, false)?;
        self.encode_zero_moments(ctx, &mut enc, g, &s)?;
        ctx.queue.submit([enc.finish()]);
        Ok(dead.len())
    }

    /// Growth (gems-train `add_new` given its draws): splits every source and appends one copy
    /// per draw with zero Adam moments, growing the buffers if needed. Submits; returns the
    /// number added.
    pub fn grow(
        &self,
        ctx: &GpuContext,
        g: &mut GpuGaussians,
        sources: &[usize],
        min_opacity: f32,
    ) -> Result<usize, GpuError> {
        if sources.is_empty() {
            return Ok(0);
        }
        let s = rows_u32(sources, g.len(), "source")?;
        let old = g.len();
        let new_len = old + s.len();
        g.reserve(ctx, new_len)?;
        let pairs: Vec<u32> = s
            .iter()
            .enumerate()
            .flat_map(|(k, &src)| [(old + k) as u32, src])
            .collect();
        let mut enc = buffers::encoder(ctx, "mcmc grow");
        self.encode_split(ctx, &mut enc, g, &s, min_opacity)?;
        self.encode_copies(ctx, &mut enc, g, &pairs, true)?;
        ctx.queue.submit([enc.finish()]);
        g.set_len(new_len);
        Ok(s.len())
    }
}

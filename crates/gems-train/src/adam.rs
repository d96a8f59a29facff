//! Adam with torch semantics on flat f32 parameter groups (structure of arrays).
//!
//! Each group owns its first/second moments as flat vectors laid out like the parameters
//! (`width` floats per row, one row per Gaussian or per trajectory), so MCMC can reset or append
//! rows without touching the others. Updates are elementwise, hence independent of thread count.

use gems_gpu::GaussianLrs;
use gems_splat::{Gaussians, Gradients};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Element count above which the update runs on the rayon pool.
const PARALLEL_MIN: usize = 1 << 14;
/// Fixed chunk so the work split does not depend on the number of threads.
const CHUNK: usize = 4096;

/// Moments and step counter of one parameter group.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct AdamState {
    /// Floats per row.
    pub width: usize,
    /// Number of Adam steps taken (for bias correction).
    pub step: u64,
    pub m: Vec<f32>,
    pub v: Vec<f32>,
}

/// Hyper-parameters shared by all groups.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AdamHyper {
    pub beta1: f32,
    pub beta2: f32,
    pub eps: f32,
}

impl AdamState {
    pub fn new(rows: usize, width: usize) -> Self {
        Self {
            width,
            step: 0,
            m: vec![0.0; rows * width],
            v: vec![0.0; rows * width],
        }
    }

    pub fn rows(&self) -> usize {
        self.m.len() / self.width
    }

    /// One torch-Adam update: g += wd·p; m,v EMAs; p -= lr/(1−β1ᵗ) · m / (sqrt(v)/sqrt(1−β2ᵗ) + eps).
    pub fn step(
        &mut self,
        params: &mut [f32],
        grads: &[f32],
        lr: f32,
        weight_decay: f32,
        h: AdamHyper,
    ) {
        self.step_by_column(params, grads, |_| lr, weight_decay, h);
    }

    /// Adam update with a learning rate per column of the row (SH dc and SH rest share one array).
    pub fn step_by_column<F>(
        &mut self,
        params: &mut [f32],
        grads: &[f32],
        lr_of_column: F,
        weight_decay: f32,
        h: AdamHyper,
    ) where
        F: Fn(usize) -> f32 + Sync,
    {
        assert_eq!(
            params.len(),
            self.m.len(),
            "Adam state and parameters disagree in size"
        );
        assert_eq!(
            grads.len(),
            self.m.len(),
            "Adam state and gradients disagree in size"
        );
        self.step += 1;
        let t = self.step as i32;
        let inv_bc1 = (1.0 / (1.0 - (h.beta1 as f64).powi(t))) as f32;
        let inv_sqrt_bc2 = (1.0 / (1.0 - (h.beta2 as f64).powi(t)).sqrt()) as f32;
        let width = self.width;
        // `offset` is the flat index of the chunk's first element, to recover the column.
        let update = |offset: usize, p: &mut [f32], g: &[f32], m: &mut [f32], v: &mut [f32]| {
            for i in 0..p.len() {
                let gi = g[i] + weight_decay * p[i];
                m[i] = h.beta1 * m[i] + (1.0 - h.beta1) * gi;
                v[i] = h.beta2 * v[i] + (1.0 - h.beta2) * gi * gi;
                let step_size = lr_of_column((offset + i) % width) * inv_bc1;
                p[i] -= step_size * m[i] / (v[i].sqrt() * inv_sqrt_bc2 + h.eps);
            }
        };
        if params.len() >= PARALLEL_MIN {
            params
                .par_chunks_mut(CHUNK)
                .zip(grads.par_chunks(CHUNK))
                .zip(
                    self.m
                        .par_chunks_mut(CHUNK)
                        .zip(self.v.par_chunks_mut(CHUNK)),
                )
                .enumerate()
                .for_each(|(c, ((p, g), (m, v)))| update(c * CHUNK, p, g, m, v));
        } else {
            update(0, params, grads, &mut self.m, &mut self.v);
        }
    }

    /// Zeroes both moments of the given rows (gsplat resets relocation sources this way).
    pub fn reset_rows(&mut self, rows: &[usize]) {
        let w = self.width;
        for &r in rows {
            self.m[r * w..(r + 1) * w].fill(0.0);
            self.v[r * w..(r + 1) * w].fill(0.0);
        }
    }

    /// Appends `n` rows with zero moments (new Gaussians from MCMC growth).
    pub fn append_zero_rows(&mut self, n: usize) {
        let len = self.m.len() + n * self.width;
        self.m.resize(len, 0.0);
        self.v.resize(len, 0.0);
    }
}

/// Adam moments of the Gaussian parameter groups, row-aligned with `Gaussians`.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct GaussianAdam {
    pub means: AdamState,
    pub quats: AdamState,
    pub log_scales: AdamState,
    pub opacity_logits: AdamState,
    /// All 16×3 SH coefficients; the dc columns (0..3) use the dc lr, the rest the rest lr.
    pub sh: AdamState,
}

impl GaussianAdam {
    pub fn new(n: usize) -> Self {
        Self {
            means: AdamState::new(n, 3),
            quats: AdamState::new(n, 4),
            log_scales: AdamState::new(n, 3),
            opacity_logits: AdamState::new(n, 1),
            sh: AdamState::new(n, 48),
        }
    }

    /// One Adam step of every Gaussian group from the renderer's gradients, without weight
    /// decay; the SH dc columns (0..3) take `lrs.sh_dc`, the rest `lrs.sh_rest`. The trainer's
    /// step, and the CPU reference of gems-gpu's `GpuAdam`.
    pub fn step(&mut self, g: &mut Gaussians, gr: &Gradients, lrs: &GaussianLrs, h: AdamHyper) {
        self.means.step(
            bytemuck::cast_slice_mut(&mut g.means),
            bytemuck::cast_slice(&gr.means),
            lrs.means,
            0.0,
            h,
        );
        self.quats.step(
            bytemuck::cast_slice_mut(&mut g.quats),
            bytemuck::cast_slice(&gr.quats),
            lrs.quats,
            0.0,
            h,
        );
        self.log_scales.step(
            bytemuck::cast_slice_mut(&mut g.log_scales),
            bytemuck::cast_slice(&gr.log_scales),
            lrs.log_scales,
            0.0,
            h,
        );
        self.opacity_logits.step(
            &mut g.opacity_logits,
            &gr.opacity_logits,
            lrs.opacity_logits,
            0.0,
            h,
        );
        let (dc, rest) = (lrs.sh_dc, lrs.sh_rest);
        self.sh.step_by_column(
            bytemuck::cast_slice_mut(&mut g.sh),
            bytemuck::cast_slice(&gr.sh),
            |col| if col < 3 { dc } else { rest },
            0.0,
            h,
        );
    }

    pub(crate) fn groups(&mut self) -> [&mut AdamState; 5] {
        [
            &mut self.means,
            &mut self.quats,
            &mut self.log_scales,
            &mut self.opacity_logits,
            &mut self.sh,
        ]
    }

    pub fn reset_rows(&mut self, rows: &[usize]) {
        for g in self.groups() {
            g.reset_rows(rows);
        }
    }

    pub fn append_zero_rows(&mut self, n: usize) {
        for g in self.groups() {
            g.append_zero_rows(n);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const H: AdamHyper = AdamHyper {
        beta1: 0.9,
        beta2: 0.999,
        eps: 1e-15,
    };

    #[test]
    fn first_step_moves_by_lr_times_sign() {
        // After one step m̂ = g and v̂ = g², so the update is lr·sign(g) exactly (torch behaviour).
        let mut p = vec![1.0f32, -2.0, 0.5];
        let g = vec![3.0f32, -0.01, 0.0];
        let mut s = AdamState::new(1, 3);
        s.step(&mut p, &g, 0.1, 0.0, H);
        assert!((p[0] - 0.9).abs() < 1e-6);
        assert!((p[1] - (-1.9)).abs() < 1e-6);
        assert_eq!(p[2], 0.5);
    }

    #[test]
    fn matches_reference_recursion_over_steps_with_weight_decay() {
        // Reference: the torch Adam recursion in f64.
        let grads = [0.3f64, -1.0, 0.25, 2.0, -0.5];
        let (lr, wd) = (0.01f64, 0.1f64);
        let (mut p, mut m, mut v) = (0.7f64, 0.0f64, 0.0f64);
        let mut pf = vec![0.7f32];
        let mut s = AdamState::new(1, 1);
        for (t, &g) in grads.iter().enumerate() {
            let gi = g + wd * p;
            m = 0.9 * m + 0.1 * gi;
            v = 0.999 * v + 0.001 * gi * gi;
            let t = (t + 1) as i32;
            p -= lr / (1.0 - 0.9f64.powi(t)) * m
                / (v.sqrt() / (1.0 - 0.999f64.powi(t)).sqrt() + 1e-15);
            s.step(&mut pf, &[g as f32], lr as f32, wd as f32, H);
        }
        assert!((pf[0] as f64 - p).abs() < 1e-6, "{} vs {p}", pf[0]);
    }

    #[test]
    fn parallel_path_equals_serial_path() {
        let n = PARALLEL_MIN + 123;
        let g: Vec<f32> = (0..n)
            .map(|i| ((i * 7919) % 1000) as f32 / 500.0 - 1.0)
            .collect();
        let mut p1: Vec<f32> = (0..n).map(|i| i as f32 * 1e-4).collect();
        let mut s1 = AdamState::new(n, 1);
        s1.step(&mut p1, &g, 1e-2, 0.0, H);
        s1.step(&mut p1, &g, 1e-2, 0.0, H);
        // Serial reference: element by element on small states.
        for i in [0usize, 1, n / 2, n - 1] {
            let mut p = vec![i as f32 * 1e-4];
            let mut s = AdamState::new(1, 1);
            s.step(&mut p, &[g[i]], 1e-2, 0.0, H);
            s.step(&mut p, &[g[i]], 1e-2, 0.0, H);
            assert_eq!(p[0], p1[i]);
        }
    }

    #[test]
    fn per_column_learning_rates() {
        let mut p = vec![0.0f32; 6];
        let mut s = AdamState::new(2, 3);
        s.step_by_column(
            &mut p,
            &[1.0; 6],
            |c| if c == 0 { 1.0 } else { 0.5 },
            0.0,
            H,
        );
        assert!((p[0] + 1.0).abs() < 1e-6 && (p[3] + 1.0).abs() < 1e-6);
        assert!((p[1] + 0.5).abs() < 1e-6 && (p[5] + 0.5).abs() < 1e-6);
    }

    #[test]
    fn reset_and_append_rows() {
        let mut s = AdamState::new(3, 2);
        s.m.fill(1.0);
        s.v.fill(2.0);
        s.reset_rows(&[1]);
        assert_eq!(s.m, vec![1.0, 1.0, 0.0, 0.0, 1.0, 1.0]);
        assert_eq!(s.v, vec![2.0, 2.0, 0.0, 0.0, 2.0, 2.0]);
        s.append_zero_rows(2);
        assert_eq!(s.rows(), 5);
        assert_eq!(&s.m[6..], &[0.0; 4]);
    }
}

//! 3DGS-MCMC densification with gsplat's `MCMCStrategy` semantics
//! (`nerfstudio-project/gsplat:gsplat/strategy/mcmc.py`, `ops.py`, `relocation.py`).
//!
//! * Relocation: Gaussians with opacity ≤ `min_opacity` are dead. As many sources are drawn from
//!   the alive ones by multinomial sampling ∝ opacity **with replacement**; a source drawn c times
//!   is split into n = c + 1 (clamped to 51) copies with o' = 1 − (1 − o)^{1/n} and
//!   s' = s·o / D (binomial-table formula, Eq. 9 of 3DGS-MCMC); o' is clamped to
//!   [min_opacity, 1 − ε] after s' is computed (gsplat ≤ 1.5.3). Each dead row then receives a
//!   copy of its source's parameters. Adam moments are zeroed at the SOURCE rows only (gsplat and
//!   the official code leave the dead rows' stale moments in place).
//! * Growth: N → min(cap_max, ⌊1.05·N⌋) by the same split applied to sources drawn ∝ opacity over
//!   all Gaussians; new rows are appended with zero Adam moments.
//! * SGLD noise, every step: μ += Σ·ε·sigmoid(−100(o − 0.005))·lr_means·noise_lr, Σ = R S² Rᵀ.
//!
//! Ordering follows gsplat ≥ 1.5 (optimizer step, then refinement, then noise with the already
//! decayed means lr).

use gems_splat::Gaussians;
use gems_splat::activation::{logit, sigmoid};
use rand::Rng;
use rand::RngExt;
use rand_distr::{Distribution, StandardNormal};

use crate::adam::GaussianAdam;

/// Largest split count represented in the binomial table (gsplat: n_max = 51).
pub const N_MAX: usize = 51;

/// C(n, k) for 0 ≤ k ≤ n < N_MAX.
pub struct BinomialTable {
    table: Vec<f64>,
}

impl Default for BinomialTable {
    fn default() -> Self {
        let mut table = vec![0.0f64; N_MAX * N_MAX];
        for n in 0..N_MAX {
            table[n * N_MAX] = 1.0;
            for k in 1..=n {
                table[n * N_MAX + k] = table[(n - 1) * N_MAX + k - 1] + table[(n - 1) * N_MAX + k];
            }
        }
        Self { table }
    }
}

impl BinomialTable {
    pub fn get(&self, n: usize, k: usize) -> f64 {
        self.table[n * N_MAX + k]
    }
}

/// New opacity and scales of a Gaussian split into `n` copies (before the opacity clamp).
///
/// o' = 1 − (1 − o)^{1/n}; D = Σ_{i=1..n} Σ_{k=0..i−1} C(i−1,k)(−1)^k o'^{k+1}/√(k+1); s' = s·o/D.
pub fn compute_relocation(
    opacity: f32,
    scale: [f32; 3],
    n: usize,
    binoms: &BinomialTable,
) -> (f32, [f32; 3]) {
    let n = n.clamp(1, N_MAX);
    let o = opacity as f64;
    let o_new = 1.0 - (1.0 - o).powf(1.0 / n as f64);
    let mut denom = 0.0f64;
    for i in 1..=n {
        for k in 0..i {
            let sign = if k % 2 == 0 { 1.0 } else { -1.0 };
            denom +=
                binoms.get(i - 1, k) * sign * o_new.powi(k as i32 + 1) / ((k + 1) as f64).sqrt();
        }
    }
    let ratio = (o / denom) as f32;
    (o_new as f32, scale.map(|s| s * ratio))
}

/// Draws `count` indices ∝ `weights` with replacement (inverse-CDF on an f64 prefix sum).
pub fn multinomial_with_replacement<R: Rng + ?Sized>(
    weights: &[f32],
    count: usize,
    rng: &mut R,
) -> Vec<usize> {
    let mut cdf = Vec::with_capacity(weights.len());
    let mut acc = 0.0f64;
    for &w in weights {
        acc += w.max(0.0) as f64;
        cdf.push(acc);
    }
    if weights.is_empty() || acc <= 0.0 {
        return Vec::new();
    }
    (0..count)
        .map(|_| {
            let x = rng.random::<f64>() * acc;
            // First index whose cumulative weight exceeds x (never a zero-weight entry).
            cdf.partition_point(|&c| c <= x).min(weights.len() - 1)
        })
        .collect()
}

/// Splits each distinct source into (count + 1) copies in place: new o' and s' written to the
/// source rows. Returns nothing; `sources` may contain repeats.
fn split_sources(g: &mut Gaussians, sources: &[usize], min_opacity: f32, binoms: &BinomialTable) {
    let mut counts = std::collections::BTreeMap::<usize, usize>::new();
    for &s in sources {
        *counts.entry(s).or_insert(0) += 1;
    }
    for (&i, &c) in &counts {
        let o = sigmoid(g.opacity_logits[i]);
        let s = g.log_scales[i].map(f32::exp);
        let (o_new, s_new) = compute_relocation(o, s, c + 1, binoms);
        let o_new = o_new.clamp(min_opacity, 1.0 - f32::EPSILON);
        g.opacity_logits[i] = logit(o_new);
        g.log_scales[i] = s_new.map(f32::ln);
    }
}

fn copy_row(g: &mut Gaussians, src: usize, dst: usize) {
    g.means[dst] = g.means[src];
    g.quats[dst] = g.quats[src];
    g.log_scales[dst] = g.log_scales[src];
    g.opacity_logits[dst] = g.opacity_logits[src];
    g.sh[dst] = g.sh[src];
}

/// The random part of [`relocate_dead`]: the dead rows (opacity ≤ `min_opacity`) and, for each,
/// a source drawn from the alive rows ∝ opacity with replacement. Empty when nothing is dead or
/// nothing is alive. (Exposed so that a GPU-resident trainer draws exactly the CPU's samples.)
pub fn relocation_draws<R: Rng + ?Sized>(
    opacity_logits: &[f32],
    min_opacity: f32,
    rng: &mut R,
) -> (Vec<usize>, Vec<usize>) {
    let n = opacity_logits.len();
    let opac: Vec<f32> = opacity_logits.iter().map(|&l| sigmoid(l)).collect();
    let (dead, alive): (Vec<usize>, Vec<usize>) = (0..n).partition(|&i| opac[i] <= min_opacity);
    if dead.is_empty() || alive.is_empty() {
        return (Vec::new(), Vec::new());
    }
    let alive_w: Vec<f32> = alive.iter().map(|&i| opac[i]).collect();
    let sources: Vec<usize> = multinomial_with_replacement(&alive_w, dead.len(), rng)
        .into_iter()
        .map(|k| alive[k])
        .collect();
    (dead, sources)
}

/// Moves dead Gaussians onto alive ones; returns how many were relocated.
pub fn relocate_dead<R: Rng + ?Sized>(
    g: &mut Gaussians,
    adam: &mut GaussianAdam,
    min_opacity: f32,
    binoms: &BinomialTable,
    rng: &mut R,
) -> usize {
    let (dead, sources) = relocation_draws(&g.opacity_logits, min_opacity, rng);
    if dead.is_empty() {
        return 0;
    }
    split_sources(g, &sources, min_opacity, binoms);
    for (&d, &s) in dead.iter().zip(&sources) {
        copy_row(g, s, d);
    }
    adam.reset_rows(&sources);
    dead.len()
}

/// The random part of [`add_new`]: min(cap_max, ⌊growth·N⌋) − N sources drawn from all rows
/// ∝ opacity with replacement (empty when there is nothing to add).
pub fn growth_draws<R: Rng + ?Sized>(
    opacity_logits: &[f32],
    cap_max: usize,
    growth_factor: f64,
    rng: &mut R,
) -> Vec<usize> {
    let n = opacity_logits.len();
    let target = cap_max.min((growth_factor * n as f64) as usize);
    let n_add = target.saturating_sub(n);
    if n_add == 0 {
        return Vec::new();
    }
    let opac: Vec<f32> = opacity_logits.iter().map(|&l| sigmoid(l)).collect();
    multinomial_with_replacement(&opac, n_add, rng)
}

/// Grows the population to min(cap_max, ⌊growth·N⌋); returns how many were added.
pub fn add_new<R: Rng + ?Sized>(
    g: &mut Gaussians,
    adam: &mut GaussianAdam,
    cap_max: usize,
    growth_factor: f64,
    min_opacity: f32,
    binoms: &BinomialTable,
    rng: &mut R,
) -> usize {
    let sources = growth_draws(&g.opacity_logits, cap_max, growth_factor, rng);
    if sources.is_empty() {
        return 0;
    }
    split_sources(g, &sources, min_opacity, binoms);
    g.means
        .extend(sources.iter().map(|&s| g.means[s]).collect::<Vec<_>>());
    g.quats
        .extend(sources.iter().map(|&s| g.quats[s]).collect::<Vec<_>>());
    g.log_scales
        .extend(sources.iter().map(|&s| g.log_scales[s]).collect::<Vec<_>>());
    g.opacity_logits.extend(
        sources
            .iter()
            .map(|&s| g.opacity_logits[s])
            .collect::<Vec<_>>(),
    );
    g.sh.extend(sources.iter().map(|&s| g.sh[s]).collect::<Vec<_>>());
    adam.append_zero_rows(sources.len());
    sources.len()
}

/// SGLD position noise: μ += R S² Rᵀ ε · sigmoid(−100(o − min_opacity)) · scale, ε ~ N(0, I).
///
/// The noise is drawn serially from `rng` so the result does not depend on thread count.
pub fn inject_noise<R: Rng + ?Sized>(g: &mut Gaussians, scale: f32, min_opacity: f32, rng: &mut R) {
    apply_noise(g, scale, min_opacity, |_| {
        std::array::from_fn(|_| StandardNormal.sample(rng))
    });
}

/// The deterministic part of [`inject_noise`] with ε given by `eps(i)`, called once per row in
/// row order (exposed so that the GPU kernel can be tested on the same noise samples).
pub fn apply_noise(
    g: &mut Gaussians,
    scale: f32,
    min_opacity: f32,
    mut eps: impl FnMut(usize) -> [f32; 3],
) {
    for i in 0..g.means.len() {
        let eps = eps(i);
        let o = sigmoid(g.opacity_logits[i]);
        let gate = sigmoid(-100.0 * (o - min_opacity)) * scale;
        let r = quat_to_rotation(g.quats[i]);
        let s2 = g.log_scales[i].map(|l| (2.0 * l).exp());
        // Σε = R (S² (Rᵀ ε)).
        let rt_eps: [f32; 3] = std::array::from_fn(|a| (0..3).map(|b| r[b][a] * eps[b]).sum());
        let scaled: [f32; 3] = std::array::from_fn(|a| s2[a] * rt_eps[a]);
        for (m, row) in g.means[i].iter_mut().zip(&r) {
            let d: f32 = row.iter().zip(&scaled).map(|(a, b)| a * b).sum();
            *m += gate * d;
        }
    }
}

/// Rotation matrix of a (not necessarily unit) wxyz quaternion.
pub(crate) fn quat_to_rotation(q: [f32; 4]) -> [[f32; 3]; 3] {
    let n = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
        .sqrt()
        .max(1e-12);
    let [w, x, y, z] = q.map(|c| c / n);
    [
        [
            1.0 - 2.0 * (y * y + z * z),
            2.0 * (x * y - w * z),
            2.0 * (x * z + w * y),
        ],
        [
            2.0 * (x * y + w * z),
            1.0 - 2.0 * (x * x + z * z),
            2.0 * (y * z - w * x),
        ],
        [
            2.0 * (x * z - w * y),
            2.0 * (y * z + w * x),
            1.0 - 2.0 * (x * x + y * y),
        ],
    ]
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn binomial_table_values() {
        let b = BinomialTable::default();
        assert_eq!(b.get(0, 0), 1.0);
        assert_eq!(b.get(5, 2), 10.0);
        assert_eq!(b.get(50, 25), 126_410_606_437_752.0);
    }

    #[test]
    fn split_into_one_is_identity() {
        let b = BinomialTable::default();
        let (o, s) = compute_relocation(0.37, [0.1, 0.2, 0.3], 1, &b);
        assert!((o - 0.37).abs() < 1e-6);
        for (a, e) in s.iter().zip([0.1, 0.2, 0.3]) {
            assert!((a - e).abs() < 1e-6);
        }
    }

    #[test]
    fn split_into_two_closed_form() {
        // n = 2: o' = 1 − √(1−o); D = o' + (o' − o'²/√2) = 2o' − o'²/√2.
        let b = BinomialTable::default();
        let o = 0.6f64;
        let on = 1.0 - (1.0 - o).sqrt();
        let d = 2.0 * on - on * on / 2f64.sqrt();
        let (o2, s2) = compute_relocation(o as f32, [1.0, 2.0, 3.0], 2, &b);
        assert!((o2 as f64 - on).abs() < 1e-6);
        assert!((s2[1] as f64 - 2.0 * o / d).abs() < 1e-5);
    }

    proptest! {
        #[test]
        fn relocation_preserves_transmittance(o in 0.006f32..0.99, n in 1usize..=51) {
            let b = BinomialTable::default();
            let (on, s) = compute_relocation(o, [1.0; 3], n, &b);
            let lhs = (1.0 - on as f64).powi(n as i32);
            prop_assert!((lhs - (1.0 - o as f64)).abs() < 1e-5);
            prop_assert!(s[0].is_finite() && s[0] > 0.0);
        }
    }

    #[test]
    fn multinomial_follows_weights_and_skips_zero_weights() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let draws = multinomial_with_replacement(&[0.0, 1.0, 3.0, 0.0], 40_000, &mut rng);
        assert!(draws.iter().all(|&d| d == 1 || d == 2));
        let frac = draws.iter().filter(|&&d| d == 2).count() as f64 / 40_000.0;
        assert!((frac - 0.75).abs() < 0.01, "{frac}");
        assert!(multinomial_with_replacement(&[0.0, 0.0], 3, &mut rng).is_empty());
    }

    fn gaussians(opacities: &[f32]) -> Gaussians {
        let mut g = Gaussians::with_degree(3);
        for (i, &o) in opacities.iter().enumerate() {
            let mut sh = [[0.0f32; 3]; 16];
            sh[0] = [i as f32; 3];
            g.push(
                [i as f32, 0.0, 0.0],
                [1.0, 0.0, 0.0, 0.0],
                [(0.1f32 * (i + 1) as f32).ln(); 3],
                logit(o),
                sh,
            );
        }
        g
    }

    #[test]
    fn relocation_moves_dead_onto_sources_and_resets_source_moments() {
        let mut g = gaussians(&[0.001, 0.9, 0.004, 0.5]);
        let mut adam = GaussianAdam::new(4);
        for s in adam.groups() {
            s.m.fill(1.0);
        }
        let before = g.clone();
        let b = BinomialTable::default();
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let moved = relocate_dead(&mut g, &mut adam, 0.005, &b, &mut rng);
        assert_eq!(moved, 2);
        // Every dead row now copies an alive row (position tells which).
        for d in [0usize, 2] {
            let src = g.means[d][0] as usize;
            assert!(src == 1 || src == 3);
            assert_eq!(g.opacity_logits[d], g.opacity_logits[src]);
            assert_eq!(g.sh[d], before.sh[src]);
            assert_eq!(adam.means.m[src * 3], 0.0, "source moments reset");
            assert_eq!(
                adam.means.m[d * 3],
                1.0,
                "dead rows keep stale moments (gsplat)"
            );
        }
        // Total transmittance of each source's copies equals the original's.
        for src in [1usize, 3] {
            let copies = (0..4).filter(|&i| g.means[i][0] as usize == src).count();
            let o_new = sigmoid(g.opacity_logits[src]) as f64;
            let o_old = sigmoid(before.opacity_logits[src]) as f64;
            assert!(((1.0 - o_new).powi(copies as i32) - (1.0 - o_old)).abs() < 1e-5);
        }
    }

    #[test]
    fn growth_is_five_percent_and_respects_cap() {
        let b = BinomialTable::default();
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let mut g = gaussians(&vec![0.5; 100]);
        let mut adam = GaussianAdam::new(100);
        let mut expected = 100usize;
        for _ in 0..10 {
            let added = add_new(&mut g, &mut adam, 130, 1.05, 0.005, &b, &mut rng);
            let target = 130.min((1.05 * expected as f64) as usize);
            assert_eq!(added, target - expected);
            expected = target;
            assert_eq!(g.means.len(), expected);
            assert_eq!(adam.sh.rows(), expected);
            assert!(expected <= 130);
        }
        assert_eq!(expected, 130);
    }

    #[test]
    fn noise_only_moves_low_opacity_gaussians() {
        let mut g = gaussians(&[0.001, 0.9]);
        let before = g.clone();
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        inject_noise(&mut g, 1.0, 0.005, &mut rng);
        let moved = |i: usize| {
            (0..3)
                .map(|a| (g.means[i][a] - before.means[i][a]).abs())
                .sum::<f32>()
        };
        assert!(moved(0) > 1e-4);
        assert!(moved(1) < 1e-20);
    }
}

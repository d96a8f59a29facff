//! Contrast-threshold estimation by minimising a sharpness energy (events.md §1.4).
//!
//! Energy of a candidate latent L (gray): `λ·Σ|∇L| − Σ edge(L)·edge(M)`, with |∇| the 3×3 Sobel
//! magnitude, edge(·) the Sobel magnitude min-max normalised to [0, 1] and binarised at
//! `m + (1 − m)/3` (m = its mean), and M the signed event map of the window (events before the
//! reference time counted negatively). A wrong c leaves ghost copies of every moving edge (too
//! small: residual blur; too large: overshoot), which raises the total variation.
//!
//! Search: the energy is evaluated on a coarse grid over `[lo, hi]`, then refined by golden-section
//! search in the grid cell around the best point (robust to the energy's small plateaus).
//!
//! **Limitation (measured):** on our synthetic moving-texture data (smooth texture, 16 px blur,
//! events simulated with c = 0.2 or 0.35, no noise) this published energy decreases monotonically
//! towards small c, so the search returns the lower bound of the range instead of the simulator's
//! threshold. Use known thresholds when they are available (synthetic data, calibrated sensors).

use super::{EdiConfig, Image, PixelEvents, Thresholds, apply_factors, exact_factors};

/// Settings of the threshold search.
#[derive(Debug, Clone, PartialEq)]
pub struct SearchConfig {
    /// Search interval (0.1, 0.5 as in davis-EDI-rs).
    pub range: (f32, f32),
    /// Coarse grid points.
    pub grid: usize,
    /// Golden-section iterations after the grid.
    pub refine: usize,
    /// TV weight λ (0.15 as in davis-EDI-rs / ev-thresh-est).
    pub tv_weight: f32,
    /// Estimate c₊ and c₋ separately (after a common estimate).
    pub separate: bool,
    /// One estimate per view (else one for the whole scene).
    pub per_view: bool,
}

impl Default for SearchConfig {
    fn default() -> Self {
        Self {
            range: (0.1, 0.5),
            grid: 17,
            refine: 12,
            tv_weight: 0.15,
            separate: false,
            per_view: false,
        }
    }
}

fn sobel(img: &[f32], w: usize, h: usize) -> Vec<f32> {
    let at = |x: isize, y: isize| {
        img[(y.clamp(0, h as isize - 1) as usize) * w + x.clamp(0, w as isize - 1) as usize]
    };
    let mut out = vec![0f32; w * h];
    for y in 0..h as isize {
        for x in 0..w as isize {
            let gx = at(x + 1, y - 1) + 2.0 * at(x + 1, y) + at(x + 1, y + 1)
                - at(x - 1, y - 1)
                - 2.0 * at(x - 1, y)
                - at(x - 1, y + 1);
            let gy = at(x - 1, y + 1) + 2.0 * at(x, y + 1) + at(x + 1, y + 1)
                - at(x - 1, y - 1)
                - 2.0 * at(x, y - 1)
                - at(x + 1, y - 1);
            out[y as usize * w + x as usize] = (gx * gx + gy * gy).sqrt();
        }
    }
    out
}

fn binary_edges(mag: &[f32]) -> Vec<f32> {
    let (lo, hi) = mag
        .iter()
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), &v| {
            (a.min(v), b.max(v))
        });
    if hi <= lo {
        return vec![0.0; mag.len()];
    }
    let norm: Vec<f32> = mag.iter().map(|&v| (v - lo) / (hi - lo)).collect();
    let m = norm.iter().sum::<f32>() / norm.len() as f32;
    let th = m + (1.0 - m) / 3.0;
    norm.iter()
        .map(|&v| if v > th { 1.0 } else { 0.0 })
        .collect()
}

/// The binarised edge map of a signed event map (see [`PixelEvents::signed_map`]).
pub fn event_edges(signed_map: &[f32], w: usize, h: usize) -> Vec<f32> {
    binary_edges(&sobel(signed_map, w, h))
}

/// The sharpness energy of a gray latent image given the binarised event edge map.
pub fn sharpness_energy(
    gray: &[f32],
    w: usize,
    h: usize,
    event_edges: &[f32],
    tv_weight: f32,
) -> f64 {
    let mag = sobel(gray, w, h);
    let tv: f64 = mag.iter().map(|&v| f64::from(v)).sum();
    let edges = binary_edges(&mag);
    let agree: f64 = edges
        .iter()
        .zip(event_edges)
        .map(|(&a, &b)| f64::from(a * b))
        .sum();
    f64::from(tv_weight) * tv - agree
}

/// One view prepared for the search.
struct Prepared<'a> {
    blurry: &'a Image,
    pe: &'a PixelEvents,
    at: i64,
    event_edges: Vec<f32>,
}

/// Estimates thresholds from views `(blurry, events, reference time)`; all views share one result
/// (call once per view for per-view estimates). The energies of the views are summed.
pub fn estimate_thresholds(
    views: &[(&Image, &PixelEvents, i64)],
    search: &SearchConfig,
    cfg: &EdiConfig,
) -> Thresholds {
    let prepared: Vec<Prepared<'_>> = views
        .iter()
        .map(|&(blurry, pe, at)| {
            let m = pe.signed_map(at);
            let mag = sobel(
                &m.iter().map(|v| v.abs()).collect::<Vec<_>>(),
                pe.width(),
                pe.height(),
            );
            Prepared {
                blurry,
                pe,
                at,
                event_edges: binary_edges(&mag),
            }
        })
        .collect();
    let s = cfg.linearisation.exponent_scale();
    let energy = |cp: f32, cn: f32| -> f64 {
        prepared
            .iter()
            .map(|v| {
                let g = exact_factors(v.pe, v.at, f64::from(cp) * s, f64::from(cn) * s);
                let mut plain = cfg.clone();
                plain.bayer = None;
                let latent = apply_factors(v.blurry, &g, &plain);
                sharpness_energy(
                    &latent.gray(),
                    latent.width,
                    latent.height,
                    &v.event_edges,
                    search.tv_weight,
                )
            })
            .sum()
    };
    let c = minimise(|c| energy(c, c), search);
    if !search.separate {
        return Thresholds::equal(c);
    }
    let c_pos = minimise(|cp| energy(cp, c), search);
    let c_neg = minimise(|cn| energy(c_pos, cn), search);
    Thresholds { c_pos, c_neg }
}

/// Grid search then golden-section refinement of a 1-D function on `search.range`.
pub fn minimise(f: impl Fn(f32) -> f64, search: &SearchConfig) -> f32 {
    let (lo, hi) = search.range;
    let n = search.grid.max(2);
    let step = (hi - lo) / (n - 1) as f32;
    let (mut best, mut best_e) = (lo, f64::INFINITY);
    for i in 0..n {
        let c = lo + step * i as f32;
        let e = f(c);
        if e < best_e {
            (best, best_e) = (c, e);
        }
    }
    let (mut a, mut b) = ((best - step).max(lo), (best + step).min(hi));
    let r = 0.618_034_f32;
    let (mut x1, mut x2) = (b - r * (b - a), a + r * (b - a));
    let (mut f1, mut f2) = (f(x1), f(x2));
    for _ in 0..search.refine {
        if f1 <= f2 {
            (b, x2, f2) = (x2, x1, f1);
            x1 = b - r * (b - a);
            f1 = f(x1);
        } else {
            (a, x1, f1) = (x1, x2, f2);
            x2 = a + r * (b - a);
            f2 = f(x2);
        }
    }
    let (c, e) = if f1 <= f2 { (x1, f1) } else { (x2, f2) };
    if e <= best_e { c } else { best }
}

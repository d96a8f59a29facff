//! Contrast-threshold estimation by minimising a sharpness energy of the EDI latent frame.
//!
//! EDI explains every pixel's blurry value exactly for any threshold c, so c can only be told
//! from the *spatial* structure of the latent frame `L_c(f)`. A wrong c leaves a ghost of every
//! moving edge over the pixels the edge swept: to first order `log L_c = log L + (c_true − c)·A`
//! with `A` the pixel's mean event count relative to f — a smooth ramp along the motion for c too
//! small (residual blur) and an overshoot for c too large.
//!
//! **Default energy, [`SearchEnergy::NormalisedSparsity`]:** `‖∇L‖₁ / ‖∇L‖₂` of the gray latent
//! (Rec. 709 luma) in the sRGB-encoded domain (Krishnan et al. 2011; natural-image statistics
//! are defined on encoded values), over the pixels near strong monotone edges (net event count
//! ≥ 3 in the 3×3 neighbourhood), where the quantisation of the events matters least. Being
//! scale-invariant, it does not reward the darkening or flattening a wrong c brings, and since a
//! ramp spreads an edge's gradient over many pixels (ℓ₁/ℓ₂ grows like √width) it is raised by
//! residual blur and by overshoot ghosts alike, while a total variation cannot tell a ramp from
//! a step.
//!
//! **Published energy, [`SearchEnergy::TvEdges`]** (EDI authors, davis-EDI-rs, ev-thresh-est:
//! `panpanfei/Bringing-a-Blurry-Frame-Alive-at-High-Frame-Rate-with-an-Event-Camera:EDI/TVnorm.m`,
//! `ac-freeman/davis-EDI-rs:src/util/reconstructor.rs`, `Goulustis/ev-thresh-est:thresh_est.py`): `λ·Σ|∇L| − Σ edge(L)·edge(M)` with Sobel magnitudes, edge(·) binarised at
//! `m + (1 − m)/3` of the min-max normalised magnitude, M the signed event map. Kept for
//! comparison: on our synthetic data it decreases monotonically towards small c (TV does not see
//! residual blur), so the search returns the lower end of the range.
//!
//! Search: the energy is evaluated on a coarse grid over `[lo, hi]`, then refined by golden-section
//! search in the grid cell around the best point (robust to the energy's small plateaus).

use super::core::latent_factors;
use super::{EdiConfig, Image, Linearisation, PixelEvents, Thresholds, apply_factors};

/// Which sharpness energy the threshold search minimises.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SearchEnergy {
    /// `‖∇L‖₁/‖∇L‖₂` of the gray latent in the sRGB-encoded domain (default).
    NormalisedSparsity,
    /// The published `λ·TV(L) − Σ edge(L)·edge(M)` with TV weight λ (0.15 in davis-EDI-rs).
    TvEdges {
        /// TV weight λ.
        tv_weight: f32,
    },
}

/// Settings of the threshold search.
#[derive(Debug, Clone, PartialEq)]
pub struct SearchConfig {
    /// Search interval (0.1, 0.5 as in davis-EDI-rs).
    pub range: (f32, f32),
    /// Coarse grid points.
    pub grid: usize,
    /// Golden-section iterations after the grid.
    pub refine: usize,
    /// The energy minimised.
    pub energy: SearchEnergy,
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
            energy: SearchEnergy::NormalisedSparsity,
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

/// The published sharpness energy ([`SearchEnergy::TvEdges`]) of a gray latent image given the
/// binarised event edge map.
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

/// Normalised sparsity `‖∇g‖₁ / ‖∇g‖₂` of a `w × h` image (forward differences, anisotropic ℓ₁)
/// over the pixels where `mask` is true (all pixels without a mask); 0 for a constant image.
pub fn normalised_sparsity(g: &[f32], w: usize, h: usize, mask: Option<&[bool]>) -> f64 {
    let (mut l1, mut l2) = (0f64, 0f64);
    for y in 0..h {
        for x in 0..w {
            if mask.is_some_and(|m| !m[y * w + x]) {
                continue;
            }
            let v = g[y * w + x];
            let dx = if x + 1 < w { g[y * w + x + 1] - v } else { 0.0 };
            let dy = if y + 1 < h {
                g[(y + 1) * w + x] - v
            } else {
                0.0
            };
            l1 += f64::from(dx.abs() + dy.abs());
            l2 += f64::from(dx * dx + dy * dy);
        }
    }
    if l2 > 0.0 { l1 / l2.sqrt() } else { 0.0 }
}

/// Gray (Rec. 709 luma of RGB) of a latent frame in the sRGB-encoded domain, the domain the
/// normalised-sparsity prior is evaluated in whatever the stored encoding.
fn encoded_gray(img: &Image, lin: Linearisation) -> Vec<f32> {
    let to_enc = |v: f32| -> f32 {
        match lin {
            Linearisation::Srgb | Linearisation::SrgbEncodedAverage => v,
            _ => Linearisation::Srgb.encode(match lin {
                Linearisation::Gamma(g) | Linearisation::EncodedAverage(g) => v.max(0.0).powf(g),
                _ => v,
            }),
        }
    };
    let c = img.channels;
    img.data
        .chunks_exact(c)
        .map(|p| {
            let v = if c == 3 {
                0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2]
            } else {
                p.iter().sum::<f32>() / c as f32
            };
            to_enc(v)
        })
        .collect()
}

/// Net event count `|n_on − n_off|` a pixel (or one of its 8 neighbours) must have for the
/// normalised sparsity to look at it. An edge of log contrast Δ fires ⌊Δ/c⌋ events, so edges
/// that fired one or two carry the largest relative quantisation error and pull the estimate
/// upwards; fine texture sweeping past a pixel fires many events of both signs whose
/// quantisation error (up to c in log per pixel) grows with c and pulls it downwards. Strong
/// monotone edges are what the threshold is best read from.
const MIN_NET_EVENTS: u32 = 3;

/// Coordinate-descent rounds (c₊ then c₋) of the separate estimate.
const SEPARATE_ROUNDS: usize = 3;

/// Pixels with a net count of at least [`MIN_NET_EVENTS`] in their 3×3 neighbourhood (`None` when there are
/// none: then every pixel counts).
fn busy_pixels(pe: &PixelEvents) -> Option<Vec<bool>> {
    let (w, h) = (pe.width(), pe.height());
    let busy: Vec<bool> = (0..w * h)
        .map(|k| {
            pe.pixel(k)
                .1
                .iter()
                .map(|&p| i32::from(p))
                .sum::<i32>()
                .unsigned_abs()
                >= MIN_NET_EVENTS
        })
        .collect();
    let mask: Vec<bool> = (0..w * h)
        .map(|k| {
            let (x, y) = (k % w, k / w);
            (y.saturating_sub(1)..(y + 2).min(h))
                .any(|yy| (x.saturating_sub(1)..(x + 2).min(w)).any(|xx| busy[yy * w + xx]))
        })
        .collect();
    mask.iter().any(|&m| m).then_some(mask)
}

/// One view prepared for the search.
struct Prepared<'a> {
    blurry: &'a Image,
    pe: &'a PixelEvents,
    at: i64,
    /// Binarised event edges ([`SearchEnergy::TvEdges`]).
    event_edges: Vec<f32>,
    /// Pixels the normalised sparsity looks at ([`SearchEnergy::NormalisedSparsity`]).
    mask: Option<Vec<bool>>,
}

/// Estimates thresholds from views `(blurry, events, reference time)` by minimising
/// `search.energy` of the exact EDI latent at the reference time; all views share one result
/// (call once per view for per-view estimates) and their energies are summed. With
/// `search.separate`, c₊ and c₋ are refined in turn (coordinate descent) from the common
/// estimate; if one of them runs to the end of the range the pair is not identifiable from
/// these views and the common estimate is returned (with a warning).
pub fn estimate_thresholds(
    views: &[(&Image, &PixelEvents, i64)],
    search: &SearchConfig,
    cfg: &EdiConfig,
) -> Thresholds {
    let prepared: Vec<Prepared<'_>> = views
        .iter()
        .map(|&(blurry, pe, at)| Prepared {
            blurry,
            pe,
            at,
            event_edges: match search.energy {
                SearchEnergy::TvEdges { .. } => {
                    let m = pe.signed_map(at);
                    let mag = sobel(
                        &m.iter().map(|v| v.abs()).collect::<Vec<_>>(),
                        pe.width(),
                        pe.height(),
                    );
                    binary_edges(&mag)
                }
                SearchEnergy::NormalisedSparsity => Vec::new(),
            },
            mask: match search.energy {
                SearchEnergy::TvEdges { .. } => None,
                SearchEnergy::NormalisedSparsity => busy_pixels(pe),
            },
        })
        .collect();
    let s = cfg.linearisation.exponent_scale();
    // the energy looks at the processed frame itself, before any demosaicking
    let mut plain = cfg.clone();
    plain.bayer = None;
    let samples = cfg.exposure_samples;
    let energy = |cp: f32, cn: f32| -> f64 {
        prepared
            .iter()
            .map(|v| {
                let (cp, cn) = (f64::from(cp) * s, f64::from(cn) * s);
                match search.energy {
                    SearchEnergy::NormalisedSparsity => {
                        let g = latent_factors(v.pe, v.at, (cp, cn), samples);
                        let latent = apply_factors(v.blurry, &g, &plain);
                        normalised_sparsity(
                            &encoded_gray(&latent, cfg.linearisation),
                            latent.width,
                            latent.height,
                            v.mask.as_deref(),
                        )
                    }
                    SearchEnergy::TvEdges { tv_weight } => {
                        let g = latent_factors(v.pe, v.at, (cp, cn), samples);
                        let latent = apply_factors(v.blurry, &g, &plain);
                        let (w, h) = (latent.width, latent.height);
                        sharpness_energy(&latent.gray(), w, h, &v.event_edges, tv_weight)
                    }
                }
            })
            .sum()
    };
    let c = minimise(|c| energy(c, c), search);
    if !search.separate {
        return Thresholds::equal(c);
    }
    // coordinate descent from the common estimate: the two thresholds are coupled (a pixel's
    // ON and OFF events meet in one exponent), so a single pass stops short
    let (mut c_pos, mut c_neg) = (c, c);
    for _ in 0..SEPARATE_ROUNDS {
        c_pos = minimise(|cp| energy(cp, c_neg), search);
        c_neg = minimise(|cn| energy(c_pos, cn), search);
    }
    // A threshold driven to the end of the range (while the common one was inside it) means the
    // energy found no minimum in the c₊/c₋ direction — seen on data where one polarity's edges
    // are few: the pair is not identifiable there, the common estimate is kept.
    let (lo, hi) = search.range;
    let at_bound = |v: f32| v <= lo + 1e-3 || v >= hi - 1e-3;
    if (at_bound(c_pos) || at_bound(c_neg)) && !at_bound(c) {
        tracing::warn!(
            c_pos,
            c_neg,
            c,
            "separate thresholds ran to the search bound; keeping the common estimate"
        );
        return Thresholds::equal(c);
    }
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

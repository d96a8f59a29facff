//! The EDI arithmetic: per-pixel event index, exact integral, binned (E2NeRF) form, latent frames.

use gems_events::{EventError, EventSlice};
use rayon::prelude::*;

use super::EdiError;

/// A float image, row-major, `channels` interleaved values per pixel (1 = gray or Bayer mosaic,
/// 3 = RGB). Values are in the image's own encoding (see [`super::Linearisation`]).
#[derive(Debug, Clone, PartialEq)]
pub struct Image {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Values per pixel.
    pub channels: usize,
    /// `width·height·channels` values.
    pub data: Vec<f32>,
}

impl Image {
    /// Checks that `data` matches the declared shape.
    pub fn new(
        width: usize,
        height: usize,
        channels: usize,
        data: Vec<f32>,
    ) -> Result<Self, EdiError> {
        if data.len() != width * height * channels || channels == 0 {
            return Err(EdiError::Invalid(format!(
                "image data has {} values, {width}×{height}×{channels} needs {}",
                data.len(),
                width * height * channels
            )));
        }
        Ok(Self {
            width,
            height,
            channels,
            data,
        })
    }
    /// Mean over channels (gray view used by the threshold search).
    pub fn gray(&self) -> Vec<f32> {
        let c = self.channels;
        self.data
            .chunks_exact(c)
            .map(|p| p.iter().sum::<f32>() / c as f32)
            .collect()
    }
}

/// The events of one exposure window `[t0, t1]` grouped by pixel (counting sort, stable, so each
/// pixel's events stay in time order). Built once per view in O(events + pixels) and shared by
/// every EDI evaluation of that view (exact, binned, each threshold tried by the search).
#[derive(Debug, Clone)]
pub struct PixelEvents {
    width: usize,
    height: usize,
    t0: i64,
    t1: i64,
    /// `offsets[k]..offsets[k+1]` indexes pixel k's events.
    offsets: Vec<u32>,
    t: Vec<i64>,
    p: Vec<i8>,
}

impl PixelEvents {
    /// Groups the events of `events` that fall in `[t0, t1]` by pixel.
    pub fn new(events: EventSlice<'_>, t0: i64, t1: i64) -> Result<Self, EdiError> {
        if t1 <= t0 {
            return Err(EdiError::Invalid(format!(
                "exposure window [{t0}, {t1}] µs is empty"
            )));
        }
        let win = events.window(t0, t1);
        let (w, h) = (events.width() as usize, events.height() as usize);
        let n = w * h;
        if win.len() >= u32::MAX as usize {
            return Err(EdiError::Events(EventError::Invalid(
                "more than 4 billion events in one exposure".into(),
            )));
        }
        let mut offsets = vec![0u32; n + 1];
        for (&x, &y) in win.x().iter().zip(win.y()) {
            offsets[y as usize * w + x as usize + 1] += 1;
        }
        for k in 0..n {
            offsets[k + 1] += offsets[k];
        }
        let mut fill = offsets.clone();
        let mut t = vec![0i64; win.len()];
        let mut p = vec![0i8; win.len()];
        for i in 0..win.len() {
            let k = win.y()[i] as usize * w + win.x()[i] as usize;
            let slot = fill[k] as usize;
            fill[k] += 1;
            t[slot] = win.t()[i];
            p[slot] = win.p()[i];
        }
        Ok(Self {
            width: w,
            height: h,
            t0,
            t1,
            offsets,
            t,
            p,
        })
    }
    /// Image width.
    pub fn width(&self) -> usize {
        self.width
    }
    /// Image height.
    pub fn height(&self) -> usize {
        self.height
    }
    /// Exposure window `(t0, t1)` in µs.
    pub fn window(&self) -> (i64, i64) {
        (self.t0, self.t1)
    }
    /// Number of events in the window.
    pub fn len(&self) -> usize {
        self.t.len()
    }
    /// True when the window holds no events.
    pub fn is_empty(&self) -> bool {
        self.t.is_empty()
    }
    /// Pixel `k`'s event times and polarities.
    pub fn pixel(&self, k: usize) -> (&[i64], &[i8]) {
        let (a, b) = (self.offsets[k] as usize, self.offsets[k + 1] as usize);
        (&self.t[a..b], &self.p[a..b])
    }
    /// Signed polarity sum per pixel with events before `f` counted negatively — the event edge
    /// map M of the threshold search (Pan et al., CVPR 2019;
    /// `ac-freeman/davis-EDI-rs:src/util/reconstructor.rs`).
    pub fn signed_map(&self, f: i64) -> Vec<f32> {
        (0..self.width * self.height)
            .map(|k| {
                let (t, p) = self.pixel(k);
                t.iter()
                    .zip(p)
                    .map(|(&ti, &pi)| {
                        if ti <= f {
                            -f32::from(pi)
                        } else {
                            f32::from(pi)
                        }
                    })
                    .sum()
            })
            .collect()
    }
    /// ON and OFF counts per bin and pixel: `[bins][2][H·W]` flattened (`[k][0]` ON, `[k][1]` OFF),
    /// bin k = `(t0 + k·T/b, t0 + (k+1)·T/b]` (an event exactly at t0 goes to bin 0).
    pub fn bin_on_off(&self, bins: usize) -> Vec<f32> {
        let n = self.width * self.height;
        let mut out = vec![0f32; bins * 2 * n];
        let span = (self.t1 - self.t0) as i128;
        for k in 0..n {
            let (t, p) = self.pixel(k);
            for (&ti, &pi) in t.iter().zip(p) {
                let dt = (ti - self.t0) as i128;
                let b =
                    ((dt * bins as i128 + span - 1) / span - 1).clamp(0, bins as i128 - 1) as usize;
                out[(b * 2 + usize::from(pi < 0)) * n + k] += 1.0;
            }
        }
        out
    }
}

/// Exponent of one event: `+c₊` for ON, `−c₋` for OFF.
#[inline]
fn step(p: i8, c_pos: f64, c_neg: f64) -> f64 {
    if p > 0 { c_pos } else { -c_neg }
}

/// `E_t0(f)`: the exponent at `f` relative to the window start (events at or before `f`).
#[inline]
fn level_at(t: &[i64], p: &[i8], f: i64, (c_pos, c_neg): (f64, f64)) -> f64 {
    t.iter()
        .zip(p)
        .take_while(|&(&ti, _)| ti <= f)
        .map(|(_, &pi)| step(pi, c_pos, c_neg))
        .sum()
}

/// Exact `J(f) = (1/T)·∫ exp(E_f(t)) dt` over the window for one pixel (piecewise-constant sum).
#[inline]
fn exact_j(t: &[i64], p: &[i8], (t0, t1): (i64, i64), f: i64, c: (f64, f64)) -> f64 {
    // E_f(t) = E_t0(t) − E_t0(f)
    let mut e = -level_at(t, p, f, c);
    let mut prev = t0;
    let mut acc = 0.0;
    for (&ti, &pi) in t.iter().zip(p) {
        acc += (ti - prev) as f64 * e.exp();
        e += step(pi, c.0, c.1);
        prev = ti;
    }
    acc += (t1 - prev) as f64 * e.exp();
    acc / (t1 - t0) as f64
}

/// `J(f) = (1/N)·Σ_k exp(E_f(t_k))` over `N ≥ 2` instants `t_k = t0 + k·T/(N−1)` (both ends
/// included): the exposure of a blurry image that is the mean of N sharp sub-frames.
#[inline]
fn sampled_j(
    t: &[i64],
    p: &[i8],
    (t0, t1): (i64, i64),
    f: i64,
    c: (f64, f64),
    samples: usize,
) -> f64 {
    let e_f = level_at(t, p, f, c);
    // one walk over the events, advancing to each (increasing) instant in turn
    let (mut i, mut e) = (0usize, 0.0);
    let span = i128::from(t1 - t0);
    let n = samples as i128;
    let mut acc = 0.0;
    for k in 0..n {
        let at = t0 + (span * k / (n - 1)) as i64;
        while i < t.len() && t[i] <= at {
            e += step(p[i], c.0, c.1);
            i += 1;
        }
        acc += (e - e_f).exp();
    }
    acc / samples as f64
}

/// Per-pixel factors `1/J(f)` of the exact EDI at time `f` (so `L(f) = B/J(f)`); pixels without
/// events get exactly 1. Since `J(t) = J(f)·exp(−E_f(t))`, evaluating at any `t` directly gives the
/// same latent frame as `L(f)·exp(E_f(t))`. `c_pos`/`c_neg` are the exponents in the image's value
/// domain.
pub fn exact_factors(pe: &PixelEvents, f: i64, c_pos: f64, c_neg: f64) -> Vec<f32> {
    latent_factors(pe, f, (c_pos, c_neg), None)
}

/// [`exact_factors`] for a blurry image that is the mean of `samples` equally spaced sharp
/// sub-frames (both exposure ends included, as `gems synth` and the GeMS/BAD-Gaussians virtual
/// cameras form it) instead of a continuous exposure: `J(f) = (1/N)·Σ_k exp(E_f(t_k))`.
pub fn sampled_factors(
    pe: &PixelEvents,
    f: i64,
    c_pos: f64,
    c_neg: f64,
    samples: usize,
) -> Vec<f32> {
    latent_factors(pe, f, (c_pos, c_neg), Some(samples))
}

/// The factors `1/J(f)` of a continuous (`samples = None`) or sampled exposure.
pub(crate) fn latent_factors(
    pe: &PixelEvents,
    f: i64,
    c: (f64, f64),
    samples: Option<usize>,
) -> Vec<f32> {
    let n = pe.width * pe.height;
    let window = (pe.t0, pe.t1);
    (0..n)
        .into_par_iter()
        .with_min_len(4096)
        .map(|k| {
            let (t, p) = pe.pixel(k);
            if t.is_empty() {
                return 1.0;
            }
            let j = match samples {
                Some(s) if s >= 2 => sampled_j(t, p, window, f, c, s),
                _ => exact_j(t, p, window, f, c),
            };
            (1.0 / j.max(1e-8)) as f32
        })
        .collect()
}

/// Binned (E2NeRF) factors: for each of the `b+1` bin boundaries k, `exp(S_k)·(b+1)/Σ_j exp(S_j)`
/// per pixel, with `S_k` the cumulative exponent of bins `1..=k` (S₀ = 0). `on_off` is
/// `[bins][2][H·W]` as from [`PixelEvents::bin_on_off`]. Returns `[(b+1)][H·W]` flattened.
pub fn binned_factors(on_off: &[f32], bins: usize, n: usize, c_pos: f64, c_neg: f64) -> Vec<f32> {
    let mut out = vec![0f32; (bins + 1) * n];
    let cols: Vec<Vec<f32>> = (0..n)
        .into_par_iter()
        .with_min_len(4096)
        .map(|k| {
            let mut s = vec![0f64; bins + 1];
            for b in 0..bins {
                let on = f64::from(on_off[(b * 2) * n + k]);
                let off = f64::from(on_off[(b * 2 + 1) * n + k]);
                s[b + 1] = s[b] + c_pos * on - c_neg * off;
            }
            let m = s.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            let denom: f64 = s.iter().map(|&v| (v - m).exp()).sum();
            s.iter()
                .map(|&v| ((bins + 1) as f64 * (v - m).exp() / denom) as f32)
                .collect()
        })
        .collect();
    for (k, col) in cols.iter().enumerate() {
        for (b, &v) in col.iter().enumerate() {
            out[b * n + k] = v;
        }
    }
    out
}

/// Signed (net) counts `[bins][H·W]` → the `[bins][2][H·W]` ON/OFF layout: a positive net count
/// is taken as ON events, a negative one as OFF events (exact when only one polarity fired per
/// bin and pixel; with c₊ = c₋ always exact).
pub fn on_off_from_signed(signed: &[f32], bins: usize, n: usize) -> Vec<f32> {
    let mut out = vec![0f32; bins * 2 * n];
    for b in 0..bins {
        for k in 0..n {
            let v = signed[b * n + k];
            out[(b * 2 + usize::from(v < 0.0)) * n + k] = v.abs();
        }
    }
    out
}

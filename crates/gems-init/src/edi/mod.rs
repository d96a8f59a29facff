//! Event-based double-integral (EDI) deblurring (Pan et al., CVPR 2019): sharp latent
//! frames from a blurry image and the events fired during its exposure. GeMS-E uses these images
//! only to initialise (SfM poses and points); training still sees the blurry images.
//!
//! # Model
//! For a pixel with events `(tᵢ, pᵢ)` in the exposure `[t₀, t₁]` (`T = t₁ − t₀`) and reference
//! time `f`, `E_f(t) = c₊·n_on(f→t) − c₋·n_off(f→t)` (negated before `f`). The blurry value is
//! `B = L(f)·J(f)` with `J(f) = (1/T)∫exp(E_f(t))dt`, so `L(f) = B/J(f)`.
//! - **Exact** ([`edi_exact`]): `J` is the exact sum of segment length × `exp(E)` over the
//!   piecewise-constant `E` — O(events + pixels), no discretisation. A pixel without events is
//!   returned bit-exactly.
//! - **Binned** ([`edi_binned`], E2NeRF/GeMS-E): `b` equal bins, `S_k` cumulative exponent of bins
//!   `1..=k`, `I₀ = (b+1)·B/Σ_{k=0..b} exp(S_k)`, `I_k = I₀·exp(S_k)` → `b+1` frames at the bin
//!   boundaries (b = 13 → 14 frames = GeMS-E's 14 virtual views). Also from pre-binned signed counts
//!   ([`gems_events::BinCounts`]).
//! - **Thresholds** ([`estimate_thresholds`]): when `c` is unknown, a 1-D search on [0.1, 0.5]
//!   (coarse grid, then golden section) minimising the normalised sparsity `‖∇L‖₁/‖∇L‖₂` of the
//!   gray latent near strong monotone edges ([`SearchEnergy`]; the published
//!   `λ·TV(L) − Σ edge(L)·edge(M)` is kept as an option but runs to the lower bound), per view
//!   or over several views; optionally c₊ and c₋ apart. Measured: within 0.03 of the simulated
//!   c on a moving dead-leaves texture (c 0.15–0.3, c₊ ≠ c₋) and on the `gems synth` small
//!   preset (c = 0.2 → 0.189, c = 0.3 → 0.308).
//!
//! # Values
//! [`Linearisation`] says how stored values relate to the light the events saw
//! ([`Linearisation::SrgbEncodedAverage`] for `gems synth` and other mean-of-sRGB-frames blur);
//! [`EdiConfig::exposure_samples`] models a blurry image that is the mean of N sub-frames
//! ([`sampled_factors`]) instead of a continuous exposure. The same event factor multiplies
//! every channel (exact only when a pixel's hue does not change during the exposure: with
//! luminance events and coloured texture, EDI cannot know the hue at the reference time);
//! saturated inputs (≥ 1) are kept; outputs are clamped to `[0, upper_clamp]`. A single-channel
//! Bayer mosaic is deblurred per mosaic pixel and then demosaiced ([`BayerPattern`]).
//!
//! # Scenes
//! [`deblur_scene`]`(&Scene, &EdiConfig)` runs EDI on every view that has an exposure window (and
//! events) or a pre-binned count slice, and [`write_edi_scene`] writes the result as a scene folder
//! (same layout, EDI images in `images/`, intrinsics/poses/split files copied) that any
//! initialiser reads. This is the function `gems edi` and `gems train --events` call.

mod core;
mod scene;
mod search;

use core::latent_factors;
pub use core::{
    Image, PixelEvents, binned_factors, exact_factors, on_off_from_signed, sampled_factors,
};
pub use scene::{EdiScene, EdiView, deblur_scene, write_edi_scene};
pub use search::{
    SearchConfig, SearchEnergy, estimate_thresholds, event_edges, minimise, normalised_sparsity,
    sharpness_energy,
};

/// Errors of the EDI stage.
#[derive(Debug, thiserror::Error)]
pub enum EdiError {
    /// Reading events failed (the message names the file).
    #[error(transparent)]
    Events(#[from] gems_events::EventError),
    /// Reading or writing scene data failed (the message names the file).
    #[error(transparent)]
    Data(#[from] gems_data::DataError),
    /// A file-system operation on the output folder failed.
    #[error("{path}: {source}")]
    Io {
        /// The file or folder.
        path: std::path::PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// Inputs are inconsistent (sizes, windows, parameters) or the scene lacks what EDI needs.
    #[error("EDI: {0}")]
    Invalid(String),
}

/// How stored image values relate to the linear light the events measured.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Linearisation {
    /// Values are linear (default; raw DAVIS APS, linear synthetic data).
    Identity,
    /// Values are sRGB-encoded; the blur happened in linear light.
    Srgb,
    /// Values are `linear^(1/γ)`; the blur happened in linear light.
    Gamma(f32),
    /// The blurry image is the mean of *encoded* sharp frames (`value = linear^(1/γ)`), the
    /// GeMS/BAD-Gaussians blur model: EDI runs on the stored values with the event exponent
    /// scaled by 1/γ (log of an encoded value = log(linear)/γ). An approximation for sRGB data;
    /// prefer [`Linearisation::SrgbEncodedAverage`] there.
    EncodedAverage(f32),
    /// The blurry image is the mean of **sRGB-encoded** sharp frames while the events saw linear
    /// light (the `gems synth` and GeMS/BAD-Gaussians formation model). Above its linear toe,
    /// sRGB is `1.055·x^(1/2.4) − 0.055`, so `B + 0.055 = 1.055·L(f)^(1/2.4)·(1/T)∫exp(E/2.4)`:
    /// EDI runs on `B + 0.055` with the exponent scaled by 1/2.4 and 0.055 is subtracted again.
    /// Exact (no γ approximation) wherever the pixel's frames stay above the toe (linear value
    /// 0.0031, encoded 0.04) and below saturation.
    SrgbEncodedAverage,
}

/// Offset `a` of the sRGB curve `(1 + a)·x^(1/2.4) − a`.
const SRGB_OFFSET: f32 = 0.055;

impl Linearisation {
    fn decode(self, v: f32) -> f32 {
        match self {
            Linearisation::Identity | Linearisation::EncodedAverage(_) => v,
            Linearisation::SrgbEncodedAverage => v + SRGB_OFFSET,
            Linearisation::Srgb => {
                if v <= 0.04045 {
                    v / 12.92
                } else {
                    ((v + 0.055) / 1.055).powf(2.4)
                }
            }
            Linearisation::Gamma(g) => v.max(0.0).powf(g),
        }
    }
    pub(crate) fn encode(self, v: f32) -> f32 {
        match self {
            Linearisation::Identity | Linearisation::EncodedAverage(_) => v,
            Linearisation::SrgbEncodedAverage => v - SRGB_OFFSET,
            Linearisation::Srgb => {
                let v = v.max(0.0);
                if v <= 0.003_130_8 {
                    v * 12.92
                } else {
                    1.055 * v.powf(1.0 / 2.4) - 0.055
                }
            }
            Linearisation::Gamma(g) => v.max(0.0).powf(1.0 / g),
        }
    }
    /// Factor turning an event threshold into an exponent in the processing domain.
    fn exponent_scale(self) -> f64 {
        match self {
            Linearisation::EncodedAverage(g) => 1.0 / f64::from(g),
            Linearisation::SrgbEncodedAverage => 1.0 / 2.4,
            Linearisation::Identity | Linearisation::Srgb | Linearisation::Gamma(_) => 1.0,
        }
    }
}

/// Colour filter layout of a raw mosaic, named by the 2×2 tile read row by row from (0, 0).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BayerPattern {
    /// R G / G B.
    Rggb,
    /// B G / G R (DAVIS346 colour, OpenCV's BayerBG).
    Bggr,
    /// G R / B G.
    Grbg,
    /// G B / R G.
    Gbrg,
}

impl BayerPattern {
    /// Colour index (0 R, 1 G, 2 B) of pixel (x, y).
    pub fn colour(self, x: usize, y: usize) -> usize {
        let tile = match self {
            BayerPattern::Rggb => [0, 1, 1, 2],
            BayerPattern::Bggr => [2, 1, 1, 0],
            BayerPattern::Grbg => [1, 0, 2, 1],
            BayerPattern::Gbrg => [1, 2, 0, 1],
        };
        tile[(y % 2) * 2 + (x % 2)]
    }
}

/// Contrast thresholds (log-intensity step per ON / OFF event).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Thresholds {
    /// ON threshold c₊.
    pub c_pos: f32,
    /// OFF threshold c₋ (positive).
    pub c_neg: f32,
}

impl Thresholds {
    /// The same threshold for both polarities.
    pub fn equal(c: f32) -> Self {
        Self { c_pos: c, c_neg: c }
    }
}

/// When the output frame is taken, for single-frame outputs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Reference {
    /// Mid-exposure (default; matches the sharp ground truth of GeMS/BAD datasets).
    Mid,
    /// Exposure start (E2NeRF's reference).
    Start,
}

/// Which frames [`deblur_scene`] produces per view.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EdiMode {
    /// One frame at the [`Reference`] time, exact integral (primary).
    Exact,
    /// `bins + 1` frames at the bin boundaries (GeMS-E: 13 bins → 14 frames).
    Binned {
        /// Number of equal bins.
        bins: usize,
    },
}

/// Settings of the EDI stage.
#[derive(Debug, Clone, PartialEq)]
pub struct EdiConfig {
    /// Known thresholds; ignored when `search` is set.
    pub thresholds: Thresholds,
    /// Estimate the thresholds instead (see [`SearchConfig`]).
    pub search: Option<SearchConfig>,
    /// Output time for [`EdiMode::Exact`].
    pub reference: Reference,
    /// Exact single frame or binned frames.
    pub mode: EdiMode,
    /// Stored values ↔ linear light.
    pub linearisation: Linearisation,
    /// Upper clamp of the output (1.0; davis-EDI-rs uses 1.1).
    pub upper_clamp: f32,
    /// Treat single-channel input as a raw Bayer mosaic of this layout (demosaic after EDI).
    pub bayer: Option<BayerPattern>,
    /// `Some(N)`: the blurry image is the mean of N equally spaced sharp sub-frames, both
    /// exposure ends included (`gems synth`: N = its `subframes`; the GeMS/BAD-Gaussians virtual
    /// cameras), so [`EdiMode::Exact`] and the threshold search use `J = (1/N)·Σ_k exp(E(t_k))`.
    /// `None` (default): a continuous exposure, the exact integral.
    pub exposure_samples: Option<usize>,
}

impl Default for EdiConfig {
    fn default() -> Self {
        Self {
            thresholds: Thresholds::equal(0.2),
            search: None,
            reference: Reference::Mid,
            mode: EdiMode::Exact,
            linearisation: Linearisation::Identity,
            upper_clamp: 1.0,
            bayer: None,
            exposure_samples: None,
        }
    }
}

/// Applies per-pixel factors `g` to the blurry image: `out = enc(clamp(lin(B)·g))`; pixels with
/// `g == 1` and saturated values (`B ≥ 1`) are copied unchanged.
pub fn apply_factors(blurry: &Image, factors: &[f32], cfg: &EdiConfig) -> Image {
    let c = blurry.channels;
    let lin = cfg.linearisation;
    let upper = cfg.upper_clamp;
    let data = blurry
        .data
        .chunks_exact(c)
        .zip(factors)
        .flat_map(|(px, &g)| {
            px.iter().map(move |&b| {
                if g == 1.0 || b >= 1.0 {
                    b
                } else {
                    // negative light is impossible; the final clamp is in stored values
                    lin.encode((lin.decode(b) * g).max(0.0)).clamp(0.0, upper)
                }
            })
        })
        .collect();
    Image {
        width: blurry.width,
        height: blurry.height,
        channels: c,
        data,
    }
}

fn check_sizes(blurry: &Image, pe: &PixelEvents) -> Result<(), EdiError> {
    if (blurry.width, blurry.height) != (pe.width(), pe.height()) {
        return Err(EdiError::Invalid(format!(
            "image is {}×{} but the event sensor is {}×{}",
            blurry.width,
            blurry.height,
            pe.width(),
            pe.height()
        )));
    }
    Ok(())
}

/// Bilinear demosaic of a single-channel mosaic: each colour at each pixel is the mean of that
/// colour's samples in the 3×3 neighbourhood (the pixel itself when it carries that colour).
pub fn demosaic(mosaic: &Image, pattern: BayerPattern) -> Image {
    let (w, h) = (mosaic.width, mosaic.height);
    let mut data = vec![0f32; w * h * 3];
    for y in 0..h {
        for x in 0..w {
            let own = pattern.colour(x, y);
            for ch in 0..3 {
                if ch == own {
                    data[(y * w + x) * 3 + ch] = mosaic.data[y * w + x];
                    continue;
                }
                let (mut sum, mut n) = (0.0, 0);
                for yy in y.saturating_sub(1)..(y + 2).min(h) {
                    for xx in x.saturating_sub(1)..(x + 2).min(w) {
                        if pattern.colour(xx, yy) == ch {
                            sum += mosaic.data[yy * w + xx];
                            n += 1;
                        }
                    }
                }
                data[(y * w + x) * 3 + ch] = if n > 0 { sum / n as f32 } else { 0.0 };
            }
        }
    }
    Image {
        width: w,
        height: h,
        channels: 3,
        data,
    }
}

fn finish(img: Image, cfg: &EdiConfig) -> Image {
    match cfg.bayer {
        Some(p) if img.channels == 1 => demosaic(&img, p),
        _ => img,
    }
}

/// Exact EDI: the latent frame at time `at` (any time in the window; use the window middle for
/// mid-exposure) from the blurry image and the view's grouped events.
pub fn edi_exact(
    blurry: &Image,
    pe: &PixelEvents,
    at: i64,
    th: Thresholds,
    cfg: &EdiConfig,
) -> Result<Image, EdiError> {
    check_sizes(blurry, pe)?;
    let s = cfg.linearisation.exponent_scale();
    let c = (f64::from(th.c_pos) * s, f64::from(th.c_neg) * s);
    let g = latent_factors(pe, at, c, cfg.exposure_samples);
    Ok(finish(apply_factors(blurry, &g, cfg), cfg))
}

/// Binned EDI from ON/OFF bin counts `[bins][2][H·W]` (see [`PixelEvents::bin_on_off`] and
/// [`on_off_from_signed`]): the `bins + 1` frames at the bin boundaries, first = exposure start.
pub fn edi_binned(
    blurry: &Image,
    on_off: &[f32],
    bins: usize,
    th: Thresholds,
    cfg: &EdiConfig,
) -> Result<Vec<Image>, EdiError> {
    let n = blurry.width * blurry.height;
    if bins == 0 || on_off.len() != bins * 2 * n {
        return Err(EdiError::Invalid(format!(
            "binned EDI: {} counts do not match {bins} bins of {}×{} ON/OFF images",
            on_off.len(),
            blurry.width,
            blurry.height
        )));
    }
    let s = cfg.linearisation.exponent_scale();
    let f = binned_factors(
        on_off,
        bins,
        n,
        f64::from(th.c_pos) * s,
        f64::from(th.c_neg) * s,
    );
    Ok(f.chunks_exact(n)
        .map(|g| finish(apply_factors(blurry, g, cfg), cfg))
        .collect())
}

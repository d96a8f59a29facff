//! Blur-robust features: a grey image reduced to the pyramid level where motion blur is a few
//! pixels, Shi–Tomasi (minimum-eigenvalue) keypoints of the heavily smoothed image, and
//! mean/contrast-normalised patch descriptors (NCC) sampled around each keypoint.
//!
//! Why this and not SIFT: 30–60 px of motion blur wipes out fine-scale extrema, but the coarse
//! intensity layout survives. At a level where the blur is ~3–6 px, a smoothed patch of a blurred
//! image still correlates with the same patch in a view blurred along another direction.

use rayon::prelude::*;

/// A single-channel f32 image, row-major.
#[derive(Clone, Debug)]
pub(crate) struct Gray {
    pub w: usize,
    pub h: usize,
    pub data: Vec<f32>,
}

impl Gray {
    pub fn from_rgb(img: &image::RgbImage) -> Gray {
        let (w, h) = (img.width() as usize, img.height() as usize);
        let data = img
            .as_raw()
            .chunks_exact(3)
            .map(|p| (0.299 * p[0] as f32 + 0.587 * p[1] as f32 + 0.114 * p[2] as f32) / 255.0)
            .collect();
        Gray { w, h, data }
    }

    #[inline]
    fn at(&self, x: usize, y: usize) -> f32 {
        self.data[y * self.w + x]
    }

    /// Bilinear sample at continuous pixel coordinates (pixel centres at integer + 0.5),
    /// clamped at the border.
    #[inline]
    pub fn sample(&self, x: f32, y: f32) -> f32 {
        let fx = (x - 0.5).clamp(0.0, (self.w - 1) as f32);
        let fy = (y - 0.5).clamp(0.0, (self.h - 1) as f32);
        let x0 = fx.floor() as usize;
        let y0 = fy.floor() as usize;
        let x1 = (x0 + 1).min(self.w - 1);
        let y1 = (y0 + 1).min(self.h - 1);
        let ax = fx - x0 as f32;
        let ay = fy - y0 as f32;
        let top = self.at(x0, y0) * (1.0 - ax) + self.at(x1, y0) * ax;
        let bot = self.at(x0, y1) * (1.0 - ax) + self.at(x1, y1) * ax;
        top * (1.0 - ay) + bot * ay
    }

    /// Separable Gaussian blur with clamped borders.
    pub fn gaussian(&self, sigma: f32) -> Gray {
        if sigma <= 0.0 {
            return self.clone();
        }
        let r = (3.0 * sigma).ceil() as isize;
        let kernel: Vec<f32> = (-r..=r)
            .map(|i| (-(i * i) as f32 / (2.0 * sigma * sigma)).exp())
            .collect();
        let norm: f32 = kernel.iter().sum();
        let kernel: Vec<f32> = kernel.iter().map(|k| k / norm).collect();
        let (w, h) = (self.w, self.h);
        let mut tmp = vec![0.0f32; w * h];
        tmp.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
            let src = &self.data[y * w..(y + 1) * w];
            for (x, out) in row.iter_mut().enumerate() {
                let mut acc = 0.0;
                for (k, kv) in kernel.iter().enumerate() {
                    let xi = (x as isize + k as isize - r).clamp(0, w as isize - 1) as usize;
                    acc += kv * src[xi];
                }
                *out = acc;
            }
        });
        let mut data = vec![0.0f32; w * h];
        data.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
            for (k, kv) in kernel.iter().enumerate() {
                let yi = (y as isize + k as isize - r).clamp(0, h as isize - 1) as usize;
                let src = &tmp[yi * w..(yi + 1) * w];
                for (o, s) in row.iter_mut().zip(src) {
                    *o += kv * s;
                }
            }
        });
        Gray { w, h, data }
    }

    /// Anti-aliased resize by `scale` (< 1 shrinks): Gaussian pre-filter, then bilinear sampling.
    /// The same factor applies to both axes (x_out = scale · x_in), so callers should pick
    /// `scale` with `width · scale` integral (see [`exact_scale`]).
    pub fn resized(&self, scale: f32) -> Gray {
        if (scale - 1.0).abs() < 1e-6 {
            return self.clone();
        }
        let src = if scale < 1.0 {
            self.gaussian(0.4 / scale)
        } else {
            self.clone()
        };
        let w = ((self.w as f32 * scale).round() as usize).max(1);
        let h = ((self.h as f32 * scale).round() as usize).max(1);
        let inv = 1.0 / scale;
        let mut data = vec![0.0f32; w * h];
        data.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
            for (x, o) in row.iter_mut().enumerate() {
                *o = src.sample((x as f32 + 0.5) * inv, (y as f32 + 0.5) * inv);
            }
        });
        Gray { w, h, data }
    }
}

/// The scale closest to `target` (≤ 1) that maps `width` to a whole number of pixels.
pub(crate) fn exact_scale(width: u32, target: f64) -> f64 {
    let t = target.min(1.0);
    let w = (width as f64 * t).round().max(1.0);
    w / width as f64
}

/// Long side of the reduced image [`estimate_blur_px`] works on.
const BLUR_EST_SIDE: f32 = 240.0;

/// Motion-blur length of an image in its own pixels, 0 when no blur is detected.
///
/// A motion-blurred image is the sharp image convolved with the path kernel; its derivative along
/// the blur direction is dominated by the kernel's two ends, so the autocorrelation of that
/// directional derivative has a negative lobe at a lag equal to the path length (Yitzhaky &
/// Kopeika). Derivatives along a direction ignore edges parallel to it, so long straight edges do
/// not pass for blur. A lobe shallower than −0.05 means no blur was found.
///
/// Two readings of the per-direction curves are taken and the deeper lobe wins
/// ([`blur_lobe_by_zero_crossing`], [`blur_lobe_near_decay`]): the first finds long blurs whose
/// lobe lies well past the correlation's decay, the second keeps sharp photos with broad soft
/// texture (striped walls and floors among finely textured objects) from reading as blurred.
/// A photo filled with one periodic pattern still reads about its period: its two edges give
/// the lobe a blur's two ends give (crates/gems-init/BENCHMARKS.md, "The blur estimate on sharp
/// photos").
pub(crate) fn estimate_blur_px(img: &Gray) -> f32 {
    let long = img.w.max(img.h) as f32;
    let scale = (BLUR_EST_SIDE / long).min(1.0);
    let g = img.resized(scale).gaussian(0.5);
    let (w, h) = (g.w, g.h);
    if w < 16 || h < 16 {
        return 0.0;
    }
    let mut gx = vec![0.0f32; w * h];
    let mut gy = vec![0.0f32; w * h];
    for y in 1..h - 1 {
        for x in 1..w - 1 {
            gx[y * w + x] = 0.5 * (g.at(x + 1, y) - g.at(x - 1, y));
            gy[y * w + x] = 0.5 * (g.at(x, y + 1) - g.at(x, y - 1));
        }
    }
    let max_lag = (w.min(h) / 3).max(4);
    let dirs = 12;
    // Normalised autocorrelation of the directional derivative at integer lags, per direction.
    let curves: Vec<Vec<f32>> = (0..dirs)
        .into_par_iter()
        .map(|k| {
            let th = std::f32::consts::PI * k as f32 / dirs as f32;
            let (c, s) = (th.cos(), th.sin());
            let d = Gray {
                w,
                h,
                data: gx.iter().zip(&gy).map(|(a, b)| c * a + s * b).collect(),
            };
            let mut curve = vec![0.0f32; max_lag + 1];
            // Only pixels whose shifted partner stays inside the image.
            let m = max_lag as f32;
            let x0 = 1 + (m * c.min(0.0)).abs().ceil() as usize;
            let x1 = (w - 1).saturating_sub((m * c.max(0.0)).ceil() as usize + 1);
            let y1 = (h - 1).saturating_sub((m * s).ceil() as usize + 1);
            if x1 <= x0 + 4 || y1 <= 5 {
                return curve;
            }
            let mut e0 = 0.0f32;
            for y in 1..y1 {
                for x in x0..x1 {
                    e0 += d.at(x, y) * d.at(x, y);
                }
            }
            if e0 <= 1e-12 {
                return curve;
            }
            for (lag, v) in curve.iter_mut().enumerate().skip(2) {
                let (ox, oy) = (c * lag as f32, s * lag as f32);
                let mut acc = 0.0f32;
                for y in 1..y1 {
                    for x in x0..x1 {
                        acc += d.at(x, y) * d.sample(x as f32 + 0.5 + ox, y as f32 + 0.5 + oy);
                    }
                }
                *v = acc / e0;
            }
            curve
        })
        .collect();
    // The deeper lobe; on a tie the first reading's.
    [
        blur_lobe_by_zero_crossing(&curves, max_lag),
        blur_lobe_near_decay(&curves, max_lag),
    ]
    .into_iter()
    .flatten()
    .min_by(|a, b| a.depth.total_cmp(&b.depth))
    .map_or(0.0, |lobe| lobe.lag as f32 / scale)
}

/// A negative lobe of one direction's derivative autocorrelation: where it is, how deep.
#[derive(Clone, Copy, Debug)]
struct BlurLobe {
    lag: usize,
    depth: f32,
}

/// Lobes shallower than this are no blur's.
const MIN_LOBE_DEPTH: f32 = -0.05;

/// The first reading. Structure of the scene (objects of some size) also gives negative lobes,
/// but at short lags and in every direction; along the blur the autocorrelation stays positive
/// for about half the blur length first. So the direction whose correlation stays positive
/// longest is the blur direction (ties: the deeper lobe), and its deepest lobe beyond that zero
/// crossing gives the length, at most 2.5× the crossing (a lobe far beyond is the scene's
/// structure). The depth is the curve's value at the returned lag. `None`: no lobe beyond
/// [`MIN_LOBE_DEPTH`].
///
/// On sharp photos with broad soft texture the correlation crosses zero late in the directions
/// nearly along the texture's bands, which are stretched projections of its short scale, and
/// the capped lag then reads as a blur of up to 20 px in a 240-px image.
fn blur_lobe_by_zero_crossing(curves: &[Vec<f32>], max_lag: usize) -> Option<BlurLobe> {
    let mut best: Option<(usize, f32, usize, usize)> = None;
    for (dir, curve) in curves.iter().enumerate() {
        let zero = (2..=max_lag).find(|&l| curve[l] < 0.0).unwrap_or(max_lag);
        let (lag, min) = (zero..=max_lag)
            .map(|l| (l, curve[l]))
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .unwrap_or((max_lag, 0.0));
        if best.is_none_or(|(z, m, _, _)| zero > z || (zero == z && min < m)) {
            best = Some((zero, min, lag, dir));
        }
    }
    let (zero, min, lag, dir) = best?;
    if min > MIN_LOBE_DEPTH {
        return None;
    }
    let lag = lag.min((2.5 * zero as f32).round() as usize);
    Some(BlurLobe {
        lag,
        depth: curves[dir][lag],
    })
}

/// The second reading. Per direction, where the correlation has decayed (first falls under
/// [`DECAYED_CORRELATION`]) and the deepest point within three times that lag, kept only when it
/// is a lobe: deeper than [`MIN_LOBE_DEPTH`] and not at the window's end (a curve still falling
/// there is the scene's structure). The direction that decays last wins (ties: the deeper lobe).
fn blur_lobe_near_decay(curves: &[Vec<f32>], max_lag: usize) -> Option<BlurLobe> {
    let mut best: Option<(usize, BlurLobe)> = None;
    for curve in curves {
        let Some(decay) = (2..=max_lag).find(|&l| curve[l] < DECAYED_CORRELATION) else {
            continue;
        };
        let end = (3 * decay).min(max_lag);
        let Some((lag, depth)) = (decay..=end)
            .map(|l| (l, curve[l]))
            .min_by(|a, b| a.1.total_cmp(&b.1))
        else {
            continue;
        };
        if depth > MIN_LOBE_DEPTH || lag >= end {
            continue;
        }
        if best.is_none_or(|(d, b)| decay > d || (decay == d && depth < b.depth)) {
            best = Some((decay, BlurLobe { lag, depth }));
        }
    }
    best.map(|(_, lobe)| lobe)
}

/// Correlation below which a direction's derivative has decorrelated (see
/// [`blur_lobe_near_decay`]).
const DECAYED_CORRELATION: f32 = 0.05;

/// Keypoints and descriptors of one image at the working level. `desc` is structure-of-arrays:
/// keypoint `k` owns `desc[k*DESC_LEN..(k+1)*DESC_LEN]`.
#[derive(Clone, Debug, Default)]
pub(crate) struct Features {
    pub xy: Vec<[f32; 2]>,
    pub desc: Vec<f32>,
}

/// Side of the square descriptor grid.
pub(crate) const DESC_SIDE: usize = 9;
pub(crate) const DESC_LEN: usize = DESC_SIDE * DESC_SIDE;

/// Feature-extraction settings, in working-level pixels.
#[derive(Clone, Debug)]
pub(crate) struct FeatureParams {
    pub max_features: usize,
    /// Smoothing applied before detection and description.
    pub smooth_sigma: f32,
    /// Spacing of descriptor samples.
    pub desc_step: f32,
    /// Non-maximum suppression radius.
    pub nms_radius: usize,
}

/// Detect Shi–Tomasi keypoints on `img` (already at the working level) and describe them.
/// Keypoints are spread over a grid so that a bright region cannot take all of them.
pub(crate) fn extract(img: &Gray, p: &FeatureParams) -> Features {
    let s = img.gaussian(p.smooth_sigma);
    let (w, h) = (s.w, s.h);
    if w < 8 || h < 8 {
        return Features::default();
    }
    // Structure tensor of the gradient, integrated with a Gaussian window.
    let mut gxx = vec![0.0f32; w * h];
    let mut gyy = vec![0.0f32; w * h];
    let mut gxy = vec![0.0f32; w * h];
    for y in 1..h - 1 {
        for x in 1..w - 1 {
            let dx = 0.5 * (s.at(x + 1, y) - s.at(x - 1, y));
            let dy = 0.5 * (s.at(x, y + 1) - s.at(x, y - 1));
            let i = y * w + x;
            gxx[i] = dx * dx;
            gyy[i] = dy * dy;
            gxy[i] = dx * dy;
        }
    }
    let win = 1.5f32.max(p.smooth_sigma);
    let gxx = Gray { w, h, data: gxx }.gaussian(win);
    let gyy = Gray { w, h, data: gyy }.gaussian(win);
    let gxy = Gray { w, h, data: gxy }.gaussian(win);
    let resp: Vec<f32> = (0..w * h)
        .map(|i| {
            let (a, b, c) = (gxx.data[i], gxy.data[i], gyy.data[i]);
            0.5 * (a + c) - (0.25 * (a - c) * (a - c) + b * b).sqrt()
        })
        .collect();
    let max_resp = resp.iter().copied().fold(0.0f32, f32::max);
    if max_resp <= 1e-12 {
        return Features::default();
    }
    let thresh = max_resp * 1e-3;
    let margin = ((DESC_SIDE / 2) as f32 * p.desc_step).ceil() as usize + 2;
    if w <= 2 * margin || h <= 2 * margin {
        return Features::default();
    }
    let r = p.nms_radius as isize;
    let mut cands: Vec<(f32, usize, usize)> = Vec::new();
    for y in margin..h - margin {
        for x in margin..w - margin {
            let v = resp[y * w + x];
            if v < thresh {
                continue;
            }
            let mut is_max = true;
            'nms: for dy in -r..=r {
                for dx in -r..=r {
                    if dx == 0 && dy == 0 {
                        continue;
                    }
                    let (xx, yy) = ((x as isize + dx) as usize, (y as isize + dy) as usize);
                    let u = resp[yy * w + xx];
                    // Ties broken by index so that plateaus give exactly one maximum.
                    if u > v || (u == v && (yy * w + xx) < y * w + x) {
                        is_max = false;
                        break 'nms;
                    }
                }
            }
            if is_max {
                cands.push((v, x, y));
            }
        }
    }
    // Grid bucketing: each of G×G cells keeps its strongest share, then the global best fill up.
    const G: usize = 6;
    let per_cell = (p.max_features / (G * G)).max(1);
    cands.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.2.cmp(&b.2)).then(a.1.cmp(&b.1)));
    let mut counts = [0usize; G * G];
    let mut chosen = Vec::with_capacity(p.max_features);
    let mut rest = Vec::new();
    for c in cands {
        let cell = (c.2 * G / h) * G + c.1 * G / w;
        if counts[cell] < per_cell {
            counts[cell] += 1;
            chosen.push(c);
        } else {
            rest.push(c);
        }
    }
    for c in rest {
        if chosen.len() >= p.max_features {
            break;
        }
        chosen.push(c);
    }
    chosen.truncate(p.max_features);

    let mut feats = Features {
        xy: Vec::with_capacity(chosen.len()),
        desc: Vec::with_capacity(chosen.len() * DESC_LEN),
    };
    let mut patch = [0.0f32; DESC_LEN];
    for &(_, x, y) in &chosen {
        // Sub-pixel peak by a quadratic fit through the response neighbourhood.
        let i = y * w + x;
        let sub = |m: f32, c: f32, pl: f32| {
            let d = m - 2.0 * c + pl;
            if d.abs() > 1e-12 {
                (0.5 * (m - pl) / d).clamp(-0.5, 0.5)
            } else {
                0.0
            }
        };
        let ox = sub(resp[i - 1], resp[i], resp[i + 1]);
        let oy = sub(resp[i - w], resp[i], resp[i + w]);
        let (cx, cy) = (x as f32 + 0.5 + ox, y as f32 + 0.5 + oy);
        if describe(&s, cx, cy, p.desc_step, &mut patch) {
            feats.xy.push([cx, cy]);
            feats.desc.extend_from_slice(&patch);
        }
    }
    feats
}

/// Zero-mean, unit-norm patch around (cx, cy). Returns false for a flat patch.
fn describe(s: &Gray, cx: f32, cy: f32, step: f32, out: &mut [f32; DESC_LEN]) -> bool {
    let half = (DESC_SIDE / 2) as f32;
    for j in 0..DESC_SIDE {
        for i in 0..DESC_SIDE {
            out[j * DESC_SIDE + i] =
                s.sample(cx + (i as f32 - half) * step, cy + (j as f32 - half) * step);
        }
    }
    let mean = out.iter().sum::<f32>() / DESC_LEN as f32;
    let mut norm = 0.0;
    for v in out.iter_mut() {
        *v -= mean;
        norm += *v * *v;
    }
    if norm < 1e-10 {
        return false;
    }
    let inv = 1.0 / norm.sqrt();
    for v in out.iter_mut() {
        *v *= inv;
    }
    true
}

/// Mutual-nearest-neighbour matches with Lowe's ratio test on descriptor distance and a minimum
/// normalised cross-correlation. Returns (index in `a`, index in `b`).
pub(crate) fn match_pair(a: &Features, b: &Features, ratio: f32, min_ncc: f32) -> Vec<(u32, u32)> {
    let na = a.xy.len();
    let nb = b.xy.len();
    if na < 2 || nb < 2 {
        return Vec::new();
    }
    // best[i] = (best j, best dot, second dot) for each row of a; column maxima for b.
    let mut best_a = vec![(u32::MAX, -2.0f32, -2.0f32); na];
    let mut best_b = vec![(u32::MAX, -2.0f32); nb];
    for (i, da) in a.desc.chunks_exact(DESC_LEN).enumerate() {
        for (j, db) in b.desc.chunks_exact(DESC_LEN).enumerate() {
            let d: f32 = da.iter().zip(db).map(|(x, y)| x * y).sum();
            let ba = &mut best_a[i];
            if d > ba.1 {
                ba.2 = ba.1;
                ba.1 = d;
                ba.0 = j as u32;
            } else if d > ba.2 {
                ba.2 = d;
            }
            if d > best_b[j].1 {
                best_b[j] = (i as u32, d);
            }
        }
    }
    let mut out = Vec::new();
    for (i, &(j, d1, d2)) in best_a.iter().enumerate() {
        if j == u32::MAX || d1 < min_ncc || best_b[j as usize].0 != i as u32 {
            continue;
        }
        // Distances of unit vectors: |a-b|² = 2 − 2·dot.
        let dist1 = (2.0 - 2.0 * d1).max(0.0).sqrt();
        let dist2 = (2.0 - 2.0 * d2).max(0.0).sqrt();
        if dist1 < ratio * dist2 {
            out.push((i as u32, j));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn blobs(w: usize, h: usize, shift: f32) -> Gray {
        let mut data = vec![0.0f32; w * h];
        let centres = [
            (20.0, 18.0, 4.0),
            (50.0, 40.0, 6.0),
            (33.0, 52.0, 3.0),
            (60.0, 12.0, 5.0),
        ];
        for y in 0..h {
            for x in 0..w {
                let mut v = 0.2;
                for &(cx, cy, s) in &centres {
                    let dx = x as f32 + 0.5 - cx - shift;
                    let dy = y as f32 + 0.5 - cy;
                    v += (-(dx * dx + dy * dy) / (2.0 * s * s)).exp();
                }
                data[y * w + x] = v;
            }
        }
        Gray { w, h, data }
    }

    #[test]
    fn gaussian_preserves_mean_and_constant() {
        let g = Gray {
            w: 10,
            h: 7,
            data: vec![0.3; 70],
        };
        let b = g.gaussian(2.0);
        assert!(b.data.iter().all(|v| (v - 0.3).abs() < 1e-5));
    }

    #[test]
    fn shifted_image_matches_with_same_offset() {
        let a = blobs(80, 64, 0.0);
        let b = blobs(80, 64, 3.0);
        let p = FeatureParams {
            max_features: 100,
            smooth_sigma: 1.0,
            desc_step: 1.0,
            nms_radius: 3,
        };
        let fa = extract(&a, &p);
        let fb = extract(&b, &p);
        assert!(fa.xy.len() >= 3, "{}", fa.xy.len());
        let m = match_pair(&fa, &fb, 0.9, 0.5);
        assert!(m.len() >= 3, "{} matches", m.len());
        for (i, j) in m {
            let (pa, pb) = (fa.xy[i as usize], fb.xy[j as usize]);
            assert!((pb[0] - pa[0] - 3.0).abs() < 0.3, "{pa:?} {pb:?}");
            assert!((pb[1] - pa[1]).abs() < 0.3, "{pa:?} {pb:?}");
        }
    }

    #[test]
    fn flat_image_has_no_features() {
        let g = Gray {
            w: 64,
            h: 64,
            data: vec![0.5; 64 * 64],
        };
        let p = FeatureParams {
            max_features: 100,
            smooth_sigma: 1.0,
            desc_step: 1.0,
            nms_radius: 3,
        };
        assert!(extract(&g, &p).xy.is_empty());
    }

    /// Random discs (sharp texture) box-blurred along a line of `len` px at angle `deg`.
    fn blurred_discs(len: usize, deg: f32) -> Gray {
        let (w, h) = (240usize, 160usize);
        let mut sharp = vec![0.3f32; w * h];
        let mut state = 12345u32;
        let mut rnd = || {
            state = state.wrapping_mul(1664525).wrapping_add(1013904223);
            (state >> 8) as f32 / (1u32 << 24) as f32
        };
        for _ in 0..160 {
            let (cx, cy, r, v) = (rnd() * w as f32, rnd() * h as f32, 2.0 + rnd() * 9.0, rnd());
            for y in 0..h {
                for x in 0..w {
                    let d = ((x as f32 - cx).powi(2) + (y as f32 - cy).powi(2)).sqrt();
                    if d < r {
                        sharp[y * w + x] = v;
                    }
                }
            }
        }
        let sharp = Gray { w, h, data: sharp };
        let (c, s) = (deg.to_radians().cos(), deg.to_radians().sin());
        let mut data = vec![0.0f32; w * h];
        for y in 0..h {
            for x in 0..w {
                let mut acc = 0.0;
                for k in 0..=len {
                    let t = k as f32 - len as f32 / 2.0;
                    acc += sharp.sample(x as f32 + 0.5 + t * c, y as f32 + 0.5 + t * s);
                }
                data[y * w + x] = acc / (len + 1) as f32;
            }
        }
        Gray { w, h, data }
    }

    #[test]
    fn blur_length_is_estimated_from_the_image() {
        for (len, deg) in [(30usize, 20.0f32), (16, 100.0), (24, 155.0)] {
            let est = estimate_blur_px(&blurred_discs(len, deg));
            assert!(
                (est - len as f32).abs() <= 0.3 * len as f32,
                "blur {len} px at {deg}°: estimated {est}"
            );
        }
        // An unblurred image reads as (much) less blurred than the mildest case above.
        let sharp = estimate_blur_px(&blurred_discs(0, 0.0));
        assert!(sharp <= 12.0, "sharp image: estimated {sharp}");
    }

    /// The sharp mid-exposure frames of `gems synth` scenes whose broad striped walls and floors
    /// the zero-crossing reading alone took for 13–20 px of blur (seeds 6, 8 and 11 at 240×160,
    /// crates/gems-init/BENCHMARKS.md), at most 10 px in the median over their views now: under
    /// the SfM's 12 px for working at full size (`SfmOptions::refine_max_blur_px`).
    #[test]
    fn sharp_photos_with_broad_texture_do_not_read_as_blurred() {
        for seed in [6u64, 8, 11] {
            let cfg = gems_synth::SynthConfig {
                views: 20,
                width: 240,
                height: 160,
                seed,
                events: None,
                ..gems_synth::SynthConfig::small()
            };
            let scene = gems_synth::SynthScene::new(&cfg).expect("a valid scene");
            let mut est: Vec<f32> = (0..cfg.views)
                .step_by(2)
                .map(|v| {
                    let frame = scene.render_sharp(v, 0.5);
                    let rgb = image::RgbImage::from_raw(frame.width, frame.height, frame.to_rgb8())
                        .expect("an RGB frame");
                    estimate_blur_px(&Gray::from_rgb(&rgb))
                })
                .collect();
            est.sort_by(f32::total_cmp);
            let median = est[est.len() / 2];
            assert!(median <= 10.0, "seed {seed}: sharp frames read {est:?} px");
        }
    }
}

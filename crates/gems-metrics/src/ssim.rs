//! SSIM with an 11×11 Gaussian window (σ 1.5, K1 0.01, K2 0.03, data range 1).
//!
//! - Evaluation ([`ssim`], torchmetrics): the images are reflect-padded by 5 (torch "reflect",
//!   edge not repeated), the SSIM map is computed for every pixel and averaged over the whole
//!   image, variances clamped at zero. (Older torchmetrics cropped 5 pixels; the reference vectors
//!   in testdata/ were made without the crop, and [`ssim`] matches them.)
//! - Training ([`ssim_valid`], fused-ssim `padding="valid"`): zero padding by 5, map cropped by 5,
//!   so only windows fully inside the image count and the padding never matters.
//!
//! The gradient of the training SSIM treats S̄ = mean_p S(μx, μy, Σxx, Σyy, Σxy)(p) with
//! μx = G∗x, Σxx = G∗x², Σxy = G∗xy (and σx² = Σxx − μx², σxy = Σxy − μxμy), so
//! dS̄/dx = G∗m₁ + 2x·(G∗m₂) + y·(G∗m₃), with m₁ = ∂S/∂μx, m₂ = ∂S/∂Σxx, m₃ = ∂S/∂Σxy on the
//! kept pixels (scaled by 1/N) and zero elsewhere; G is symmetric, so its adjoint is itself with
//! zero padding.

use rayon::prelude::*;

use crate::{MetricsError, check_pair};

/// Side of the SSIM window in pixels: images smaller than this in either axis have no SSIM.
pub const SSIM_WINDOW: usize = 11;
const WIN: usize = SSIM_WINDOW;
const RAD: usize = WIN / 2;
const C1: f64 = 0.01 * 0.01;
const C2: f64 = 0.03 * 0.03;

/// The normalised 1-D Gaussian of the 11-tap window, σ = 1.5.
fn gaussian_window() -> [f64; WIN] {
    let mut g = [0.0; WIN];
    for (k, v) in g.iter_mut().enumerate() {
        let d = k as f64 - RAD as f64;
        *v = (-(d * d) / (2.0 * 1.5 * 1.5)).exp();
    }
    let s: f64 = g.iter().sum();
    g.map(|v| v / s)
}

fn check_ssim_input(
    render: &[f32],
    target: &[f32],
    height: usize,
    width: usize,
) -> Result<(), MetricsError> {
    check_pair(render, target, height, width)?;
    if height < WIN || width < WIN {
        return Err(MetricsError::TooSmall { height, width });
    }
    Ok(())
}

/// torch "reflect" padding index: −1 → 1, n → n − 2.
fn reflect(i: isize, n: usize) -> usize {
    let n = n as isize;
    let i = if i < 0 { -i } else { i };
    (if i >= n { 2 * (n - 1) - i } else { i }) as usize
}

/// Evaluation SSIM (torchmetrics `StructuralSimilarityIndexMeasure(data_range=1)` defaults:
/// reflect padding, mean over the full map), computed in f64.
pub fn ssim(
    render: &[f32],
    target: &[f32],
    height: usize,
    width: usize,
) -> Result<f64, MetricsError> {
    check_ssim_input(render, target, height, width)?;
    let g = gaussian_window();
    let cols: Vec<[usize; WIN]> = (0..width)
        .map(|c| std::array::from_fn(|k| reflect(c as isize + k as isize - RAD as isize, width)))
        .collect();
    let rows: Vec<[usize; WIN]> = (0..height)
        .map(|r| std::array::from_fn(|k| reflect(r as isize + k as isize - RAD as isize, height)))
        .collect();
    let total: f64 = (0..3)
        .into_par_iter()
        .map(|ch| {
            // Horizontal pass: [row][col][5 moments].
            let mut horiz = vec![[0.0f64; 5]; height * width];
            for r in 0..height {
                for (c, idx) in cols.iter().enumerate() {
                    let mut acc = [0.0; 5];
                    for (gk, &cc) in g.iter().zip(idx) {
                        let i = (r * width + cc) * 3 + ch;
                        let (x, y) = (f64::from(render[i]), f64::from(target[i]));
                        acc[0] += gk * x;
                        acc[1] += gk * y;
                        acc[2] += gk * x * x;
                        acc[3] += gk * y * y;
                        acc[4] += gk * x * y;
                    }
                    horiz[r * width + c] = acc;
                }
            }
            let mut sum = 0.0;
            for idx in &rows {
                for c in 0..width {
                    let mut m = [0.0; 5];
                    for (gk, &rr) in g.iter().zip(idx) {
                        for (mv, hv) in m.iter_mut().zip(&horiz[rr * width + c]) {
                            *mv += gk * hv;
                        }
                    }
                    let (mx, my) = (m[0], m[1]);
                    let sxx = (m[2] - mx * mx).max(0.0);
                    let syy = (m[3] - my * my).max(0.0);
                    let sxy = m[4] - mx * my;
                    sum += ((2.0 * mx * my + C1) * (2.0 * sxy + C2))
                        / ((mx * mx + my * my + C1) * (sxx + syy + C2));
                }
            }
            sum
        })
        .collect::<Vec<f64>>()
        .iter()
        .sum();
    Ok(total / (3 * height * width) as f64)
}

/// Per-channel scratch buffers of the f32 SSIM forward/backward. Every pass runs over whole
/// contiguous rows (taps in the outer loop, pixels in the inner one) so that it vectorises.
#[derive(Default)]
struct ChannelScratch {
    x: Vec<f32>,
    y: Vec<f32>,
    /// Horizontal pass, [row][moment (5)][kept col].
    horiz: Vec<f32>,
    /// Vertical pass, [kept row][moment (5)][kept col].
    vert: Vec<f32>,
    /// ∂S/∂(μx, Σxx, Σxy) on kept pixels (scaled by 1/N), [kept row][3][kept col].
    dmap: Vec<f32>,
    row_ssim: Vec<f64>,
    /// Vertical adjoint pass, [row][3][kept col].
    back: Vec<f32>,
    /// Horizontal adjoint pass, [row][3][col].
    backh: Vec<f32>,
    /// dS̄/dx for this channel, planar [row][col].
    grad: Vec<f32>,
}

/// Reusable workspace for SSIM-valid with gradient at a fixed image size.
struct SsimWorkspace {
    height: usize,
    width: usize,
    g: [f32; WIN],
    chans: [ChannelScratch; 3],
}

impl SsimWorkspace {
    fn new(height: usize, width: usize) -> Self {
        let (hi, wi) = (height - 2 * RAD, width - 2 * RAD);
        let g = gaussian_window().map(|v| v as f32);
        let chans = std::array::from_fn(|_| ChannelScratch {
            x: vec![0.0; height * width],
            y: vec![0.0; height * width],
            horiz: vec![0.0; height * 5 * wi],
            vert: vec![0.0; hi * 5 * wi],
            dmap: vec![0.0; hi * 3 * wi],
            row_ssim: vec![0.0; hi],
            back: vec![0.0; height * 3 * wi],
            backh: vec![0.0; height * 3 * width],
            grad: vec![0.0; height * width],
        });
        SsimWorkspace {
            height,
            width,
            g,
            chans,
        }
    }

    /// Mean SSIM over kept pixels of all channels; fills each channel's `grad` with dS̄/d(render).
    fn run(&mut self, render: &[f32], target: &[f32]) -> f64 {
        let (h, w) = (self.height, self.width);
        let (hi, wi) = (h - 2 * RAD, w - 2 * RAD);
        let scale = 1.0 / (3 * hi * wi) as f32;
        let g = self.g;
        let (c1, c2) = (C1 as f32, C2 as f32);
        let mut total = 0.0;
        for (ch, s) in self.chans.iter_mut().enumerate() {
            s.x.par_chunks_mut(w)
                .zip(s.y.par_chunks_mut(w))
                .enumerate()
                .for_each(|(r, (xr, yr))| {
                    for c in 0..w {
                        let i = (r * w + c) * 3 + ch;
                        xr[c] = render[i];
                        yr[c] = target[i];
                    }
                });
            let (x, y) = (&s.x, &s.y);
            s.horiz
                .par_chunks_mut(5 * wi)
                .enumerate()
                .for_each(|(r, out)| {
                    out.fill(0.0);
                    let (o0, rest) = out.split_at_mut(wi);
                    let (o1, rest) = rest.split_at_mut(wi);
                    let (o2, rest) = rest.split_at_mut(wi);
                    let (o3, o4) = rest.split_at_mut(wi);
                    let (xs, ys) = (&x[r * w..(r + 1) * w], &y[r * w..(r + 1) * w]);
                    for (k, &gk) in g.iter().enumerate() {
                        let (xk, yk) = (&xs[k..k + wi], &ys[k..k + wi]);
                        for c in 0..wi {
                            let (xv, yv) = (xk[c], yk[c]);
                            let (gx, gy) = (gk * xv, gk * yv);
                            o0[c] += gx;
                            o1[c] += gy;
                            o2[c] += gx * xv;
                            o3[c] += gy * yv;
                            o4[c] += gx * yv;
                        }
                    }
                });
            let horiz = &s.horiz;
            s.vert
                .par_chunks_mut(5 * wi)
                .enumerate()
                .for_each(|(r, out)| {
                    out.fill(0.0);
                    for (k, &gk) in g.iter().enumerate() {
                        let src = &horiz[(r + k) * 5 * wi..(r + k + 1) * 5 * wi];
                        for (o, v) in out.iter_mut().zip(src) {
                            *o += gk * v;
                        }
                    }
                });
            let vert = &s.vert;
            s.dmap
                .par_chunks_mut(3 * wi)
                .zip(s.row_ssim.par_iter_mut())
                .enumerate()
                .for_each(|(r, (out, row_sum))| {
                    let m = &vert[r * 5 * wi..(r + 1) * 5 * wi];
                    let (mxs, rest) = m.split_at(wi);
                    let (mys, rest) = rest.split_at(wi);
                    let (sxxs, rest) = rest.split_at(wi);
                    let (syys, sxys) = rest.split_at(wi);
                    let (d0, rest) = out.split_at_mut(wi);
                    let (d1, d2) = rest.split_at_mut(wi);
                    let mut sum = 0.0f64;
                    for c in 0..wi {
                        let (mx, my) = (mxs[c], mys[c]);
                        let a = 2.0 * mx * my + c1;
                        let b = 2.0 * (sxys[c] - mx * my) + c2;
                        let cc = mx * mx + my * my + c1;
                        let d = (sxxs[c] - mx * mx) + (syys[c] - my * my) + c2;
                        let cd = cc * d;
                        let ssim = a * b / cd;
                        sum += f64::from(ssim);
                        d0[c] = scale
                            * (2.0 * my * (b - a) / cd - 2.0 * mx * ssim * (1.0 / cc - 1.0 / d));
                        d1[c] = scale * (-ssim / d);
                        d2[c] = scale * (2.0 * a / cd);
                    }
                    *row_sum = sum;
                });
            total += s.row_ssim.iter().sum::<f64>();
            let dmap = &s.dmap;
            s.back
                .par_chunks_mut(3 * wi)
                .enumerate()
                .for_each(|(q, out)| {
                    out.fill(0.0);
                    // Kept row p (full row p + RAD) saw input row q with tap k = q − p.
                    let p_lo = q.saturating_sub(WIN - 1);
                    let p_hi = q.min(hi - 1);
                    for p in p_lo..=p_hi {
                        let gk = g[q - p];
                        let src = &dmap[p * 3 * wi..(p + 1) * 3 * wi];
                        for (o, v) in out.iter_mut().zip(src) {
                            *o += gk * v;
                        }
                    }
                });
            let back = &s.back;
            s.backh
                .par_chunks_mut(3 * w)
                .zip(s.grad.par_chunks_mut(w))
                .enumerate()
                .for_each(|(q, (acc, out))| {
                    acc.fill(0.0);
                    // Kept column c' saw input column c' + k with tap k.
                    for m in 0..3 {
                        let src = &back[(q * 3 + m) * wi..(q * 3 + m + 1) * wi];
                        let dst = &mut acc[m * w..(m + 1) * w];
                        for (k, &gk) in g.iter().enumerate() {
                            for (o, v) in dst[k..k + wi].iter_mut().zip(src) {
                                *o += gk * v;
                            }
                        }
                    }
                    let (a0, rest) = acc.split_at(w);
                    let (a1, a2) = rest.split_at(w);
                    let (xs, ys) = (&x[q * w..(q + 1) * w], &y[q * w..(q + 1) * w]);
                    for c in 0..w {
                        out[c] = a0[c] + 2.0 * xs[c] * a1[c] + ys[c] * a2[c];
                    }
                });
        }
        total / (3 * hi * wi) as f64
    }
}

/// Training-loss SSIM (fused-ssim `padding="valid"`) of `render` against `target`.
pub fn ssim_valid(
    render: &[f32],
    target: &[f32],
    height: usize,
    width: usize,
) -> Result<f32, MetricsError> {
    let mut grad = vec![0.0; render.len()];
    ssim_valid_with_grad(render, target, height, width, &mut grad)
}

/// [`ssim_valid`] and its gradient w.r.t. `render`, written to `grad` ([H, W, 3]).
pub fn ssim_valid_with_grad(
    render: &[f32],
    target: &[f32],
    height: usize,
    width: usize,
    grad: &mut [f32],
) -> Result<f32, MetricsError> {
    check_ssim_input(render, target, height, width)?;
    check_pair(grad, render, height, width)?;
    let mut ws = SsimWorkspace::new(height, width);
    let value = ws.run(render, target);
    interleave(&ws, width, |_, _, s| s, grad);
    Ok(value as f32)
}

/// Writes `f(render_index, value_index, ssim_grad)` into the interleaved output, row-parallel.
fn interleave(
    ws: &SsimWorkspace,
    width: usize,
    f: impl Fn(usize, usize, f32) -> f32 + Sync,
    out: &mut [f32],
) {
    out.par_chunks_mut(width * 3)
        .enumerate()
        .for_each(|(r, row)| {
            for c in 0..width {
                for ch in 0..3 {
                    let i = r * width * 3 + c * 3 + ch;
                    row[c * 3 + ch] = f(i, ch, ws.chans[ch].grad[r * width + c]);
                }
            }
        });
}

/// Value of the fused training loss and its parts.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LossValue {
    /// (1−λ)·L1 + λ·(1 − SSIM).
    pub loss: f32,
    /// Mean absolute error over all pixels and channels.
    pub l1: f32,
    /// SSIM-valid.
    pub ssim: f32,
}

/// The photometric training loss `(1−λ)·L1 + λ·(1 − SSIM_valid)` and dL/d(render), with its
/// buffers kept between calls for one image size.
pub struct TrainingLoss {
    lambda: f32,
    ws: SsimWorkspace,
}

impl TrainingLoss {
    /// Workspace for `height`×`width` images; `lambda` is the SSIM weight (GeMS: 0.3).
    pub fn new(height: usize, width: usize, lambda: f32) -> Result<Self, MetricsError> {
        if height < WIN || width < WIN {
            return Err(MetricsError::TooSmall { height, width });
        }
        Ok(TrainingLoss {
            lambda,
            ws: SsimWorkspace::new(height, width),
        })
    }

    pub fn lambda(&self) -> f32 {
        self.lambda
    }

    /// Loss of `render` against `target`; writes dL/d(render) into `grad` (all [H, W, 3]).
    pub fn compute(
        &mut self,
        render: &[f32],
        target: &[f32],
        grad: &mut [f32],
    ) -> Result<LossValue, MetricsError> {
        let (h, w) = (self.ws.height, self.ws.width);
        check_pair(render, target, h, w)?;
        check_pair(grad, render, h, w)?;
        let ssim = self.ws.run(render, target) as f32;
        let n = render.len();
        let l1 = render
            .par_chunks(w * 3)
            .zip(target.par_chunks(w * 3))
            .map(|(r, t)| {
                r.iter()
                    .zip(t)
                    .map(|(a, b)| f64::from((a - b).abs()))
                    .sum::<f64>()
            })
            .collect::<Vec<f64>>()
            .iter()
            .sum::<f64>()
            / n as f64;
        let (lam, inv_n) = (self.lambda, 1.0 / n as f32);
        interleave(
            &self.ws,
            w,
            |i, _, gs| {
                let d = render[i] - target[i];
                // torch.sign(0) = 0: no L1 push when already equal.
                let sign = if d > 0.0 {
                    1.0
                } else if d < 0.0 {
                    -1.0
                } else {
                    0.0
                };
                (1.0 - lam) * sign * inv_n - lam * gs
            },
            grad,
        );
        let l1 = l1 as f32;
        Ok(LossValue {
            loss: (1.0 - lam) * l1 + lam * (1.0 - ssim),
            l1,
            ssim,
        })
    }
}

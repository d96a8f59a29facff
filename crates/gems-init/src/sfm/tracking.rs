//! Guided patch tracking between overlapping views (the "KLT-style" half of the matcher).
//!
//! Descriptor matching needs the *same* keypoint to be detected in both images, which motion
//! blur along different directions makes unlikely. Tracking does not: every keypoint of a root
//! view is searched for by normalised cross-correlation of a large smoothed patch inside a window
//! around the position predicted by the global shift between the two views, refined to sub-pixel
//! by a parabola fit, and kept only if the search from the found position back into the root
//! view returns to the start (forward–backward check) and the correlation peak is unique.
//!
//! Overlapping views are found from the images, not from their order: tiny thumbnails of every
//! pair are correlated over all shifts, and each view tracks into its best-correlated neighbours.

use super::features::Gray;
use nalgebra::Matrix2;
use rayon::prelude::*;

/// Settings, in working-level pixels.
#[derive(Clone, Debug)]
pub(crate) struct TrackParams {
    /// Patch half-size (patch side 2·half+1).
    pub half: i32,
    /// Search radius around the predicted position.
    pub radius: i32,
    /// Neighbours each root view tracks into.
    pub neighbours: usize,
    pub min_ncc: f32,
    /// Required gap between the best peak and the best score ≥ 3 px away.
    pub min_margin: f32,
    /// Forward–backward tolerance.
    pub fb_tol: f32,
    /// Refine each match with an affine map of the window (the template's predicted
    /// warp corrected), not by translation alone.
    pub affine: bool,
}

/// Overlap score and global shift (working-level px, dst − src) of an ordered view pair.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Overlap {
    pub score: f32,
    pub shift: [f32; 2],
}

const THUMB: usize = 48;

/// Thumbnail correlation of every ordered pair: `out[i][j]`. Shifts are scaled to `work_w`.
pub(crate) fn overlaps(grays: &[Gray], work_w: usize) -> Vec<Vec<Overlap>> {
    let thumbs: Vec<Gray> = grays
        .par_iter()
        .map(|g| {
            let s = THUMB as f32 / g.w as f32;
            g.resized(s).gaussian(1.0)
        })
        .collect();
    let n = thumbs.len();
    let scale = work_w as f32 / thumbs[0].w as f32;
    (0..n)
        .into_par_iter()
        .map(|i| {
            (0..n)
                .map(|j| {
                    if i == j {
                        return Overlap {
                            score: -1.0,
                            shift: [0.0, 0.0],
                        };
                    }
                    let (score, dx, dy) = best_shift(&thumbs[i], &thumbs[j]);
                    Overlap {
                        score,
                        shift: [dx as f32 * scale, dy as f32 * scale],
                    }
                })
                .collect()
        })
        .collect()
}

/// Integer shift (dx, dy) maximising the NCC of a(x) against b(x + d) over the overlap, with at
/// least half of the thumbnail overlapping.
fn best_shift(a: &Gray, b: &Gray) -> (f32, i32, i32) {
    let (w, h) = (a.w as i32, a.h as i32);
    let (rx, ry) = (w / 2, h / 2);
    let mut best = (-1.0f32, 0, 0);
    for dy in -ry..=ry {
        for dx in -rx..=rx {
            let x0 = 0.max(-dx);
            let x1 = w.min(w - dx);
            let y0 = 0.max(-dy);
            let y1 = h.min(h - dy);
            if (x1 - x0) * (y1 - y0) * 2 < w * h {
                continue;
            }
            let (mut sa, mut sb, mut saa, mut sbb, mut sab) =
                (0.0f32, 0.0f32, 0.0f32, 0.0f32, 0.0f32);
            for y in y0..y1 {
                let ra = &a.data[(y * w) as usize..((y + 1) * w) as usize];
                let rb = &b.data[((y + dy) * w) as usize..((y + dy + 1) * w) as usize];
                for x in x0..x1 {
                    let (p, q) = (ra[x as usize], rb[(x + dx) as usize]);
                    sa += p;
                    sb += q;
                    saa += p * p;
                    sbb += q * q;
                    sab += p * q;
                }
            }
            let n = ((x1 - x0) * (y1 - y0)) as f32;
            let cov = sab - sa * sb / n;
            let va = saa - sa * sa / n;
            let vb = sbb - sb * sb / n;
            if va <= 1e-9 || vb <= 1e-9 {
                continue;
            }
            let ncc = cov / (va * vb).sqrt();
            if ncc > best.0 {
                best = (ncc, dx, dy);
            }
        }
    }
    best
}

/// A local affine map between two views' pixel offsets around corresponding points: offset d in
/// one view ↦ `m·d` in the other (the identity when the two views see the patch alike).
pub(crate) type Warp = Matrix2<f32>;

/// The inverse of `m`, or `None` when it is (nearly) singular or flips orientation.
fn invert(m: &Warp) -> Option<Warp> {
    (m.determinant() > 1e-3).then(|| m.try_inverse()).flatten()
}

/// Normalised template of `src` around the sub-pixel point `p`, sampled at `p + m·d` for the
/// patch's integer offsets d (so it looks as the patch does in a view where `m` maps that view's
/// offsets into `src`'s); false when flat.
fn template(src: &Gray, p: [f32; 2], m: &Warp, half: i32, out: &mut Vec<f32>) -> bool {
    out.clear();
    for dy in -half..=half {
        for dx in -half..=half {
            let (dx, dy) = (dx as f32, dy as f32);
            out.push(src.sample(
                p[0] + m[(0, 0)] * dx + m[(0, 1)] * dy,
                p[1] + m[(1, 0)] * dx + m[(1, 1)] * dy,
            ));
        }
    }
    normalise(out)
}

/// Mean and 1/‖win − mean‖ of a sampled window (what the Gauss–Newton steps compare with a
/// normalised template), or `None` for a flat window.
fn mean_and_inverse_norm(win: &[f32]) -> Option<(f32, f32)> {
    let mean = win.iter().sum::<f32>() / win.len() as f32;
    let norm = win
        .iter()
        .map(|v| (v - mean) * (v - mean))
        .sum::<f32>()
        .sqrt();
    if norm < 1e-6 {
        return None;
    }
    Some((mean, 1.0 / norm))
}

fn normalise(v: &mut [f32]) -> bool {
    let mean = v.iter().sum::<f32>() / v.len() as f32;
    let mut n = 0.0;
    for x in v.iter_mut() {
        *x -= mean;
        n += *x * *x;
    }
    if n < 1e-8 {
        return false;
    }
    let inv = 1.0 / n.sqrt();
    for x in v.iter_mut() {
        *x *= inv;
    }
    true
}

/// Reusable buffers of one search (no allocation per tracked point).
#[derive(Default)]
pub(crate) struct Scratch {
    tmpl: Vec<f32>,
    scores: Vec<f32>,
}

/// A view prepared for tracking: the smoothed image and integral images of I and I² (f64, so
/// window sums stay exact enough), which make each candidate window's norm O(1).
pub(crate) struct Prepared {
    pub img: Gray,
    sum: Vec<f64>,
    sum2: Vec<f64>,
}

impl Prepared {
    pub fn new(img: Gray) -> Prepared {
        let (w, h) = (img.w, img.h);
        let mut sum = vec![0.0f64; (w + 1) * (h + 1)];
        let mut sum2 = vec![0.0f64; (w + 1) * (h + 1)];
        for y in 0..h {
            let (mut rs, mut rs2) = (0.0f64, 0.0f64);
            for x in 0..w {
                let v = img.data[y * w + x] as f64;
                rs += v;
                rs2 += v * v;
                sum[(y + 1) * (w + 1) + x + 1] = sum[y * (w + 1) + x + 1] + rs;
                sum2[(y + 1) * (w + 1) + x + 1] = sum2[y * (w + 1) + x + 1] + rs2;
            }
        }
        Prepared { img, sum, sum2 }
    }

    /// Sum and sum of squares over the inclusive pixel box [x0, x1] × [y0, y1].
    #[inline]
    fn box_sums(&self, x0: usize, y0: usize, x1: usize, y1: usize) -> (f64, f64) {
        let w1 = self.img.w + 1;
        let at = |t: &[f64], x: usize, y: usize| t[y * w1 + x];
        let s =
            at(&self.sum, x1 + 1, y1 + 1) - at(&self.sum, x0, y1 + 1) - at(&self.sum, x1 + 1, y0)
                + at(&self.sum, x0, y0);
        let s2 = at(&self.sum2, x1 + 1, y1 + 1)
            - at(&self.sum2, x0, y1 + 1)
            - at(&self.sum2, x1 + 1, y0)
            + at(&self.sum2, x0, y0);
        (s, s2)
    }
}

/// Search `s.tmpl` (zero-mean, unit norm, side 2·half+1) in `dst` at integer pixels within
/// `radius` of `centre`. Because the template has zero mean, Σ T·W equals Σ T·(W − mean W), so
/// the NCC is that dot product over the window's centred norm from the integral images.
/// Returns the sub-pixel position and peak score when the peak is strong and unique.
fn search(
    dst: &Prepared,
    centre: [f32; 2],
    p: &TrackParams,
    radius: i32,
    s: &mut Scratch,
) -> Option<([f32; 2], f32)> {
    let half = p.half;
    let side = 2 * radius + 1;
    let cx = (centre[0] - 0.5).round() as i32;
    let cy = (centre[1] - 0.5).round() as i32;
    s.scores.clear();
    s.scores.resize((side * side) as usize, f32::NAN);
    let (w, h) = (dst.img.w as i32, dst.img.h as i32);
    let npx = ((2 * half + 1) * (2 * half + 1)) as f64;
    let tside = (2 * half + 1) as usize;
    let score = |ox: i32, oy: i32| -> f32 {
        let (qx, qy) = (cx + ox, cy + oy);
        if qx - half < 0 || qy - half < 0 || qx + half >= w || qy + half >= h {
            return f32::NEG_INFINITY;
        }
        let (sm, sm2) = dst.box_sums(
            (qx - half) as usize,
            (qy - half) as usize,
            (qx + half) as usize,
            (qy + half) as usize,
        );
        let var = sm2 - sm * sm / npx;
        if var < 1e-8 {
            return f32::NEG_INFINITY;
        }
        let mut dot = 0.0f32;
        for (dy, trow) in (-half..=half).zip(s.tmpl.chunks_exact(tside)) {
            let row = ((qy + dy) * w) as usize;
            let wrow = &dst.img.data[row + (qx - half) as usize..=row + (qx + half) as usize];
            dot += wrow.iter().zip(trow).map(|(a, b)| a * b).sum::<f32>();
        }
        dot / var.sqrt() as f32
    };
    // Coarse-to-fine: the smoothed NCC surface is sampled on every other offset, then the best
    // sample is hill-climbed on the full grid (a quarter of the work of an exhaustive search).
    let idx = |ox: i32, oy: i32| ((oy + radius) * side + ox + radius) as usize;
    let mut best = (f32::NEG_INFINITY, 0i32, 0i32);
    for oy in (-radius..=radius).step_by(2) {
        for ox in (-radius..=radius).step_by(2) {
            let v = score(ox, oy);
            s.scores[idx(ox, oy)] = v;
            if v > best.0 {
                best = (v, ox, oy);
            }
        }
    }
    loop {
        let mut moved = best;
        for dy in -1..=1 {
            for dx in -1..=1 {
                let (ox, oy) = (best.1 + dx, best.2 + dy);
                if ox.abs() > radius || oy.abs() > radius {
                    continue;
                }
                let k = idx(ox, oy);
                if s.scores[k].is_nan() {
                    s.scores[k] = score(ox, oy);
                }
                if s.scores[k] > moved.0 {
                    moved = (s.scores[k], ox, oy);
                }
            }
        }
        if (moved.1, moved.2) == (best.1, best.2) {
            break;
        }
        best = moved;
    }
    if best.0 < p.min_ncc || best.1.abs() == radius || best.2.abs() == radius {
        return None;
    }
    let mut second = f32::NEG_INFINITY;
    for oy in -radius..=radius {
        for ox in -radius..=radius {
            if (ox - best.1).abs() <= 2 && (oy - best.2).abs() <= 2 {
                continue;
            }
            // Offsets never evaluated are NaN and never win.
            let v = s.scores[((oy + radius) * side + ox + radius) as usize];
            if v > second {
                second = v;
            }
        }
    }
    if best.0 - second < p.min_margin {
        return None;
    }
    let start = [(cx + best.1) as f32 + 0.5, (cy + best.2) as f32 + 0.5];
    let q = if p.affine {
        refine_lk_affine(&dst.img, start, half, &s.tmpl)?
    } else {
        refine_lk(&dst.img, start, half, &s.tmpl)?
    };
    Some((q, best.0))
}

/// Sub-pixel refinement of the integer NCC peak by Gauss–Newton (Lucas–Kanade) on the
/// zero-mean, gain-normalised window: minimises ‖T − Ŵ(q)‖² with Ŵ the centred, unit-norm window
/// sampled bilinearly at q. Rejects steps that leave the ±1.5 px neighbourhood of the peak.
fn refine_lk(img: &Gray, start: [f32; 2], half: i32, tmpl: &[f32]) -> Option<[f32; 2]> {
    let mut q = start;
    let n = tmpl.len();
    let mut win = [0.0f32; 441];
    let mut gx = [0.0f32; 441];
    let mut gy = [0.0f32; 441];
    if n > win.len() {
        return Some(q);
    }
    for _ in 0..6 {
        let mut k = 0;
        for dy in -half..=half {
            for dx in -half..=half {
                let (x, y) = (q[0] + dx as f32, q[1] + dy as f32);
                win[k] = img.sample(x, y);
                gx[k] = 0.5 * (img.sample(x + 1.0, y) - img.sample(x - 1.0, y));
                gy[k] = 0.5 * (img.sample(x, y + 1.0) - img.sample(x, y - 1.0));
                k += 1;
            }
        }
        let (mean, inv) = mean_and_inverse_norm(&win[..n])?;
        let (mgx, mgy) = (
            gx[..n].iter().sum::<f32>() / n as f32,
            gy[..n].iter().sum::<f32>() / n as f32,
        );
        let (mut a11, mut a12, mut a22, mut b1, mut b2) = (0.0f32, 0.0f32, 0.0f32, 0.0f32, 0.0f32);
        for i in 0..n {
            let r = (win[i] - mean) * inv - tmpl[i];
            let (jx, jy) = ((gx[i] - mgx) * inv, (gy[i] - mgy) * inv);
            a11 += jx * jx;
            a12 += jx * jy;
            a22 += jy * jy;
            b1 += jx * r;
            b2 += jy * r;
        }
        let det = a11 * a22 - a12 * a12;
        if det.abs() < 1e-12 {
            return None;
        }
        let dx = -(a22 * b1 - a12 * b2) / det;
        let dy = -(a11 * b2 - a12 * b1) / det;
        q[0] += dx.clamp(-0.5, 0.5);
        q[1] += dy.clamp(-0.5, 0.5);
        if (q[0] - start[0]).abs() > 1.5 || (q[1] - start[1]).abs() > 1.5 {
            return None;
        }
        if dx.abs() < 0.01 && dy.abs() < 0.01 {
            break;
        }
    }
    Some(q)
}

/// As [`refine_lk`], with the window sampled at q + (I + B)·d: B (four entries, damped toward 0)
/// corrects the foreshortening that the template's predicted warp got wrong (a surface not
/// facing the two views' bisector), which would otherwise shift the translation's optimum.
fn refine_lk_affine(img: &Gray, start: [f32; 2], half: i32, tmpl: &[f32]) -> Option<[f32; 2]> {
    use nalgebra::{Matrix6, Vector6};
    let mut q = start;
    let mut b = [0.0f32; 4];
    let n = tmpl.len();
    if n > 441 {
        return Some(q);
    }
    let mut win = [0.0f32; 441];
    let mut jac = [[0.0f32; 6]; 441];
    for _ in 0..10 {
        let mut k = 0;
        for dy in -half..=half {
            for dx in -half..=half {
                let (dx, dy) = (dx as f32, dy as f32);
                let x = q[0] + dx + b[0] * dx + b[1] * dy;
                let y = q[1] + dy + b[2] * dx + b[3] * dy;
                win[k] = img.sample(x, y);
                let gx = 0.5 * (img.sample(x + 1.0, y) - img.sample(x - 1.0, y));
                let gy = 0.5 * (img.sample(x, y + 1.0) - img.sample(x, y - 1.0));
                jac[k] = [gx, gy, gx * dx, gx * dy, gy * dx, gy * dy];
                k += 1;
            }
        }
        let (mean, inv) = mean_and_inverse_norm(&win[..n])?;
        let mut jmean = [0.0f32; 6];
        for j in &jac[..n] {
            for c in 0..6 {
                jmean[c] += j[c] / n as f32;
            }
        }
        let mut a = Matrix6::<f64>::zeros();
        let mut g = Vector6::<f64>::zeros();
        for i in 0..n {
            let r = f64::from((win[i] - mean) * inv - tmpl[i]);
            let jc: [f64; 6] = std::array::from_fn(|c| f64::from((jac[i][c] - jmean[c]) * inv));
            for c in 0..6 {
                g[c] += jc[c] * r;
                for e in 0..6 {
                    a[(c, e)] += jc[c] * jc[e];
                }
            }
        }
        // Damping of the affine part, relative to the translation's curvature, and a pull of B
        // toward 0: a smooth or smeared window barely constrains it.
        let damp = 0.1 * (a[(0, 0)] + a[(1, 1)]) / (f64::from(half * half).max(1.0));
        for c in 2..6 {
            a[(c, c)] += damp;
            g[c] += damp * f64::from(b[c - 2]);
        }
        let step = a.lu().solve(&(-g))?;
        let (sx, sy) = (step[0] as f32, step[1] as f32);
        q[0] += sx.clamp(-0.5, 0.5);
        q[1] += sy.clamp(-0.5, 0.5);
        for c in 0..4 {
            b[c] = (b[c] + step[c + 2] as f32).clamp(-0.3, 0.3);
        }
        if (q[0] - start[0]).abs() > 1.5 || (q[1] - start[1]).abs() > 1.5 {
            return None;
        }
        if sx.abs() < 0.01 && sy.abs() < 0.01 {
            break;
        }
    }
    Some(q)
}

/// Dense query points for tracking: the centres of a grid with `spacing` px whose tracking patch
/// (side 2·half+1) is well conditioned — the smaller eigenvalue of the gradient structure tensor
/// summed over the patch is at least `min_rel` of the 90th percentile over the grid and at least
/// `min_isotropy` of the larger one (a patch smeared along the blur direction is matched with a
/// bias along it, which bends the reconstructed camera path) — and that
/// lie at least `spacing`/2 from every point of `existing`; at most `max_points`, the best
/// conditioned. Corners are rare under heavy blur, but a large patch of a blurred image is
/// usually still trackable in two directions.
pub(crate) fn grid_points(
    img: &Gray,
    half: i32,
    spacing: usize,
    min_rel: f32,
    min_isotropy: f32,
    existing: &[[f32; 2]],
    max_points: usize,
) -> Vec<[f32; 2]> {
    let (w, h) = (img.w, img.h);
    let hs = half as usize + 1;
    if w <= 2 * hs + 2 || h <= 2 * hs + 2 || spacing == 0 {
        return Vec::new();
    }
    // Integral images of gx², gy², gx·gy (central differences, zero at the border).
    let w1 = w + 1;
    let mut ixx = vec![0.0f64; w1 * (h + 1)];
    let mut iyy = vec![0.0f64; w1 * (h + 1)];
    let mut ixy = vec![0.0f64; w1 * (h + 1)];
    for y in 0..h {
        let (mut rxx, mut ryy, mut rxy) = (0.0f64, 0.0f64, 0.0f64);
        for x in 0..w {
            let (gx, gy) = if x > 0 && x + 1 < w && y > 0 && y + 1 < h {
                (
                    0.5 * (img.data[y * w + x + 1] - img.data[y * w + x - 1]) as f64,
                    0.5 * (img.data[(y + 1) * w + x] - img.data[(y - 1) * w + x]) as f64,
                )
            } else {
                (0.0, 0.0)
            };
            rxx += gx * gx;
            ryy += gy * gy;
            rxy += gx * gy;
            let i = (y + 1) * w1 + x + 1;
            ixx[i] = ixx[y * w1 + x + 1] + rxx;
            iyy[i] = iyy[y * w1 + x + 1] + ryy;
            ixy[i] = ixy[y * w1 + x + 1] + rxy;
        }
    }
    let boxed = |t: &[f64], x0: usize, y0: usize, x1: usize, y1: usize| {
        t[(y1 + 1) * w1 + x1 + 1] - t[y0 * w1 + x1 + 1] - t[(y1 + 1) * w1 + x0] + t[y0 * w1 + x0]
    };
    let hu = half as usize;
    let mut cands: Vec<([f32; 2], f64)> = Vec::new();
    let mut y = hs + spacing / 2;
    while y + hs < h {
        let mut x = hs + spacing / 2;
        while x + hs < w {
            let (x0, y0, x1, y1) = (x - hu, y - hu, x + hu, y + hu);
            let a = boxed(&ixx, x0, y0, x1, y1);
            let c = boxed(&iyy, x0, y0, x1, y1);
            let b = boxed(&ixy, x0, y0, x1, y1);
            let disc = (0.25 * (a - c) * (a - c) + b * b).sqrt();
            let lmin = 0.5 * (a + c) - disc;
            let lmax = 0.5 * (a + c) + disc;
            if lmin >= min_isotropy as f64 * lmax {
                cands.push(([x as f32 + 0.5, y as f32 + 0.5], lmin));
            }
            x += spacing;
        }
        y += spacing;
    }
    if cands.is_empty() {
        return Vec::new();
    }
    let mut sorted: Vec<f64> = cands.iter().map(|c| c.1).collect();
    sorted.sort_by(|a, b| a.total_cmp(b));
    let p90 = sorted[(sorted.len() * 9 / 10).min(sorted.len() - 1)];
    if p90 <= 1e-12 {
        return Vec::new();
    }
    let min_d2 = (spacing as f32 * 0.5).powi(2);
    let mut kept: Vec<([f32; 2], f64)> = cands
        .into_iter()
        .filter(|(p, l)| {
            *l >= min_rel as f64 * p90
                && existing
                    .iter()
                    .all(|q| (p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) >= min_d2)
        })
        .collect();
    if kept.len() > max_points {
        // Strongest first; the sort is stable, so equal scores keep their raster order.
        kept.sort_by(|a, b| b.1.total_cmp(&a.1));
        kept.truncate(max_points);
    }
    kept.into_iter().map(|(p, _)| p).collect()
}

/// Track `pts` of `src` into `dst` (predicted at pts + shift). Returns, per point, the position
/// in `dst` when forward–backward consistent.
pub(crate) fn track_points(
    src: &Prepared,
    dst: &Prepared,
    pts: &[[f32; 2]],
    shift: [f32; 2],
    p: &TrackParams,
) -> Vec<Option<[f32; 2]>> {
    pts.par_iter()
        .map_init(Scratch::default, |s, &pt| {
            let predicted = [pt[0] + shift[0], pt[1] + shift[1]];
            track_point(src, dst, pt, predicted, &Warp::identity(), p, s)
        })
        .collect()
}

/// Track the point `pt` of `src` into `dst`, searching within `p.radius` of `predicted`. Returns
/// its position in `dst` when the track back from there lands within `p.fb_tol` of `pt`.
///
/// `warp` maps pixel offsets around `pt` in `src` to offsets in `dst` (the local affine map of the
/// surface between the two views, when a model predicts it; the identity otherwise). Each
/// template is resampled through it, so a patch seen obliquely, rotated or at another scale in
/// the other view is compared in that view's geometry: a translation-only match of a foreshortened
/// patch is biased, and across a wide baseline that bias is systematic.
pub(crate) fn track_point(
    src: &Prepared,
    dst: &Prepared,
    pt: [f32; 2],
    predicted: [f32; 2],
    warp: &Warp,
    p: &TrackParams,
    s: &mut Scratch,
) -> Option<[f32; 2]> {
    let inverse = invert(warp)?;
    if !template(&src.img, pt, &inverse, p.half, &mut s.tmpl) {
        return None;
    }
    let (q, _) = search(dst, predicted, p, p.radius, s)?;
    if !template(&dst.img, q, warp, p.half, &mut s.tmpl) {
        return None;
    }
    let back_r = (p.fb_tol.ceil() as i32 + 2).max(3);
    let (b, _) = search(src, pt, p, back_r, s)?;
    let err = ((b[0] - pt[0]).powi(2) + (b[1] - pt[1]).powi(2)).sqrt();
    (err <= p.fb_tol).then_some(q)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector2;

    fn pattern(w: usize, h: usize, sx: f32, sy: f32) -> Gray {
        let mut data = vec![0.0; w * h];
        for y in 0..h {
            for x in 0..w {
                let (u, v) = (x as f32 + 0.5 - sx, y as f32 + 0.5 - sy);
                data[y * w + x] = (0.21 * u).sin() * (0.17 * v).cos()
                    + 0.5 * (0.05 * u + 0.11 * v).sin()
                    + (0.013 * u * v).sin() * 0.3;
            }
        }
        Gray { w, h, data }
    }

    #[test]
    fn tracks_a_subpixel_shift() {
        let a = Prepared::new(pattern(96, 80, 0.0, 0.0).gaussian(1.0));
        let b = Prepared::new(pattern(96, 80, 4.3, -2.6).gaussian(1.0));
        let p = TrackParams {
            half: 6,
            radius: 8,
            neighbours: 1,
            min_ncc: 0.8,
            min_margin: 0.0,
            fb_tol: 1.0,
            affine: false,
        };
        let pts = [[30.5, 30.5], [50.2, 40.7], [60.0, 25.0]];
        let out = track_points(&a, &b, &pts, [3.0, -2.0], &p);
        for (pt, q) in pts.iter().zip(out) {
            let q = q.expect("tracked");
            assert!(
                (q[0] - pt[0] - 4.3).abs() < 0.05 && (q[1] - pt[1] + 2.6).abs() < 0.05,
                "{pt:?} → {q:?}"
            );
        }
    }

    #[test]
    fn invert_undoes_a_warp_and_refuses_a_flip() {
        let m = Warp::new(0.8, 0.3, -0.2, 1.4);
        let inv = invert(&m).expect("invertible");
        assert!((m * inv - Warp::identity()).abs().max() < 1e-6);
        assert!(invert(&Warp::new(0.0, 1.0, 1.0, 0.0)).is_none());
        assert!(invert(&Warp::new(1.0, 2.0, 0.5, 1.0)).is_none());
    }

    /// A 140×120 view of `texture` and a second view of it seen through the affine map `a`
    /// (offsets d around (70, 60) in the first appear at (72.3, 58.6) + a·d in the second), both
    /// smoothed; returns them and the second view's true position of the first's point `pt`.
    fn affine_pair(
        texture: &dyn Fn(f32, f32) -> f32,
        a: &Warp,
    ) -> (Prepared, Prepared, impl Fn([f32; 2]) -> [f32; 2]) {
        let inv = invert(a).unwrap();
        let (w, h) = (140, 120);
        let (cs, cd) = ([70.0f32, 60.0], [72.3f32, 58.6]);
        let image = |f: &dyn Fn(f32, f32) -> f32| Gray {
            w,
            h,
            data: (0..w * h)
                .map(|i| f((i % w) as f32 + 0.5, (i / w) as f32 + 0.5))
                .collect(),
        };
        let src = Prepared::new(image(texture).gaussian(1.0));
        let dst = Prepared::new(
            image(&|x, y| {
                let e = inv * Vector2::new(x - cd[0], y - cd[1]);
                texture(cs[0] + e.x, cs[1] + e.y)
            })
            .gaussian(1.0),
        );
        let a = *a;
        let truth = move |pt: [f32; 2]| {
            let d = a * Vector2::new(pt[0] - cs[0], pt[1] - cs[1]);
            [cd[0] + d.x, cd[1] + d.y]
        };
        (src, dst, truth)
    }

    /// Query points around the first view's centre (70, 60).
    const AFFINE_OFFSETS: [[f32; 2]; 5] = [
        [0.0, 0.0],
        [-14.3, 9.1],
        [11.7, -12.4],
        [16.2, 14.8],
        [-9.0, -15.5],
    ];

    /// A patch seen obliquely in the other view (an affine map of its offsets) is found where
    /// the map puts it when the template goes through that map, and with a bias without it.
    #[test]
    fn a_warped_template_removes_the_foreshortening_bias() {
        let texture = |u: f32, v: f32| {
            (0.23 * u).sin() * (0.19 * v).cos()
                + 0.6 * (0.07 * u - 0.13 * v).sin()
                + 0.4 * (0.011 * u * v + 0.3).sin()
        };
        let a = Warp::new(0.72, 0.22, -0.05, 1.18);
        let (src, dst, truth_of) = affine_pair(&texture, &a);
        let p = TrackParams {
            half: 8,
            radius: 6,
            neighbours: 1,
            min_ncc: 0.5,
            min_margin: 0.0,
            fb_tol: 3.0,
            affine: false,
        };
        let mut s = Scratch::default();
        let (mut warped, mut plain) = (Vec::new(), Vec::new());
        for e in &AFFINE_OFFSETS[..4] {
            let pt = [70.0 + e[0], 60.0 + e[1]];
            let truth = truth_of(pt);
            let err = |q: [f32; 2]| (q[0] - truth[0]).hypot(q[1] - truth[1]);
            let q = track_point(&src, &dst, pt, truth, &a, &p, &mut s).expect("tracked");
            warped.push(err(q));
            if let Some(q) = track_point(&src, &dst, pt, truth, &Warp::identity(), &p, &mut s) {
                plain.push(err(q));
            }
        }
        let mean = |v: &[f32]| v.iter().sum::<f32>() / v.len().max(1) as f32;
        assert!(warped.iter().all(|&e| e < 0.1), "{warped:?}");
        assert!(
            plain.len() < warped.len() || mean(&plain) > 3.0 * mean(&warped),
            "warped {warped:?}, plain {plain:?}"
        );
    }

    /// A predicted warp that is some 10–15 % off (a surface whose normal the model guessed
    /// wrong) biases a translation-only match; the affine refinement corrects the warp and finds
    /// the point.
    #[test]
    fn an_affine_refinement_corrects_a_wrongly_predicted_warp() {
        let texture = |u: f32, v: f32| {
            (0.23 * u).sin() * (0.19 * v).cos()
                + 0.6 * (0.07 * u - 0.13 * v).sin()
                + 0.4 * (0.011 * u * v + 0.3).sin()
                + 0.3 * (0.31 * u + 0.05 * v * v * 0.01).cos()
        };
        let a = Warp::new(0.84, 0.16, -0.05, 1.1);
        let predicted = a * Warp::new(1.13, -0.09, 0.07, 0.88);
        let (src, dst, truth_of) = affine_pair(&texture, &a);
        let mut p = TrackParams {
            half: 6,
            radius: 4,
            neighbours: 1,
            min_ncc: 0.5,
            min_margin: 0.0,
            fb_tol: 3.0,
            affine: false,
        };
        let mut s = Scratch::default();
        let mut errors = |affine: bool| -> Vec<f32> {
            p.affine = affine;
            AFFINE_OFFSETS
                .iter()
                .map(|e| {
                    let pt = [70.0 + e[0], 60.0 + e[1]];
                    let truth = truth_of(pt);
                    let q = track_point(&src, &dst, pt, truth, &predicted, &p, &mut s)
                        .expect("tracked");
                    (q[0] - truth[0]).hypot(q[1] - truth[1])
                })
                .collect()
        };
        let (plain, affine) = (errors(false), errors(true));
        let mean = |v: &[f32]| v.iter().sum::<f32>() / v.len() as f32;
        assert!(affine.iter().all(|&e| e < 0.1), "affine {affine:?}");
        assert!(
            mean(&plain) > 2.0 * mean(&affine),
            "translation only {plain:?}, affine {affine:?}"
        );
    }

    #[test]
    fn grid_points_skip_flat_regions_and_respect_budget_and_spacing() {
        // Left half textured, right half flat.
        let mut g = pattern(120, 80, 0.0, 0.0);
        for y in 0..80 {
            for x in 60..120 {
                g.data[y * 120 + x] = 0.5;
            }
        }
        let existing = [[20.5f32, 20.5]];
        let pts = grid_points(&g, 5, 6, 0.1, 0.0, &existing, 1000);
        assert!(pts.len() >= 20, "{}", pts.len());
        for p in &pts {
            // Patches reaching the flat half by more than their half-size are ill-conditioned.
            assert!(p[0] < 60.0 + 5.0, "{p:?} in the flat half");
            assert!(
                (p[0] - 20.5).powi(2) + (p[1] - 20.5).powi(2) >= 9.0,
                "{p:?}"
            );
        }
        let capped = grid_points(&g, 5, 6, 0.1, 0.0, &existing, 7);
        assert_eq!(capped.len(), 7);
        assert!(grid_points(&g, 5, 6, 0.1, 0.0, &existing, 0).is_empty());
        // Stripes (texture almost only across x, like a smear) are kept only without the
        // isotropy requirement.
        let stripes = Gray {
            w: 80,
            h: 60,
            data: (0..80 * 60)
                .map(|i| ((i % 80) as f32 * 0.4).sin() + 0.05 * ((i / 80) as f32 * 0.3).sin())
                .collect(),
        };
        assert!(!grid_points(&stripes, 5, 6, 0.1, 0.0, &[], 1000).is_empty());
        assert!(grid_points(&stripes, 5, 6, 0.1, 0.2, &[], 1000).is_empty());
    }

    #[test]
    fn thumbnail_overlap_finds_the_global_shift() {
        let a = pattern(192, 128, 0.0, 0.0);
        let b = pattern(192, 128, 20.0, 8.0);
        let o = overlaps(&[a, b], 192);
        assert!(o[0][1].score > 0.9);
        assert!(
            (o[0][1].shift[0] - 20.0).abs() <= 4.0 && (o[0][1].shift[1] - 8.0).abs() <= 4.0,
            "{:?}",
            o[0][1]
        );
    }
}

//! The fast f32 tile renderer.
//!
//! Forward: per-Gaussian preparation (covariance, opacity) once per call; projection of every
//! (camera, Gaussian) pair into a dense `[C·N]` array; per camera a depth sort of the drawable
//! Gaussians and per-16×16-tile lists filled in depth order; then rayon over (camera, tile), each
//! tile compositing its pixels front to back into tile-major buffers, which keep the final
//! transmittance and the number of list entries each pixel used for the backward.
//!
//! Backward: rayon over tiles again; each pixel walks its list back to front from its last
//! contributor and writes gradients into the tile's own slice of a per-intersection buffer (no
//! atomics, no sharing). Each camera then sums its intersections per Gaussian in list order, and
//! the shared f64 projection backward finishes. Every sum has a fixed order, so the results do
//! not depend on the number of threads.
//!
//! The per-pixel loops walk each splat's box row by row, 8 pixels (lanes) at a time with masks,
//! and are compiled for AVX2 / AVX-512 as well as portably, chosen at run time; all builds give
//! the same bits (no FMA contraction), which a unit test checks.

use rayon::prelude::*;

use crate::project::{self, Cam, GradSlices, Prep, ProjGrad};
use crate::{Camera, Gaussians, Gradients, RenderOutput, RenderSettings, SplatError, check_inputs};

/// Tile edge in pixels.
pub(crate) const TILE: usize = 16;
const TILE_PIXELS: usize = TILE * TILE;

/// One projected Gaussian in one camera, in the precision of the per-pixel loops.
#[derive(Clone, Copy, Debug, Default)]
struct Splat {
    x: f32,
    y: f32,
    conic: [f32; 3],
    opacity: f32,
    color: [f32; 3],
    depth: f32,
    /// Inclusive pixel range `[x0, x1] × [y0, y1]` where the Gaussian can be drawn (within
    /// the image); `x0 > x1` when there is none.
    pbox: [i32; 4],
}

/// Per-intersection (or per-splat) screen-space gradient.
#[derive(Clone, Copy, Debug, Default)]
struct SplatGrad {
    mean2d: [f32; 2],
    conic: [f32; 3],
    opacity: f32,
    color: [f32; 3],
}

impl SplatGrad {
    fn add(&mut self, o: &SplatGrad) {
        for k in 0..2 {
            self.mean2d[k] += o.mean2d[k];
        }
        for k in 0..3 {
            self.conic[k] += o.conic[k];
            self.color[k] += o.color[k];
        }
        self.opacity += o.opacity;
    }
}

/// Depth-ordered tile lists of one camera.
#[derive(Default)]
struct Bins {
    /// Sort keys (depth bits, Gaussian index) of the drawable Gaussians.
    keys: Vec<u64>,
    /// Gaussian index of each drawable splat, by increasing depth.
    gid: Vec<u32>,
    /// The drawable splats in that order, so that tiles read them with increasing addresses.
    splats: Vec<Splat>,
    /// Tile range `[x0, x1) × [y0, y1)` of each drawable splat.
    rects: Vec<[u16; 4]>,
    /// `[tiles + 1]` start of each tile's run in `ids`.
    offsets: Vec<u32>,
    /// Index into `splats` per intersection.
    ids: Vec<u32>,
    /// Copy of the splat per intersection, so that a tile reads its list sequentially.
    packed: Vec<Splat>,
    /// Write cursor per tile while filling `ids`.
    cursor: Vec<u32>,
}

/// Tile-local pixel box `[x0, x1) × [y0, y1)` a splat with pixel range `pbox` can draw into,
/// for the tile whose first pixel is `origin`.
#[inline(always)]
fn tile_box(pbox: [i32; 4], origin: (usize, usize)) -> [usize; 4] {
    let local = |lo: i32, hi: i32, o: usize| {
        let o = o as i32;
        let (lo, hi) = (lo.max(o), hi.min(o + TILE as i32 - 1));
        if lo <= hi {
            ((lo - o) as usize, (hi - o + 1) as usize)
        } else {
            (0, 0)
        }
    };
    let [px0, px1, py0, py1] = pbox;
    let (x0, x1) = local(px0, px1, origin.0);
    let (y0, y1) = local(py0, py1, origin.1);
    [x0, x1, y0, y1]
}

/// Inclusive range of pixel indices in `[0, n)` whose centre is within `extent` of `mean`.
fn pixel_span(mean: f32, extent: f32, n: usize) -> Option<(usize, usize)> {
    let lo = (mean - extent - 0.5).ceil();
    let hi = (mean + extent - 0.5).floor();
    // Positive phrasing: NaN gives None.
    if !(hi >= 0.0 && lo <= (n - 1) as f32 && lo <= hi) {
        return None;
    }
    Some((lo.max(0.0) as usize, (hi as usize).min(n - 1)))
}

/// Settings as f32 constants for the per-pixel loops.
#[derive(Clone, Copy)]
struct PixelRules {
    alpha_min: f32,
    alpha_max: f32,
    t_min: f32,
}

/// What `backward` needs from the last `forward`.
#[derive(Default)]
struct Saved {
    valid: bool,
    num_gaussians: usize,
    num_cameras: usize,
    width: usize,
    height: usize,
    tiles_x: usize,
    tiles_y: usize,
    settings: Option<RenderSettings>,
}

/// Fast renderer holding reusable buffers and the state the backward needs (saved by the last forward).
#[derive(Default)]
pub struct Renderer {
    saved: Saved,
    preps: Vec<Option<Prep>>,
    splats: Vec<Splat>,
    radii: Vec<[i32; 2]>,
    bins: Vec<Bins>,
    /// Tile-major per-pixel buffers, `[C · tiles · 256]`.
    tile_rgb: Vec<[f32; 3]>,
    tile_t: Vec<f32>,
    tile_last: Vec<u32>,
    tile_depth: Vec<f32>,
    isect_grads: Vec<SplatGrad>,
    splat_grads: Vec<SplatGrad>,
    tile_bg_grads: Vec<[f64; 3]>,
}

impl Renderer {
    pub fn new() -> Self {
        Self::default()
    }

    /// Renders `g` from every camera (all of one size) over its background.
    pub fn forward(
        &mut self,
        g: &Gaussians,
        cams: &[Camera],
        backgrounds: &[[f32; 3]],
        s: &RenderSettings,
    ) -> Result<RenderOutput, SplatError> {
        self.saved.valid = false;
        let (width, height) = check_inputs(g, cams, backgrounds)?;
        let (w, h) = (width as usize, height as usize);
        let n = g.len();
        let nc = cams.len();
        let tiles_x = w.div_ceil(TILE);
        let tiles_y = h.div_ceil(TILE);
        let tiles = tiles_x * tiles_y;
        let cams64: Vec<Cam> = cams.iter().map(Cam::new).collect();

        // Camera-independent work, once per call.
        self.preps.clear();
        self.preps.resize(n, None);
        self.preps
            .par_iter_mut()
            .enumerate()
            .with_min_len(256)
            .for_each(|(i, p)| *p = project::prepare(g, i));

        // Projection of every (camera, Gaussian).
        refill(&mut self.splats, nc * n, Splat::default());
        refill(&mut self.radii, nc * n, [0, 0]);
        let preps = &self.preps;
        self.splats
            .par_iter_mut()
            .zip(self.radii.par_iter_mut())
            .enumerate()
            .with_min_len(256)
            .for_each(|(k, (sp, r))| {
                let (c, i) = (k / n, k % n);
                if let Some(prep) = &preps[i]
                    && let Some(p) = project::project(g, i, prep, &cams64[c], s)
                {
                    *r = p.radii;
                    *sp = Splat {
                        x: p.mean2d[0] as f32,
                        y: p.mean2d[1] as f32,
                        conic: p.conic.map(|v| v as f32),
                        opacity: p.opacity as f32,
                        color: p.color.map(|v| v as f32),
                        depth: p.depth as f32,
                        pbox: [0; 4],
                    };
                    sp.pbox = match (
                        pixel_span(sp.x, p.extent[0] as f32, w),
                        pixel_span(sp.y, p.extent[1] as f32, h),
                    ) {
                        (Some((x0, x1)), Some((y0, y1))) => [x0, x1, y0, y1].map(|v| v as i32),
                        _ => [1, 0, 1, 0],
                    };
                }
            });

        // Per-camera depth order and tile lists.
        self.bins.resize_with(nc, Bins::default);
        let alpha_min = s.alpha_min;
        let splats = &self.splats;
        let radii = &self.radii;
        self.bins.par_iter_mut().enumerate().for_each(|(c, bins)| {
            let sp = &splats[c * n..(c + 1) * n];
            let rr = &radii[c * n..(c + 1) * n];
            bin_camera(bins, sp, rr, alpha_min, (w, h));
        });

        // Rasterise every (camera, tile).
        let total_pixels = nc * tiles * TILE_PIXELS;
        refill(&mut self.tile_rgb, total_pixels, [0.0; 3]);
        refill(&mut self.tile_t, total_pixels, 1.0);
        refill(&mut self.tile_last, total_pixels, 0);
        refill(&mut self.tile_depth, total_pixels, 0.0);
        let rules = PixelRules {
            alpha_min: s.alpha_min,
            alpha_max: s.alpha_max,
            t_min: s.transmittance_min,
        };
        let bins = &self.bins;
        (
            self.tile_rgb.par_chunks_mut(TILE_PIXELS),
            self.tile_t.par_chunks_mut(TILE_PIXELS),
            self.tile_last.par_chunks_mut(TILE_PIXELS),
            self.tile_depth.par_chunks_mut(TILE_PIXELS),
        )
            .into_par_iter()
            .enumerate()
            .for_each(|(gt, (rgb, t, last, depth))| {
                let (c, tile) = (gt / tiles, gt % tiles);
                let b = &bins[c];
                let range = b.offsets[tile] as usize..b.offsets[tile + 1] as usize;
                if range.is_empty() {
                    return;
                }
                let (tx, ty) = (tile % tiles_x, tile / tiles_x);
                let origin = (tx * TILE, ty * TILE);
                raster_tile_forward(
                    &b.packed[range],
                    &rules,
                    origin,
                    (w, h),
                    TileOut {
                        rgb,
                        t,
                        last,
                        depth,
                    },
                );
            });

        // Tile-major → [C,H,W] with the background.
        let mut rgb = vec![0.0f32; nc * h * w * 3];
        let mut alpha = vec![0.0f32; nc * h * w];
        let mut depth = s.compute_depth.then(|| vec![0.0f32; nc * h * w]);
        let (tile_rgb, tile_t, tile_depth) = (&self.tile_rgb, &self.tile_t, &self.tile_depth);
        let tile_index = |c: usize, x: usize, y: usize| {
            let tile = (y / TILE) * tiles_x + x / TILE;
            (c * tiles + tile) * TILE_PIXELS + (y % TILE) * TILE + x % TILE
        };
        rgb.par_chunks_mut(w * 3)
            .zip(alpha.par_chunks_mut(w))
            .enumerate()
            .for_each(|(row, (rgb_row, alpha_row))| {
                let (c, y) = (row / h, row % h);
                let bg = backgrounds[c];
                for x in 0..w {
                    let k = tile_index(c, x, y);
                    let t = tile_t[k];
                    for ch in 0..3 {
                        rgb_row[x * 3 + ch] = tile_rgb[k][ch] + t * bg[ch];
                    }
                    alpha_row[x] = 1.0 - t;
                }
            });
        if let Some(depth) = depth.as_mut() {
            depth
                .par_chunks_mut(w)
                .enumerate()
                .for_each(|(row, d_row)| {
                    let (c, y) = (row / h, row % h);
                    for (x, d) in d_row.iter_mut().enumerate() {
                        let k = tile_index(c, x, y);
                        let a = 1.0 - tile_t[k];
                        *d = if a > 0.0 { tile_depth[k] / a } else { 0.0 };
                    }
                });
        }

        self.saved = Saved {
            valid: true,
            num_gaussians: n,
            num_cameras: nc,
            width: w,
            height: h,
            tiles_x,
            tiles_y,
            settings: Some(*s),
        };
        Ok(RenderOutput {
            width,
            height,
            num_cameras: nc,
            rgb,
            alpha,
            depth,
            radii: self.radii.clone(),
        })
    }

    /// The last forward's settings, when it succeeded and rendered this batch (same number of
    /// Gaussians and cameras, same image size).
    fn last_forward(
        &self,
        g: &Gaussians,
        cams: &[Camera],
        backgrounds: &[[f32; 3]],
    ) -> Result<RenderSettings, SplatError> {
        let (width, height) = check_inputs(g, cams, backgrounds)?;
        let sv = &self.saved;
        let s = match sv.settings {
            Some(s) if sv.valid => s,
            _ => return Err(SplatError::NoForward("no successful forward call".into())),
        };
        crate::check_same_batch(
            crate::BatchShape {
                gaussians: sv.num_gaussians,
                cameras: sv.num_cameras,
                width: sv.width,
                height: sv.height,
            },
            crate::BatchShape {
                gaussians: g.len(),
                cameras: cams.len(),
                width: width as usize,
                height: height as usize,
            },
        )?;
        Ok(s)
    }

    /// Surface depth `[C,H,W]` of the last forward's images ([`crate::surface`]): at each
    /// pixel, the ray depth of the Gaussian that brings the transmittance to one half or below,
    /// 0 where it stays above. `g` and `cams` must be the last forward's. One pixel at a time
    /// (no lanes): it serves geometry, once per view, not the training loop.
    pub fn surface_depth(&self, g: &Gaussians, cams: &[Camera]) -> Result<Vec<f32>, SplatError> {
        let s = self.last_forward(g, cams, &vec![[0.0; 3]; cams.len()])?;
        let sv = &self.saved;
        let (w, h, tiles_x) = (sv.width, sv.height, sv.tiles_x);
        let (amin, amax, tmin) = (s.alpha_min, s.alpha_max, s.transmittance_min);
        let mut depth = vec![0.0f32; cams.len() * h * w];
        for (c, image) in depth.chunks_mut(h * w).enumerate() {
            let cam = Cam::new(&cams[c]);
            let b = &self.bins[c];
            let rays: Vec<Option<crate::surface::RayDepth>> = b
                .gid
                .par_iter()
                .map(|&i| crate::surface::RayDepth::new(g, i as usize, &cam))
                .collect();
            image.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
                let py = y as f32 + 0.5;
                for (x, out) in row.iter_mut().enumerate() {
                    let px = x as f32 + 0.5;
                    let tile = (y / TILE) * tiles_x + x / TILE;
                    let list = b.offsets[tile] as usize..b.offsets[tile + 1] as usize;
                    let mut t = 1.0f32;
                    for k in list {
                        let sp = &b.packed[k];
                        let [x0, x1, y0, y1] = sp.pbox;
                        let (xi, yi) = (x as i32, y as i32);
                        if xi < x0 || xi > x1 || yi < y0 || yi > y1 {
                            continue;
                        }
                        let (dx, dy) = (sp.x - px, sp.y - py);
                        let [ca, cb, cc] = sp.conic;
                        let sigma = 0.5 * (ca * dx * dx + cc * dy * dy) + cb * dx * dy;
                        let alpha = (sp.opacity * exp_neg(-sigma)).min(amax);
                        if sigma < 0.0 || alpha < amin {
                            continue;
                        }
                        let next_t = t * (1.0 - alpha);
                        if next_t <= tmin {
                            break;
                        }
                        if f64::from(next_t) <= crate::surface::SURFACE_TRANSMITTANCE {
                            if let Some(ray) = &rays[b.ids[k] as usize] {
                                *out = ray.at(&cam, f64::from(px), f64::from(py)) as f32;
                            }
                            break;
                        }
                        t = next_t;
                    }
                }
            });
        }
        Ok(depth)
    }

    /// Backward of the LAST forward call (same g/cams/backgrounds). d_rgb [C,H,W,3], d_alpha [C,H,W] or None.
    pub fn backward(
        &mut self,
        g: &Gaussians,
        cams: &[Camera],
        backgrounds: &[[f32; 3]],
        d_rgb: &[f32],
        d_alpha: Option<&[f32]>,
    ) -> Result<Gradients, SplatError> {
        let s = self.last_forward(g, cams, backgrounds)?;
        let sv = &self.saved;
        let (n, nc, w, h) = (sv.num_gaussians, sv.num_cameras, sv.width, sv.height);
        let (tiles_x, tiles_y) = (sv.tiles_x, sv.tiles_y);
        let tiles = tiles_x * tiles_y;
        if d_rgb.len() != nc * h * w * 3 {
            return Err(SplatError::Shape(format!(
                "d_rgb has {} values, expected C·H·W·3 = {}",
                d_rgb.len(),
                nc * h * w * 3
            )));
        }
        if let Some(da) = d_alpha
            && da.len() != nc * h * w
        {
            return Err(SplatError::Shape(format!(
                "d_alpha has {} values, expected C·H·W = {}",
                da.len(),
                nc * h * w
            )));
        }
        let rules = PixelRules {
            alpha_min: s.alpha_min,
            alpha_max: s.alpha_max,
            t_min: s.transmittance_min,
        };

        // Per-intersection gradients, one disjoint slice per (camera, tile).
        let isect_base: Vec<usize> = self
            .bins
            .iter()
            .scan(0usize, |acc, b| {
                let start = *acc;
                *acc += b.ids.len();
                Some(start)
            })
            .collect();
        let total_isect = self.bins.iter().map(|b| b.ids.len()).sum::<usize>();
        refill(&mut self.isect_grads, total_isect, SplatGrad::default());
        let mut tile_slices: Vec<&mut [SplatGrad]> = Vec::with_capacity(nc * tiles);
        let mut rest: &mut [SplatGrad] = &mut self.isect_grads;
        for b in &self.bins {
            for tile in 0..tiles {
                let len = (b.offsets[tile + 1] - b.offsets[tile]) as usize;
                let (head, tail) = std::mem::take(&mut rest).split_at_mut(len);
                tile_slices.push(head);
                rest = tail;
            }
        }
        self.tile_bg_grads.clear();
        self.tile_bg_grads.resize(nc * tiles, [0.0; 3]);
        // A camera given no upstream gradient contributes exact zeros: its tiles are not walked
        // and its entries stay zero (the trainer's stochastic backward through a subset of the
        // virtual views, `TrainConfig::backward_virtual_views`, relies on this to save the time).
        let active: Vec<bool> = (0..nc)
            .map(|c| {
                let img = c * h * w;
                d_rgb[img * 3..(img + h * w) * 3].iter().any(|&v| v != 0.0)
                    || d_alpha.is_some_and(|da| da[img..img + h * w].iter().any(|&v| v != 0.0))
            })
            .collect();
        let bins = &self.bins;
        let (tile_t, tile_last) = (&self.tile_t, &self.tile_last);
        tile_slices
            .into_par_iter()
            .zip(self.tile_bg_grads.par_iter_mut())
            .enumerate()
            .for_each(|(gt, (grads, bg_grad))| {
                let (c, tile) = (gt / tiles, gt % tiles);
                if !active[c] {
                    return;
                }
                let (tx, ty) = (tile % tiles_x, tile / tiles_x);
                let px = gt * TILE_PIXELS;
                let b = &bins[c];
                let range = b.offsets[tile] as usize..b.offsets[tile + 1] as usize;
                let origin = (tx * TILE, ty * TILE);
                // Entries behind every pixel's last contributor are never revisited.
                let last = &tile_last[px..px + TILE_PIXELS];
                let used = last.iter().copied().max().unwrap_or(0) as usize;
                let list = &b.packed[range.start..range.start + used];
                let img = c * h * w;
                let ctx = TileBackward {
                    rules: &rules,
                    origin,
                    w,
                    h,
                    t_final: &tile_t[px..px + TILE_PIXELS],
                    last,
                    d_rgb: &d_rgb[img * 3..(img + h * w) * 3],
                    d_alpha: d_alpha.map(|da| &da[img..img + h * w]),
                    bg: backgrounds[c],
                };
                *bg_grad = raster_tile_backward(list, &ctx, grads);
            });

        // Per camera: sum the intersections of each Gaussian in list order.
        refill(&mut self.splat_grads, nc * n, SplatGrad::default());
        let isect_grads = &self.isect_grads;
        self.splat_grads
            .par_chunks_mut(n.max(1))
            .enumerate()
            .for_each(|(c, acc)| {
                if !active[c] {
                    return;
                }
                let b = &bins[c];
                let base = isect_base[c];
                for (k, &id) in b.ids.iter().enumerate() {
                    acc[b.gid[id as usize] as usize].add(&isect_grads[base + k]);
                }
            });

        let mut backgrounds_grad = vec![[0.0f32; 3]; nc];
        for (c, bgg) in backgrounds_grad.iter_mut().enumerate() {
            let mut sum = [0.0f64; 3];
            for t in &self.tile_bg_grads[c * tiles..(c + 1) * tiles] {
                for ch in 0..3 {
                    sum[ch] += t[ch];
                }
            }
            *bgg = sum.map(|v| v as f32);
        }

        let mut out = Gradients {
            means: vec![[0.0; 3]; n],
            quats: vec![[0.0; 4]; n],
            log_scales: vec![[0.0; 3]; n],
            opacity_logits: vec![0.0; n],
            sh: vec![[[0.0; 3]; 16]; n],
            backgrounds: backgrounds_grad,
            cam_rotation: Vec::new(),
            cam_translation: Vec::new(),
            cam_focal: Vec::new(),
            mean2d_grad_norm: vec![0.0; n],
            visible_count: vec![0; n],
        };
        let cams64: Vec<Cam> = cams.iter().map(Cam::new).collect();
        let (radii, splat_grads) = (&self.radii, &self.splat_grads);
        let upstream = |c: usize, i: usize| -> Option<ProjGrad> {
            let k = c * n + i;
            if radii[k][0] <= 0 {
                return None;
            }
            let v = &splat_grads[k];
            Some(ProjGrad {
                mean2d: v.mean2d.map(f64::from),
                conic: v.conic.map(f64::from),
                opacity: v.opacity as f64,
                color: v.color.map(f64::from),
            })
        };
        let cam_grads = project::backward_all(
            g,
            &cams64,
            &self.preps,
            &s,
            &upstream,
            GradSlices {
                means: &mut out.means,
                quats: &mut out.quats,
                log_scales: &mut out.log_scales,
                opacity_logits: &mut out.opacity_logits,
                sh: &mut out.sh,
                mean2d_grad_norm: &mut out.mean2d_grad_norm,
                visible_count: &mut out.visible_count,
            },
        );
        out.cam_rotation = cam_grads
            .iter()
            .map(|cg| cg.r.map(|row| row.map(|v| v as f32)))
            .collect();
        out.cam_translation = cam_grads.iter().map(|cg| cg.t.map(|v| v as f32)).collect();
        out.cam_focal = cam_grads
            .iter()
            .map(|cg| cg.focal.map(|v| v as f32))
            .collect();
        Ok(out)
    }
}

/// Sets `v` to `len` copies of `value`, filling in parallel: these buffers are tens of MB, and a
/// serial fill would idle the other threads.
fn refill<T: Copy + Send + Sync>(v: &mut Vec<T>, len: usize, value: T) {
    v.truncate(len);
    v.par_iter_mut()
        .with_min_len(1 << 14)
        .for_each(|x| *x = value);
    v.resize(len, value);
}

/// Sorts the drawable Gaussians of one camera by depth, stores them compactly in that order and
/// fills the per-tile lists (indices into the compact array, hence increasing within a tile).
fn bin_camera(
    bins: &mut Bins,
    splats: &[Splat],
    radii: &[[i32; 2]],
    alpha_min: f32,
    (width, height): (usize, usize),
) {
    let tiles_x = width.div_ceil(TILE);
    let tiles_y = height.div_ceil(TILE);
    bins.keys.clear();
    for (i, (sp, r)) in splats.iter().zip(radii).enumerate() {
        // A Gaussian with opacity below the α cut-off can draw nothing; leaving it out of the
        // lists changes no output. Depth > near plane > 0, so its bit pattern sorts like the
        // value; the index in the low bits breaks ties as the reference's stable order does.
        if r[0] > 0 && sp.opacity >= alpha_min {
            bins.keys
                .push(((sp.depth.to_bits() as u64) << 32) | i as u64);
        }
    }
    bins.keys.sort_unstable();
    bins.gid.clear();
    bins.gid.extend(bins.keys.iter().map(|&k| k as u32));
    bins.splats.clear();
    bins.splats
        .extend(bins.gid.iter().map(|&i| splats[i as usize]));
    let tiles = tiles_x * tiles_y;
    bins.offsets.clear();
    bins.offsets.resize(tiles + 1, 0);
    bins.rects.clear();
    bins.rects.extend(bins.splats.iter().map(|sp| {
        let [x0, x1, y0, y1] = sp.pbox;
        if x0 <= x1 && y0 <= y1 {
            let tile = |v: i32| (v as usize / TILE) as u16;
            [tile(x0), tile(x1) + 1, tile(y0), tile(y1) + 1]
        } else {
            [0; 4]
        }
    }));
    for r in &bins.rects {
        let [x0, x1, y0, y1] = r.map(usize::from);
        for ty in y0..y1 {
            for tx in x0..x1 {
                bins.offsets[ty * tiles_x + tx + 1] += 1;
            }
        }
    }
    for t in 0..tiles {
        bins.offsets[t + 1] += bins.offsets[t];
    }
    bins.ids.clear();
    bins.ids.resize(bins.offsets[tiles] as usize, 0);
    bins.packed.clear();
    bins.packed
        .resize(bins.offsets[tiles] as usize, Splat::default());
    bins.cursor.clear();
    bins.cursor.extend_from_slice(&bins.offsets[..tiles]);
    let cursor = &mut bins.cursor;
    for (k, r) in bins.rects.iter().enumerate() {
        let [x0, x1, y0, y1] = r.map(usize::from);
        for ty in y0..y1 {
            for tx in x0..x1 {
                let t = ty * tiles_x + tx;
                bins.ids[cursor[t] as usize] = k as u32;
                bins.packed[cursor[t] as usize] = bins.splats[k];
                cursor[t] += 1;
            }
        }
    }
}

/// `exp(x)` for `x ≤ 0` without a libm call, so that the per-pixel loops stay branch-free and
/// vectorisable: `x = n·ln2 + r`, `|r| ≤ ln2/2`, degree-6 Taylor polynomial for `eʳ` (relative
/// error below 2e-7) and `2ⁿ` from the exponent bits. Inputs below −87 give `exp(−87)`.
#[inline(always)]
fn exp_neg(x: f32) -> f32 {
    const LOG2E: f32 = std::f32::consts::LOG2_E;
    // ln 2 split so that n·LN2_HI is exact (Cody–Waite).
    const LN2_HI: f32 = 0.693_359_4;
    const LN2_LO: f32 = -2.121_944_4e-4;
    // Round to nearest without `floor` (a libm call on baseline x86-64).
    const MAGIC: f32 = 12_582_912.0;
    let x = x.clamp(-87.0, 0.0);
    let m = x * LOG2E + MAGIC;
    let n = m - MAGIC;
    // m lies in [2²³, 2²⁴), where the spacing is 1, so its bits minus MAGIC's are the integer
    // n exactly; unlike `n as i32` (saturating, scalar code) this vectorises.
    let ni = m.to_bits() as i32 - MAGIC.to_bits() as i32;
    let r = (x - n * LN2_HI) - n * LN2_LO;
    let p = 1.0
        + r * (1.0
            + r * (0.5
                + r * (1.0 / 6.0 + r * (1.0 / 24.0 + r * (1.0 / 120.0 + r * (1.0 / 720.0))))));
    let scale = f32::from_bits(((ni + 127) as u32) << 23);
    p * scale
}

/// Pixel lanes evaluated together in the per-pixel loops (one AVX2 register of f32).
const LANES: usize = 8;
/// Tile buffers are padded so that a run of `LANES` pixels starting at any column of the last
/// row stays in bounds; lanes beyond a splat's span are masked out and leave the pixels as
/// they are.
const PADDED: usize = TILE_PIXELS + LANES;

/// Defines `$fast` as `$generic` compiled with the given target features. The lanes map onto
/// one AVX2 register; all builds perform the same IEEE operations in the same order (Rust
/// never contracts to FMA), so the results are bit-identical whichever build the CPU runs.
macro_rules! multiversion {
    ($features:literal, $generic:ident, $fast:ident, ($($arg:ident: $ty:ty),* $(,)?) -> $ret:ty) => {
        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = $features)]
        fn $fast($($arg: $ty),*) -> $ret {
            $generic($($arg),*)
        }
    };
}

/// Composites one tile front to back: splats in depth order, each over the pixels of its box
/// (the bounding box of its α ≥ 1/255 ellipse; row by row, `LANES` pixels at a time: a typical
/// box row fits in one step, so trimming rows to the ellipse costs more than it saves), with
/// per-pixel state in structure-of-arrays tile buffers. The lane loop is branch-free
/// (masks and selects instead of `continue`) so that it vectorises; masked lanes add exact
/// zeros and keep their state.
// Unsafe only to call the `#[target_feature]` build after the runtime CPU check.
#[allow(unsafe_code)]
fn raster_tile_forward(
    sc: &[Splat],
    rules: &PixelRules,
    origin: (usize, usize),
    size: (usize, usize),
    out: TileOut<'_>,
) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU supports AVX2 (checked just above).
        return unsafe { raster_tile_forward_avx2(sc, rules, origin, size, out) };
    }
    raster_tile_forward_generic(sc, rules, origin, size, out);
}

/// One tile's output buffers (`TILE_PIXELS` entries each, tile-major): colour over a black
/// background, final transmittance, index of the last contributing splat + 1, expected depth.
struct TileOut<'a> {
    rgb: &'a mut [[f32; 3]],
    t: &'a mut [f32],
    last: &'a mut [u32],
    depth: &'a mut [f32],
}

multiversion!("avx2", raster_tile_forward_generic, raster_tile_forward_avx2, (
    sc: &[Splat],
    rules: &PixelRules,
    origin: (usize, usize),
    size: (usize, usize),
    out: TileOut<'_>,
) -> ());

#[inline(always)]
fn raster_tile_forward_generic(
    sc: &[Splat],
    rules: &PixelRules,
    origin: (usize, usize),
    (w, h): (usize, usize),
    out: TileOut<'_>,
) {
    let TileOut {
        rgb,
        t: t_out,
        last: last_out,
        depth: depth_out,
    } = out;
    let mut t = [1.0f32; PADDED];
    let mut cr = [0.0f32; PADDED];
    let mut cg = [0.0f32; PADDED];
    let mut cb = [0.0f32; PADDED];
    let mut dz = [0.0f32; PADDED];
    let mut last = [0u32; PADDED];
    // Pixels beyond the image edge are never opened (1 = done).
    let mut done = [1u32; PADDED];
    let mut open = 0usize;
    for ly in 0..TILE.min(h - origin.1) {
        for lx in 0..TILE.min(w - origin.0) {
            done[ly * TILE + lx] = 0;
            open += 1;
        }
    }
    let lane_offset: [f32; LANES] = std::array::from_fn(|i| i as f32);
    let (amin, amax, tmin) = (rules.alpha_min, rules.alpha_max, rules.t_min);
    for (j, sp) in sc.iter().enumerate() {
        let [x0, x1, y0, y1] = tile_box(sp.pbox, origin);
        let (mx, my) = (sp.x, sp.y);
        let ([ca, cbb, cc], op) = (sp.conic, sp.opacity);
        let [r, g, b] = sp.color;
        let z = sp.depth;
        let id = j as u32 + 1;
        let px0 = mx - (origin.0 as f32 + 0.5);
        // Per lane, so that the count stays a vector add.
        let mut stopped = [0u32; LANES];
        for ly in y0..y1 {
            let dy = my - ((origin.1 + ly) as f32 + 0.5);
            let row = ly * TILE;
            let mut start = x0;
            while start < x1 {
                let k0 = row + start;
                let n_in = (x1 - start) as u32;
                let tv: &mut [f32; LANES] = (&mut t[k0..k0 + LANES]).try_into().unwrap();
                let crv: &mut [f32; LANES] = (&mut cr[k0..k0 + LANES]).try_into().unwrap();
                let cgv: &mut [f32; LANES] = (&mut cg[k0..k0 + LANES]).try_into().unwrap();
                let cbv: &mut [f32; LANES] = (&mut cb[k0..k0 + LANES]).try_into().unwrap();
                let dzv: &mut [f32; LANES] = (&mut dz[k0..k0 + LANES]).try_into().unwrap();
                let lastv: &mut [u32; LANES] = (&mut last[k0..k0 + LANES]).try_into().unwrap();
                let donev: &mut [u32; LANES] = (&mut done[k0..k0 + LANES]).try_into().unwrap();
                let dx0 = px0 - start as f32;
                for i in 0..LANES {
                    let dx = dx0 - lane_offset[i];
                    let sigma = 0.5 * (ca * dx * dx + cc * dy * dy) + cbb * dx * dy;
                    let alpha = (op * exp_neg(-sigma)).min(amax);
                    let tk = tv[i];
                    let next_t = tk * (1.0 - alpha);
                    let valid =
                        ((i as u32) < n_in) & (donev[i] == 0) & (sigma >= 0.0) & (alpha >= amin);
                    let stop = valid & (next_t <= tmin);
                    let draw = valid & !stop;
                    donev[i] |= stop as u32;
                    stopped[i] += stop as u32;
                    let wgt = if draw { alpha * tk } else { 0.0 };
                    crv[i] += r * wgt;
                    cgv[i] += g * wgt;
                    cbv[i] += b * wgt;
                    dzv[i] += z * wgt;
                    tv[i] = if draw { next_t } else { tk };
                    lastv[i] = if draw { id } else { lastv[i] };
                }
                start += LANES;
            }
        }
        open -= stopped.iter().sum::<u32>() as usize;
        if open == 0 {
            break;
        }
    }
    for k in 0..TILE_PIXELS {
        rgb[k] = [cr[k], cg[k], cb[k]];
    }
    t_out.copy_from_slice(&t[..TILE_PIXELS]);
    last_out.copy_from_slice(&last[..TILE_PIXELS]);
    depth_out.copy_from_slice(&dz[..TILE_PIXELS]);
}

/// Inputs of one tile's backward.
struct TileBackward<'a> {
    rules: &'a PixelRules,
    origin: (usize, usize),
    w: usize,
    h: usize,
    t_final: &'a [f32],
    last: &'a [u32],
    /// This camera's `[H,W,3]`.
    d_rgb: &'a [f32],
    d_alpha: Option<&'a [f32]>,
    bg: [f32; 3],
}

/// Walks a tile's list back to front, each splat over the pixels of its box for which it was
/// composited (index below the pixel's last contributor), restoring the transmittance and the
/// colour behind, `LANES` pixels at a time with masks (as in the forward); writes each list
/// entry's summed gradient into `grads` (per-lane partial sums added in lane order, so the
/// result is deterministic) and returns the tile's background gradient.
// Unsafe only to call the `#[target_feature]` builds after the runtime CPU checks.
#[allow(unsafe_code)]
fn raster_tile_backward(sc: &[Splat], ctx: &TileBackward<'_>, grads: &mut [SplatGrad]) -> [f64; 3] {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::is_x86_feature_detected as has;
        if has!("avx512f") && has!("avx512vl") {
            // SAFETY: the CPU supports AVX-512 F and VL (checked just above).
            return unsafe { raster_tile_backward_avx512(sc, ctx, grads) };
        }
        if has!("avx2") {
            // SAFETY: the CPU supports AVX2 (checked just above).
            return unsafe { raster_tile_backward_avx2(sc, ctx, grads) };
        }
    }
    raster_tile_backward_generic(sc, ctx, grads)
}

multiversion!("avx2", raster_tile_backward_generic, raster_tile_backward_avx2, (
    sc: &[Splat],
    ctx: &TileBackward<'_>,
    grads: &mut [SplatGrad],
) -> [f64; 3]);

// Same 8-lane code with AVX-512 F+VL enabled: 32 vector registers and mask registers remove
// the spills of the backward's many accumulators (about 10% faster here; the forward, with
// fewer live values, runs slower this way and stays on AVX2).
multiversion!("avx2,avx512f,avx512vl", raster_tile_backward_generic, raster_tile_backward_avx512, (
    sc: &[Splat],
    ctx: &TileBackward<'_>,
    grads: &mut [SplatGrad],
) -> [f64; 3]);

/// Sum of the lanes in lane order.
#[inline(always)]
fn lane_sum(v: &[f32; LANES]) -> f32 {
    v.iter().fold(0.0, |acc, &x| acc + x)
}

#[inline(always)]
fn raster_tile_backward_generic(
    sc: &[Splat],
    ctx: &TileBackward<'_>,
    grads: &mut [SplatGrad],
) -> [f64; 3] {
    let rules = ctx.rules;
    let (ox, oy) = ctx.origin;
    let mut t = [0.0f32; PADDED];
    // Colour composited behind each pixel so far, per channel.
    let mut behind = [[0.0f32; PADDED]; 3];
    // dL/dRGB per channel.
    let mut vc = [[0.0f32; PADDED]; 3];
    // (d_alpha − d_rgb·bg) · T_final: the part of dL/dα_j common to every splat of a pixel.
    let mut v_final = [0.0f32; PADDED];
    // Last contributor per pixel; 0 (nothing to undo) outside the image and in the padding.
    let mut last = [0u32; PADDED];
    let mut v_bg = [0.0f64; 3];
    let mut max_last = 0u32;
    for ly in 0..TILE.min(ctx.h - oy) {
        for lx in 0..TILE.min(ctx.w - ox) {
            let k = ly * TILE + lx;
            let pix = (oy + ly) * ctx.w + ox + lx;
            let v = [
                ctx.d_rgb[pix * 3],
                ctx.d_rgb[pix * 3 + 1],
                ctx.d_rgb[pix * 3 + 2],
            ];
            let va = ctx.d_alpha.map_or(0.0, |da| da[pix]);
            let tf = ctx.t_final[k];
            for ch in 0..3 {
                v_bg[ch] += (v[ch] * tf) as f64;
                vc[ch][k] = v[ch];
            }
            let bg_dot = v[0] * ctx.bg[0] + v[1] * ctx.bg[1] + v[2] * ctx.bg[2];
            v_final[k] = tf * (va - bg_dot);
            t[k] = tf;
            last[k] = ctx.last[k];
            max_last = max_last.max(ctx.last[k]);
        }
    }
    let lane_offset: [f32; LANES] = std::array::from_fn(|i| i as f32);
    let (amin, amax) = (rules.alpha_min, rules.alpha_max);
    let [vr, vg, vb] = &vc;
    let [br, bgr, bb] = &mut behind;
    for j in (0..max_last as usize).rev() {
        let sp = &sc[j];
        let [x0, x1, y0, y1] = tile_box(sp.pbox, ctx.origin);
        let (mx, my) = (sp.x, sp.y);
        let ([ca, cb, cc], op) = (sp.conic, sp.opacity);
        let col = sp.color;
        let px0 = mx - (ox as f32 + 0.5);
        let jj = j as u32;
        let mut g_col = [[0.0f32; LANES]; 3];
        let mut g_conic = [[0.0f32; LANES]; 3];
        let mut g_mean = [[0.0f32; LANES]; 2];
        let mut g_op = [0.0f32; LANES];
        for ly in y0..y1 {
            let dy = my - ((oy + ly) as f32 + 0.5);
            let row = ly * TILE;
            let mut start = x0;
            while start < x1 {
                let k0 = row + start;
                let n_in = (x1 - start) as u32;
                let lane =
                    |a: &[f32; PADDED]| -> [f32; LANES] { a[k0..k0 + LANES].try_into().unwrap() };
                let (vr, vg, vb, vf) = (lane(vr), lane(vg), lane(vb), lane(&v_final));
                let lastv: [u32; LANES] = last[k0..k0 + LANES].try_into().unwrap();
                let tv: &mut [f32; LANES] = (&mut t[k0..k0 + LANES]).try_into().unwrap();
                let brv: &mut [f32; LANES] = (&mut br[k0..k0 + LANES]).try_into().unwrap();
                let bgv: &mut [f32; LANES] = (&mut bgr[k0..k0 + LANES]).try_into().unwrap();
                let bbv: &mut [f32; LANES] = (&mut bb[k0..k0 + LANES]).try_into().unwrap();
                let dx0 = px0 - start as f32;
                for i in 0..LANES {
                    let dx = dx0 - lane_offset[i];
                    let sigma = 0.5 * (ca * dx * dx + cc * dy * dy) + cb * dx * dy;
                    let gauss = exp_neg(-sigma);
                    let raw = op * gauss;
                    let alpha = raw.min(amax);
                    // Exactly the forward's test for "composited at this pixel".
                    let valid =
                        ((i as u32) < n_in) & (jj < lastv[i]) & (sigma >= 0.0) & (alpha >= amin);
                    let ra = 1.0 / (1.0 - alpha);
                    let tk = tv[i] * ra;
                    tv[i] = if valid { tk } else { tv[i] };
                    let wgt = if valid { alpha * tk } else { 0.0 };
                    let mut v_alpha = vf[i] * ra;
                    v_alpha += vr[i] * (col[0] * tk - brv[i] * ra);
                    v_alpha += vg[i] * (col[1] * tk - bgv[i] * ra);
                    v_alpha += vb[i] * (col[2] * tk - bbv[i] * ra);
                    g_col[0][i] += wgt * vr[i];
                    g_col[1][i] += wgt * vg[i];
                    g_col[2][i] += wgt * vb[i];
                    brv[i] += col[0] * wgt;
                    bgv[i] += col[1] * wgt;
                    bbv[i] += col[2] * wgt;
                    let unclamped = valid & (raw <= amax);
                    let v_sigma = if unclamped { -raw * v_alpha } else { 0.0 };
                    let v_op = if unclamped { gauss * v_alpha } else { 0.0 };
                    g_conic[0][i] += 0.5 * v_sigma * dx * dx;
                    g_conic[1][i] += v_sigma * dx * dy;
                    g_conic[2][i] += 0.5 * v_sigma * dy * dy;
                    g_mean[0][i] += v_sigma * (ca * dx + cb * dy);
                    g_mean[1][i] += v_sigma * (cb * dx + cc * dy);
                    g_op[i] += v_op;
                }
                start += LANES;
            }
        }
        grads[j] = SplatGrad {
            mean2d: g_mean.each_ref().map(lane_sum),
            conic: g_conic.each_ref().map(lane_sum),
            opacity: lane_sum(&g_op),
            color: g_col.each_ref().map(lane_sum),
        };
    }
    v_bg
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exp_neg_is_accurate_where_alpha_can_pass_the_cutoff() {
        let mut worst = 0.0f64;
        for k in 0..=200_000 {
            let x = -(k as f32) * 30.0 / 200_000.0;
            let got = exp_neg(x) as f64;
            let want = (x as f64).exp();
            worst = worst.max((got - want).abs() / want);
        }
        assert!(worst < 3e-7, "relative error {worst}");
        assert_eq!(exp_neg(0.0), 1.0);
        assert!(exp_neg(-200.0) > 0.0 && exp_neg(-200.0) < 1e-37);
    }

    /// Random splats of one tile (partly outside a 40×40 image) in depth order, with their
    /// drawable pixel boxes.
    fn random_tile(seed: u32, count: usize) -> (Vec<Splat>, (usize, usize), (usize, usize)) {
        let mut state = seed;
        let mut next = || {
            state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (state >> 8) as f32 / (1u32 << 24) as f32
        };
        let (origin, size) = ((32, 32), (40, 40));
        let splats: Vec<Splat> = (0..count)
            .map(|k| {
                let (sx, sy, rho) = (0.4 + 4.0 * next(), 0.4 + 4.0 * next(), 1.6 * next() - 0.8);
                let (xx, yy, xy) = (sx * sx + 0.3, sy * sy + 0.3, rho * sx * sy);
                let det = xx * yy - xy * xy;
                let (x, y) = (26.0 + 20.0 * next(), 26.0 + 20.0 * next());
                let (ex, ey) = (3.33 * xx.sqrt(), 3.33 * yy.sqrt());
                let pbox = match (pixel_span(x, ex, size.0), pixel_span(y, ey, size.1)) {
                    (Some((x0, x1)), Some((y0, y1))) => [x0, x1, y0, y1].map(|v| v as i32),
                    _ => [1, 0, 1, 0],
                };
                Splat {
                    x,
                    y,
                    conic: [yy / det, -xy / det, xx / det],
                    opacity: 0.02 + 0.97 * next(),
                    color: [next(), next(), next()],
                    depth: 1.0 + k as f32 * 0.01,
                    pbox,
                }
            })
            .collect();
        (splats, origin, size)
    }

    type TileForwardFn<'a> = dyn Fn(&mut [[f32; 3]], &mut [f32], &mut [u32], &mut [f32]) + 'a;

    /// The portable build of the pixel loops must give the same bits as the SIMD builds the
    /// CPU dispatches to, so that results do not depend on the machine.
    #[test]
    fn simd_and_portable_pixel_loops_agree_bit_for_bit() {
        let rules = PixelRules {
            alpha_min: 1.0 / 255.0,
            alpha_max: 0.999,
            t_min: 1e-4,
        };
        for (seed, count) in [(1, 5), (2, 60), (3, 400)] {
            let (sc, origin, size) = random_tile(seed, count);
            let forward = |f: &TileForwardFn| {
                let mut rgb = vec![[0.0f32; 3]; TILE_PIXELS];
                let (mut t, mut last, mut depth) = (
                    vec![0.0f32; TILE_PIXELS],
                    vec![0u32; TILE_PIXELS],
                    vec![0.0f32; TILE_PIXELS],
                );
                f(&mut rgb, &mut t, &mut last, &mut depth);
                (rgb, t, last, depth)
            };
            let fast = forward(&|rgb, t, last, depth| {
                let out = TileOut {
                    rgb,
                    t,
                    last,
                    depth,
                };
                raster_tile_forward(&sc, &rules, origin, size, out);
            });
            let portable = forward(&|rgb, t, last, depth| {
                let out = TileOut {
                    rgb,
                    t,
                    last,
                    depth,
                };
                raster_tile_forward_generic(&sc, &rules, origin, size, out);
            });
            let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(fast.0.as_flattened()), bits(portable.0.as_flattened()));
            assert_eq!(bits(&fast.1), bits(&portable.1));
            assert_eq!(fast.2, portable.2);
            assert_eq!(bits(&fast.3), bits(&portable.3));
            assert!(fast.2.iter().any(|&l| l > 0), "nothing drawn");

            let d_rgb: Vec<f32> = (0..size.0 * size.1 * 3)
                .map(|k| ((k * 7919) % 200) as f32 / 100.0 - 1.0)
                .collect();
            let d_alpha: Vec<f32> = (0..size.0 * size.1)
                .map(|k| ((k * 104_729) % 200) as f32 / 100.0 - 1.0)
                .collect();
            let ctx = TileBackward {
                rules: &rules,
                origin,
                w: size.0,
                h: size.1,
                t_final: &fast.1,
                last: &fast.2,
                d_rgb: &d_rgb,
                d_alpha: Some(&d_alpha),
                bg: [0.1, 0.2, 0.3],
            };
            let mut g_fast = vec![SplatGrad::default(); count];
            let mut g_portable = vec![SplatGrad::default(); count];
            let bg_fast = raster_tile_backward(&sc, &ctx, &mut g_fast);
            let bg_portable = raster_tile_backward_generic(&sc, &ctx, &mut g_portable);
            assert_eq!(bg_fast.map(f64::to_bits), bg_portable.map(f64::to_bits));
            let flat = |g: &[SplatGrad]| {
                g.iter()
                    .flat_map(|v| {
                        v.mean2d
                            .into_iter()
                            .chain(v.conic)
                            .chain([v.opacity])
                            .chain(v.color)
                    })
                    .map(f32::to_bits)
                    .collect::<Vec<_>>()
            };
            assert_eq!(flat(&g_fast), flat(&g_portable));
            assert!(g_fast.iter().any(|v| v.opacity != 0.0), "no gradient");
        }
    }

    #[test]
    fn pixel_span_covers_exactly_the_centres_within_the_extent() {
        // Centres at x + 0.5: mean 10.2, extent 2 covers centres 8.5..=11.5 → pixels 8..=11.
        assert_eq!(pixel_span(10.2, 2.0, 100), Some((8, 11)));
        assert_eq!(pixel_span(-5.0, 2.0, 100), None);
        assert_eq!(pixel_span(1.0, 100.0, 10), Some((0, 9)));
        assert_eq!(pixel_span(f32::NAN, 1.0, 10), None);
    }
}

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
    /// (depth, Gaussian) of the drawable Gaussians, sorted.
    order: Vec<(f32, u32)>,
    /// `[tiles + 1]` start of each tile's run in `ids`.
    offsets: Vec<u32>,
    /// Gaussian index per intersection.
    ids: Vec<u32>,
    /// Write cursor per tile while filling `ids`.
    cursor: Vec<u32>,
}

/// Tile-local copy of the splats in a tile's list (structure of arrays), reused across tiles.
#[derive(Default)]
struct TileScratch {
    x: Vec<f32>,
    y: Vec<f32>,
    a: Vec<f32>,
    b: Vec<f32>,
    c: Vec<f32>,
    o: Vec<f32>,
    col: Vec<[f32; 3]>,
    z: Vec<f32>,
}

impl TileScratch {
    fn load(&mut self, splats: &[Splat], ids: &[u32]) {
        self.x.clear();
        self.y.clear();
        self.a.clear();
        self.b.clear();
        self.c.clear();
        self.o.clear();
        self.col.clear();
        self.z.clear();
        for &id in ids {
            let s = &splats[id as usize];
            self.x.push(s.x);
            self.y.push(s.y);
            self.a.push(s.conic[0]);
            self.b.push(s.conic[1]);
            self.c.push(s.conic[2]);
            self.o.push(s.opacity);
            self.col.push(s.color);
            self.z.push(s.depth);
        }
    }
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
        self.splats.clear();
        self.splats.resize(nc * n, Splat::default());
        self.radii.clear();
        self.radii.resize(nc * n, [0, 0]);
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
            bin_camera(bins, sp, rr, alpha_min, tiles_x, tiles_y);
        });

        // Rasterise every (camera, tile).
        let total_pixels = nc * tiles * TILE_PIXELS;
        self.tile_rgb.clear();
        self.tile_rgb.resize(total_pixels, [0.0; 3]);
        self.tile_t.clear();
        self.tile_t.resize(total_pixels, 1.0);
        self.tile_last.clear();
        self.tile_last.resize(total_pixels, 0);
        self.tile_depth.clear();
        self.tile_depth.resize(total_pixels, 0.0);
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
            .for_each_init(
                TileScratch::default,
                |scratch, (gt, (rgb, t, last, depth))| {
                    let (c, tile) = (gt / tiles, gt % tiles);
                    let b = &bins[c];
                    let ids = &b.ids[b.offsets[tile] as usize..b.offsets[tile + 1] as usize];
                    if ids.is_empty() {
                        return;
                    }
                    scratch.load(&splats[c * n..(c + 1) * n], ids);
                    let (tx, ty) = (tile % tiles_x, tile / tiles_x);
                    raster_tile_forward(scratch, &rules, tx, ty, w, h, rgb, t, last, depth);
                },
            );

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

    /// Backward of the LAST forward call (same g/cams/backgrounds). d_rgb [C,H,W,3], d_alpha [C,H,W] or None.
    pub fn backward(
        &mut self,
        g: &Gaussians,
        cams: &[Camera],
        backgrounds: &[[f32; 3]],
        d_rgb: &[f32],
        d_alpha: Option<&[f32]>,
    ) -> Result<Gradients, SplatError> {
        let (width, height) = check_inputs(g, cams, backgrounds)?;
        let sv = &self.saved;
        let s = match sv.settings {
            Some(s) if sv.valid => s,
            _ => return Err(SplatError::NoForward("no successful forward call".into())),
        };
        if sv.num_gaussians != g.len()
            || sv.num_cameras != cams.len()
            || sv.width != width as usize
            || sv.height != height as usize
        {
            return Err(SplatError::NoForward(format!(
                "forward had {} Gaussians, {} cameras of {}x{}; backward got {}, {} of {}x{}",
                sv.num_gaussians,
                sv.num_cameras,
                sv.width,
                sv.height,
                g.len(),
                cams.len(),
                width,
                height
            )));
        }
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
        self.isect_grads.clear();
        self.isect_grads.resize(total_isect, SplatGrad::default());
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
        let (bins, splats) = (&self.bins, &self.splats);
        let (tile_t, tile_last) = (&self.tile_t, &self.tile_last);
        tile_slices
            .into_par_iter()
            .zip(self.tile_bg_grads.par_iter_mut())
            .enumerate()
            .for_each_init(TileScratch::default, |scratch, (gt, (grads, bg_grad))| {
                let (c, tile) = (gt / tiles, gt % tiles);
                let (tx, ty) = (tile % tiles_x, tile / tiles_x);
                let px = gt * TILE_PIXELS;
                let b = &bins[c];
                let ids = &b.ids[b.offsets[tile] as usize..b.offsets[tile + 1] as usize];
                scratch.load(&splats[c * n..(c + 1) * n], ids);
                let img = c * h * w;
                let ctx = TileBackward {
                    rules: &rules,
                    tx,
                    ty,
                    w,
                    h,
                    t_final: &tile_t[px..px + TILE_PIXELS],
                    last: &tile_last[px..px + TILE_PIXELS],
                    d_rgb: &d_rgb[img * 3..(img + h * w) * 3],
                    d_alpha: d_alpha.map(|da| &da[img..img + h * w]),
                    bg: backgrounds[c],
                };
                *bg_grad = raster_tile_backward(scratch, &ctx, grads);
            });

        // Per camera: sum the intersections of each Gaussian in list order.
        self.splat_grads.clear();
        self.splat_grads.resize(nc * n, SplatGrad::default());
        let isect_grads = &self.isect_grads;
        self.splat_grads
            .par_chunks_mut(n.max(1))
            .enumerate()
            .for_each(|(c, acc)| {
                let b = &bins[c];
                let base = isect_base[c];
                for (k, &id) in b.ids.iter().enumerate() {
                    acc[id as usize].add(&isect_grads[base + k]);
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
        Ok(out)
    }
}

/// Sorts the drawable Gaussians of one camera by depth and fills its per-tile lists in that order.
fn bin_camera(
    bins: &mut Bins,
    splats: &[Splat],
    radii: &[[i32; 2]],
    alpha_min: f32,
    tiles_x: usize,
    tiles_y: usize,
) {
    bins.order.clear();
    for (i, (sp, r)) in splats.iter().zip(radii).enumerate() {
        // A Gaussian with opacity below the α cut-off can draw nothing; leaving it out of the
        // lists changes no output.
        if r[0] > 0 && sp.opacity >= alpha_min {
            bins.order.push((sp.depth, i as u32));
        }
    }
    // Increasing depth, ties by index: the reference's stable order.
    bins.order
        .sort_unstable_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    let tiles = tiles_x * tiles_y;
    bins.offsets.clear();
    bins.offsets.resize(tiles + 1, 0);
    let rect = |i: u32| {
        let sp = &splats[i as usize];
        let r = radii[i as usize];
        tile_rect(sp.x, sp.y, r, tiles_x, tiles_y)
    };
    for &(_, i) in &bins.order {
        let (x0, x1, y0, y1) = rect(i);
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
    bins.cursor.clear();
    bins.cursor.extend_from_slice(&bins.offsets[..tiles]);
    let cursor = &mut bins.cursor;
    for &(_, i) in &bins.order {
        let (x0, x1, y0, y1) = rect(i);
        for ty in y0..y1 {
            for tx in x0..x1 {
                let t = ty * tiles_x + tx;
                bins.ids[cursor[t] as usize] = i;
                cursor[t] += 1;
            }
        }
    }
}

/// Tile range `[x0, x1) × [y0, y1)` covered by the box `mean ± radius`.
fn tile_rect(
    x: f32,
    y: f32,
    r: [i32; 2],
    tiles_x: usize,
    tiles_y: usize,
) -> (usize, usize, usize, usize) {
    let ts = TILE as f32;
    let clampf = |v: f32, hi: usize| (v.max(0.0) as usize).min(hi);
    let x0 = clampf(((x - r[0] as f32) / ts).floor(), tiles_x);
    let x1 = clampf(((x + r[0] as f32) / ts).ceil(), tiles_x);
    let y0 = clampf(((y - r[1] as f32) / ts).floor(), tiles_y);
    let y1 = clampf(((y + r[1] as f32) / ts).ceil(), tiles_y);
    (x0, x1, y0, y1)
}

/// Composites one tile front to back.
#[allow(clippy::too_many_arguments)]
fn raster_tile_forward(
    sc: &TileScratch,
    rules: &PixelRules,
    tx: usize,
    ty: usize,
    w: usize,
    h: usize,
    rgb: &mut [[f32; 3]],
    t_out: &mut [f32],
    last_out: &mut [u32],
    depth_out: &mut [f32],
) {
    let len = sc.x.len();
    for ly in 0..TILE {
        let y = ty * TILE + ly;
        if y >= h {
            break;
        }
        let py = y as f32 + 0.5;
        for lx in 0..TILE {
            let x = tx * TILE + lx;
            if x >= w {
                break;
            }
            let px = x as f32 + 0.5;
            let mut t = 1.0f32;
            let mut acc = [0.0f32; 3];
            let mut d = 0.0f32;
            let mut last = 0u32;
            for j in 0..len {
                let dx = sc.x[j] - px;
                let dy = sc.y[j] - py;
                let sigma = 0.5 * (sc.a[j] * dx * dx + sc.c[j] * dy * dy) + sc.b[j] * dx * dy;
                if sigma < 0.0 {
                    continue;
                }
                let alpha = (sc.o[j] * (-sigma).exp()).min(rules.alpha_max);
                if alpha < rules.alpha_min {
                    continue;
                }
                let next_t = t * (1.0 - alpha);
                if next_t <= rules.t_min {
                    break;
                }
                let wgt = alpha * t;
                let col = sc.col[j];
                acc[0] += col[0] * wgt;
                acc[1] += col[1] * wgt;
                acc[2] += col[2] * wgt;
                d += sc.z[j] * wgt;
                t = next_t;
                last = j as u32 + 1;
            }
            let k = ly * TILE + lx;
            rgb[k] = acc;
            t_out[k] = t;
            last_out[k] = last;
            depth_out[k] = d;
        }
    }
}

/// Inputs of one tile's backward.
struct TileBackward<'a> {
    rules: &'a PixelRules,
    tx: usize,
    ty: usize,
    w: usize,
    h: usize,
    t_final: &'a [f32],
    last: &'a [u32],
    /// This camera's `[H,W,3]`.
    d_rgb: &'a [f32],
    d_alpha: Option<&'a [f32]>,
    bg: [f32; 3],
}

/// Walks each pixel of a tile back to front; writes per-list-entry gradients into `grads` and
/// returns this tile's background gradient.
fn raster_tile_backward(
    sc: &TileScratch,
    ctx: &TileBackward<'_>,
    grads: &mut [SplatGrad],
) -> [f64; 3] {
    let rules = ctx.rules;
    let mut v_bg = [0.0f64; 3];
    for ly in 0..TILE {
        let y = ctx.ty * TILE + ly;
        if y >= ctx.h {
            break;
        }
        let py = y as f32 + 0.5;
        for lx in 0..TILE {
            let x = ctx.tx * TILE + lx;
            if x >= ctx.w {
                break;
            }
            let px = x as f32 + 0.5;
            let k = ly * TILE + lx;
            let pix = y * ctx.w + x;
            let vc = [
                ctx.d_rgb[pix * 3],
                ctx.d_rgb[pix * 3 + 1],
                ctx.d_rgb[pix * 3 + 2],
            ];
            let va = ctx.d_alpha.map_or(0.0, |da| da[pix]);
            let t_final = ctx.t_final[k];
            for ch in 0..3 {
                v_bg[ch] += (vc[ch] * t_final) as f64;
            }
            let bg_dot = vc[0] * ctx.bg[0] + vc[1] * ctx.bg[1] + vc[2] * ctx.bg[2];
            let mut t = t_final;
            let mut behind = [0.0f32; 3];
            for j in (0..ctx.last[k] as usize).rev() {
                let dx = sc.x[j] - px;
                let dy = sc.y[j] - py;
                let sigma = 0.5 * (sc.a[j] * dx * dx + sc.c[j] * dy * dy) + sc.b[j] * dx * dy;
                if sigma < 0.0 {
                    continue;
                }
                let gauss = (-sigma).exp();
                let raw = sc.o[j] * gauss;
                let alpha = raw.min(rules.alpha_max);
                if alpha < rules.alpha_min {
                    continue;
                }
                let ra = 1.0 / (1.0 - alpha);
                t *= ra;
                let wgt = alpha * t;
                let col = sc.col[j];
                let gr = &mut grads[j];
                for ch in 0..3 {
                    gr.color[ch] += wgt * vc[ch];
                }
                let mut v_alpha = t_final * ra * (va - bg_dot);
                for ch in 0..3 {
                    v_alpha += vc[ch] * (col[ch] * t - behind[ch] * ra);
                }
                if raw <= rules.alpha_max {
                    let v_sigma = -raw * v_alpha;
                    gr.conic[0] += 0.5 * v_sigma * dx * dx;
                    gr.conic[1] += v_sigma * dx * dy;
                    gr.conic[2] += 0.5 * v_sigma * dy * dy;
                    gr.mean2d[0] += v_sigma * (sc.a[j] * dx + sc.b[j] * dy);
                    gr.mean2d[1] += v_sigma * (sc.b[j] * dx + sc.c[j] * dy);
                    gr.opacity += gauss * v_alpha;
                }
                for ch in 0..3 {
                    behind[ch] += col[ch] * wgt;
                }
            }
        }
    }
    v_bg
}

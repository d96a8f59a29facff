//! Slow, dense, f64 reference renderer with the same semantics as [`crate::Renderer`].
//!
//! No tiles: every pixel of every camera walks all non-culled Gaussians in increasing depth
//! (ties by index), exactly as the rules are written. The backward re-runs each pixel's forward,
//! records the contributing Gaussians and differentiates the compositing sum analytically back to
//! front; projection, SH and covariance gradients come from the shared f64 code. Use it for
//! tests and small scenes only: it costs O(C·H·W·N).

use crate::project::{self, Cam, GradSlices, Prep, Proj, ProjGrad};
use crate::surface::{RayDepth, SURFACE_TRANSMITTANCE};
use crate::{Camera, Gaussians, RenderSettings, SplatError, check_inputs};

/// Output of [`forward`], in f64.
#[derive(Clone, Debug)]
pub struct ReferenceOutput {
    pub width: usize,
    pub height: usize,
    pub num_cameras: usize,
    /// `[C,H,W,3]`.
    pub rgb: Vec<f64>,
    /// `[C,H,W]`.
    pub alpha: Vec<f64>,
    /// `[C,H,W]` expected depth (0 where nothing is drawn).
    pub depth: Vec<f64>,
    /// `[C,N,2]`; 0 means culled.
    pub radii: Vec<[i32; 2]>,
    /// `[C,N]` screen-space mean (pixels), conic (a, b, c) and camera depth; zero when culled.
    pub means2d: Vec<[f64; 2]>,
    pub conics: Vec<[f64; 3]>,
    pub depths: Vec<f64>,
}

/// Gradients from [`backward`], in f64; same meaning as [`crate::Gradients`].
#[derive(Clone, Debug, Default)]
pub struct ReferenceGradients {
    pub means: Vec<[f64; 3]>,
    pub quats: Vec<[f64; 4]>,
    pub log_scales: Vec<[f64; 3]>,
    pub opacity_logits: Vec<f64>,
    pub sh: Vec<[[f64; 3]; 16]>,
    pub backgrounds: Vec<[f64; 3]>,
    pub cam_rotation: Vec<[[f64; 3]; 3]>,
    pub cam_translation: Vec<[f64; 3]>,
    /// (dL/dfx, dL/dfy) per camera.
    pub cam_focal: Vec<[f64; 2]>,
    pub mean2d_grad_norm: Vec<f64>,
    pub visible_count: Vec<u32>,
}

struct Scene {
    cams: Vec<Cam>,
    preps: Vec<Option<Prep>>,
    /// `[C][N]`.
    projs: Vec<Vec<Option<Proj>>>,
    /// Per camera: non-culled Gaussians by increasing depth, ties by index.
    orders: Vec<Vec<usize>>,
    width: usize,
    height: usize,
}

fn build(
    g: &Gaussians,
    cams: &[Camera],
    backgrounds: &[[f32; 3]],
    s: &RenderSettings,
) -> Result<Scene, SplatError> {
    let (width, height) = check_inputs(g, cams, backgrounds)?;
    let cams: Vec<Cam> = cams.iter().map(Cam::new).collect();
    let preps: Vec<Option<Prep>> = (0..g.len()).map(|i| project::prepare(g, i)).collect();
    let mut projs = Vec::with_capacity(cams.len());
    let mut orders = Vec::with_capacity(cams.len());
    for cam in &cams {
        let p: Vec<Option<Proj>> = (0..g.len())
            .map(|i| {
                preps[i]
                    .as_ref()
                    .and_then(|prep| project::project(g, i, prep, cam, s))
            })
            .collect();
        let mut order: Vec<usize> = (0..g.len()).filter(|&i| p[i].is_some()).collect();
        // Stable sort: equal depths keep index order.
        order.sort_by(|&a, &b| {
            let da = p[a].as_ref().map_or(0.0, |v| v.depth);
            let db = p[b].as_ref().map_or(0.0, |v| v.depth);
            da.total_cmp(&db)
        });
        projs.push(p);
        orders.push(order);
    }
    Ok(Scene {
        cams,
        preps,
        projs,
        orders,
        width: width as usize,
        height: height as usize,
    })
}

/// One contribution to a pixel: Gaussian, its α, the transmittance before it, its Gaussian
/// falloff `exp(−σ)` and offset from the pixel centre.
struct Contribution {
    i: usize,
    alpha: f64,
    t: f64,
    gauss: f64,
    dx: f64,
    dy: f64,
}

/// Composites one pixel; returns (colour without background, final T, Σ w·z).
fn composite(
    scene: &Scene,
    c: usize,
    px: f64,
    py: f64,
    s: &RenderSettings,
    mut record: Option<&mut Vec<Contribution>>,
) -> ([f64; 3], f64, f64) {
    let mut t = 1.0;
    let mut col = [0.0; 3];
    let mut d = 0.0;
    for &i in &scene.orders[c] {
        let p = scene.projs[c][i]
            .as_ref()
            .expect("ordered Gaussians are projected");
        let dx = p.mean2d[0] - px;
        let dy = p.mean2d[1] - py;
        let [a, b, cc] = p.conic;
        let sigma = 0.5 * (a * dx * dx + cc * dy * dy) + b * dx * dy;
        if sigma < 0.0 {
            continue;
        }
        let gauss = (-sigma).exp();
        let alpha = (p.opacity * gauss).min(s.alpha_max as f64);
        if alpha < s.alpha_min as f64 {
            continue;
        }
        let next_t = t * (1.0 - alpha);
        if next_t <= s.transmittance_min as f64 {
            break;
        }
        if let Some(rec) = record.as_deref_mut() {
            rec.push(Contribution {
                i,
                alpha,
                t,
                gauss,
                dx,
                dy,
            });
        }
        for ch in 0..3 {
            col[ch] += p.color[ch] * alpha * t;
        }
        d += p.depth * alpha * t;
        t = next_t;
    }
    (col, t, d)
}

/// Renders every camera densely in f64.
pub fn forward(
    g: &Gaussians,
    cams: &[Camera],
    backgrounds: &[[f32; 3]],
    s: &RenderSettings,
) -> Result<ReferenceOutput, SplatError> {
    let scene = build(g, cams, backgrounds, s)?;
    let (w, h, nc, n) = (scene.width, scene.height, cams.len(), g.len());
    let mut out = ReferenceOutput {
        width: w,
        height: h,
        num_cameras: nc,
        rgb: vec![0.0; nc * h * w * 3],
        alpha: vec![0.0; nc * h * w],
        depth: vec![0.0; nc * h * w],
        radii: vec![[0, 0]; nc * n],
        means2d: vec![[0.0; 2]; nc * n],
        conics: vec![[0.0; 3]; nc * n],
        depths: vec![0.0; nc * n],
    };
    for c in 0..nc {
        for i in 0..n {
            if let Some(p) = &scene.projs[c][i] {
                out.radii[c * n + i] = p.radii;
                out.means2d[c * n + i] = p.mean2d;
                out.conics[c * n + i] = p.conic;
                out.depths[c * n + i] = p.depth;
            }
        }
        let bg = backgrounds[c].map(f64::from);
        for y in 0..h {
            for x in 0..w {
                let (col, t, d) = composite(&scene, c, x as f64 + 0.5, y as f64 + 0.5, s, None);
                let k = (c * h + y) * w + x;
                for ch in 0..3 {
                    out.rgb[k * 3 + ch] = col[ch] + t * bg[ch];
                }
                out.alpha[k] = 1.0 - t;
                out.depth[k] = if t < 1.0 { d / (1.0 - t) } else { 0.0 };
            }
        }
    }
    Ok(out)
}

/// Surface depth `[C,H,W]` ([`crate::surface`]): at each pixel, the ray depth of the Gaussian
/// that brings the transmittance to one half or below; 0 where it stays above.
pub fn surface_depth(
    g: &Gaussians,
    cams: &[Camera],
    s: &RenderSettings,
) -> Result<Vec<f64>, SplatError> {
    let scene = build(g, cams, &vec![[0.0; 3]; cams.len()], s)?;
    let (w, h) = (scene.width, scene.height);
    let mut out = vec![0.0; cams.len() * h * w];
    let mut contributions = Vec::new();
    for c in 0..cams.len() {
        for y in 0..h {
            for x in 0..w {
                let (px, py) = (x as f64 + 0.5, y as f64 + 0.5);
                contributions.clear();
                composite(&scene, c, px, py, s, Some(&mut contributions));
                let crossing = contributions
                    .iter()
                    .find(|k| k.t * (1.0 - k.alpha) <= SURFACE_TRANSMITTANCE);
                if let Some(k) = crossing
                    && let Some(ray) = RayDepth::new(g, k.i, &scene.cams[c])
                {
                    out[(c * h + y) * w + x] = ray.at(&scene.cams[c], px, py);
                }
            }
        }
    }
    Ok(out)
}

/// Gradients of `L` given `d_rgb = dL/drgb` `[C,H,W,3]` and optionally `d_alpha` `[C,H,W]`.
pub fn backward(
    g: &Gaussians,
    cams: &[Camera],
    backgrounds: &[[f32; 3]],
    s: &RenderSettings,
    d_rgb: &[f64],
    d_alpha: Option<&[f64]>,
) -> Result<ReferenceGradients, SplatError> {
    let scene = build(g, cams, backgrounds, s)?;
    let (w, h, nc, n) = (scene.width, scene.height, cams.len(), g.len());
    if d_rgb.len() != nc * h * w * 3 || d_alpha.is_some_and(|da| da.len() != nc * h * w) {
        return Err(SplatError::Shape(
            "d_rgb must be [C,H,W,3] and d_alpha [C,H,W]".into(),
        ));
    }
    let mut up = vec![ProjGrad::default(); nc * n];
    let mut v_bg = vec![[0.0f64; 3]; nc];
    let mut rec = Vec::new();
    for c in 0..nc {
        let bg = backgrounds[c].map(f64::from);
        for y in 0..h {
            for x in 0..w {
                rec.clear();
                let (_, t_final, _) =
                    composite(&scene, c, x as f64 + 0.5, y as f64 + 0.5, s, Some(&mut rec));
                let k = (c * h + y) * w + x;
                let vc = [d_rgb[k * 3], d_rgb[k * 3 + 1], d_rgb[k * 3 + 2]];
                let va = d_alpha.map_or(0.0, |da| da[k]);
                for ch in 0..3 {
                    v_bg[c][ch] += vc[ch] * t_final;
                }
                // out = Σ_j c_j α_j T_j + T_final·bg, alpha = 1 − T_final, T_j = Π_{i<j}(1 − α_i).
                let mut behind = [0.0f64; 3];
                for con in rec.iter().rev() {
                    let p = scene.projs[c][con.i]
                        .as_ref()
                        .expect("contributors are projected");
                    let u = &mut up[c * n + con.i];
                    let ra = 1.0 / (1.0 - con.alpha);
                    let mut v_alpha = 0.0;
                    for ch in 0..3 {
                        u.color[ch] += con.alpha * con.t * vc[ch];
                        v_alpha +=
                            vc[ch] * (p.color[ch] * con.t - (behind[ch] + t_final * bg[ch]) * ra);
                    }
                    v_alpha += va * t_final * ra;
                    if p.opacity * con.gauss <= s.alpha_max as f64 {
                        let v_sigma = -p.opacity * con.gauss * v_alpha;
                        let [a, b, cc] = p.conic;
                        let (dx, dy) = (con.dx, con.dy);
                        u.conic[0] += 0.5 * v_sigma * dx * dx;
                        u.conic[1] += v_sigma * dx * dy;
                        u.conic[2] += 0.5 * v_sigma * dy * dy;
                        u.mean2d[0] += v_sigma * (a * dx + b * dy);
                        u.mean2d[1] += v_sigma * (b * dx + cc * dy);
                        u.opacity += con.gauss * v_alpha;
                    }
                    for ch in 0..3 {
                        behind[ch] += p.color[ch] * con.alpha * con.t;
                    }
                }
            }
        }
    }
    let mut out = ReferenceGradients {
        means: vec![[0.0; 3]; n],
        quats: vec![[0.0; 4]; n],
        log_scales: vec![[0.0; 3]; n],
        opacity_logits: vec![0.0; n],
        sh: vec![[[0.0; 3]; 16]; n],
        backgrounds: v_bg,
        cam_rotation: Vec::new(),
        cam_translation: Vec::new(),
        cam_focal: Vec::new(),
        mean2d_grad_norm: vec![0.0; n],
        visible_count: vec![0; n],
    };
    let projs = &scene.projs;
    let upstream = |c: usize, i: usize| projs[c][i].as_ref().map(|_| up[c * n + i]);
    let cam_grads = project::backward_all(
        g,
        &scene.cams,
        &scene.preps,
        s,
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
    out.cam_rotation = cam_grads.iter().map(|cg| cg.r).collect();
    out.cam_translation = cam_grads.iter().map(|cg| cg.t).collect();
    out.cam_focal = cam_grads.iter().map(|cg| cg.focal).collect();
    Ok(out)
}

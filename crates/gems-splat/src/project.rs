//! Per-(camera, Gaussian) EWA projection, SH colour and opacity in f64, and their backward.
//!
//! Shared by the fast renderer and the reference: this work is O(C·N), small next to the
//! per-pixel work, and doing it in f64 keeps the two paths' screen-space inputs identical.

use crate::{Camera, Gaussians, RenderSettings, sh};

pub(crate) type Mat3 = [[f64; 3]; 3];

/// A camera converted to f64, with its centre.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Cam {
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
    pub width: f64,
    pub height: f64,
    pub r: Mat3,
    pub t: [f64; 3],
    pub center: [f64; 3],
}

impl Cam {
    pub fn new(c: &Camera) -> Cam {
        let r = c.rotation.map(|row| row.map(f64::from));
        let t = c.translation.map(f64::from);
        let center = [0, 1, 2].map(|i| -(r[0][i] * t[0] + r[1][i] * t[1] + r[2][i] * t[2]));
        Cam {
            fx: c.fx as f64,
            fy: c.fy as f64,
            cx: c.cx as f64,
            cy: c.cy as f64,
            width: c.width as f64,
            height: c.height as f64,
            r,
            t,
            center,
        }
    }
}

/// Camera-independent per-Gaussian quantities.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Prep {
    /// World covariance `R S Sᵀ Rᵀ`.
    pub cov: Mat3,
    /// `sigmoid(opacity_logit)`.
    pub opacity: f64,
}

/// Covariance and opacity of Gaussian `i`, or `None` when its parameters are not finite or its
/// quaternion is (nearly) zero, in which case it is culled everywhere.
pub(crate) fn prepare(g: &Gaussians, i: usize) -> Option<Prep> {
    let q = g.quats[i].map(f64::from);
    let ls = g.log_scales[i].map(f64::from);
    let m = g.means[i];
    let logit = g.opacity_logits[i] as f64;
    let qn2 = q.iter().map(|v| v * v).sum::<f64>();
    let finite = m.iter().all(|v| v.is_finite())
        && ls.iter().all(|v| v.is_finite())
        && logit.is_finite()
        && qn2.is_finite()
        && g.sh[i].iter().flatten().all(|v| v.is_finite());
    // Positive phrasing: NaN fails every test.
    if !(finite && qn2 > 1e-24) {
        return None;
    }
    let rq = quat_to_rot(normalize4(q));
    let s = ls.map(f64::exp);
    if !s.iter().all(|v| v.is_finite()) {
        return None;
    }
    let mut cov = [[0.0; 3]; 3];
    for a in 0..3 {
        for b in 0..3 {
            cov[a][b] = (0..3).map(|k| rq[a][k] * s[k] * s[k] * rq[b][k]).sum();
        }
    }
    Some(Prep {
        cov,
        opacity: crate::activation::sigmoid_f64(logit),
    })
}

/// Screen-space result of projecting one Gaussian into one camera.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Proj {
    pub mean2d: [f64; 2],
    pub conic: [f64; 3],
    pub depth: f64,
    pub radii: [i32; 2],
    /// Opacity used for compositing (times the compensation in antialiased mode).
    pub opacity: f64,
    pub color: [f64; 3],
    /// Half extent (pixels, per axis) of the region where α can reach `alpha_min`: the
    /// bounding box of the ellipse `σ = ln(opacity / alpha_min)` (with a 1% margin against
    /// rounding), capped by the radius. Outside it a pixel skips this Gaussian anyway, so the
    /// fast path may ignore it there without changing any output.
    pub extent: [f64; 2],
}

struct Geometry {
    pc: [f64; 3],
    j: [[f64; 3]; 2],
    cov_c: Mat3,
    /// 2D covariance before the low-pass filter, (xx, xy, yy).
    cov2d: [f64; 3],
    clamped: [bool; 2],
}

fn geometry(mean: [f64; 3], cov: &Mat3, cam: &Cam) -> Geometry {
    let pc = add3(matvec(&cam.r, mean), cam.t);
    let cov_c = mul3(&mul3(&cam.r, cov), &transpose(&cam.r));
    let [x, y, z] = pc;
    let tan_fovx = 0.5 * cam.width / cam.fx;
    let tan_fovy = 0.5 * cam.height / cam.fy;
    let lim_x_pos = (cam.width - cam.cx) / cam.fx + 0.3 * tan_fovx;
    let lim_x_neg = cam.cx / cam.fx + 0.3 * tan_fovx;
    let lim_y_pos = (cam.height - cam.cy) / cam.fy + 0.3 * tan_fovy;
    let lim_y_neg = cam.cy / cam.fy + 0.3 * tan_fovy;
    let rx = x / z;
    let ry = y / z;
    let cxr = rx.clamp(-lim_x_neg, lim_x_pos);
    let cyr = ry.clamp(-lim_y_neg, lim_y_pos);
    let tx = z * cxr;
    let ty = z * cyr;
    let j = [
        [cam.fx / z, 0.0, -cam.fx * tx / (z * z)],
        [0.0, cam.fy / z, -cam.fy * ty / (z * z)],
    ];
    let mut cov2d_m = [[0.0; 2]; 2];
    for a in 0..2 {
        for b in 0..2 {
            let mut s = 0.0;
            for k in 0..3 {
                for l in 0..3 {
                    s += j[a][k] * cov_c[k][l] * j[b][l];
                }
            }
            cov2d_m[a][b] = s;
        }
    }
    Geometry {
        pc,
        j,
        cov_c,
        cov2d: [
            cov2d_m[0][0],
            0.5 * (cov2d_m[0][1] + cov2d_m[1][0]),
            cov2d_m[1][1],
        ],
        clamped: [cxr != rx, cyr != ry],
    }
}

/// Projects Gaussian `i` into `cam`. `None` means culled (radius 0).
pub(crate) fn project(
    g: &Gaussians,
    i: usize,
    prep: &Prep,
    cam: &Cam,
    s: &RenderSettings,
) -> Option<Proj> {
    let mean = g.means[i].map(f64::from);
    let geo = geometry(mean, &prep.cov, cam);
    let z = geo.pc[2];
    if !(z > s.near_plane as f64 && z < s.far_plane as f64) {
        return None;
    }
    let eps = s.eps2d as f64;
    let [a0, b0, c0] = geo.cov2d;
    let (a, b, c) = (a0 + eps, b0, c0 + eps);
    let det = a * c - b * b;
    if !(det > 0.0 && det.is_finite()) {
        return None;
    }
    let conic = [c / det, -b / det, a / det];
    let mean2d = [
        cam.fx * geo.pc[0] / z + cam.cx,
        cam.fy * geo.pc[1] / z + cam.cy,
    ];
    let ext = s.radius_extent as f64;
    let rx = (ext * a.sqrt()).ceil();
    let ry = (ext * c.sqrt()).ceil();
    let inside = mean2d[0] + rx > 0.0
        && mean2d[0] - rx < cam.width
        && mean2d[1] + ry > 0.0
        && mean2d[1] - ry < cam.height;
    if !(inside && rx > 0.0 && ry > 0.0) {
        return None;
    }
    let comp = if s.antialiased {
        ((a0 * c0 - b0 * b0) / det).max(0.0).sqrt()
    } else {
        1.0
    };
    let dir = sub3(mean, cam.center);
    let color = sh::color(g.sh_degree, &g.sh[i], dir);
    let opacity = prep.opacity * comp;
    let mut extent = [rx, ry];
    if s.alpha_min > 0.0 {
        let thr = (opacity / s.alpha_min as f64).ln() * 1.01 + 1e-3;
        let e = [(2.0 * thr * a).sqrt(), (2.0 * thr * c).sqrt()];
        for k in 0..2 {
            // thr < 0 (NaN root) means α never reaches alpha_min: nothing to draw.
            extent[k] = if thr > 0.0 { e[k].min(extent[k]) } else { 0.0 };
        }
    }
    // Radii above i32 range cannot occur for an on-screen Gaussian worth drawing; saturate.
    let clamp_i32 = |v: f64| v.min(i32::MAX as f64) as i32;
    Some(Proj {
        mean2d,
        conic,
        depth: z,
        radii: [clamp_i32(rx), clamp_i32(ry)],
        opacity,
        color,
        extent,
    })
}

/// Upstream gradient of one projected Gaussian in one camera.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct ProjGrad {
    pub mean2d: [f64; 2],
    pub conic: [f64; 3],
    pub opacity: f64,
    pub color: [f64; 3],
}

impl ProjGrad {
    /// Every component exactly zero: the projection's backward, linear in this gradient, would
    /// add only zeros (a Gaussian hidden behind opaque ones, or a camera given no upstream
    /// gradient), so it is skipped.
    fn is_zero(&self) -> bool {
        self.mean2d
            .iter()
            .chain(&self.conic)
            .chain(&self.color)
            .chain(std::iter::once(&self.opacity))
            .all(|&v| v == 0.0)
    }
}

/// Gradient of one Gaussian, before the quaternion/scale chain (world covariance kept).
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct GaussAcc {
    pub mean: [f64; 3],
    pub cov: Mat3,
    pub opacity_logit: f64,
    pub sh: [[f64; 3]; 16],
}

/// Gradient of one camera: its pose and its focal lengths.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct CamAcc {
    pub r: Mat3,
    pub t: [f64; 3],
    /// (dL/dfx, dL/dfy).
    pub focal: [f64; 2],
}

impl CamAcc {
    pub fn add(&mut self, o: &CamAcc) {
        for a in 0..2 {
            self.focal[a] += o.focal[a];
        }
        for a in 0..3 {
            self.t[a] += o.t[a];
            for b in 0..3 {
                self.r[a][b] += o.r[a][b];
            }
        }
    }
}

/// Where [`project_backward`] adds the gradients of one (camera, Gaussian) pair.
pub(crate) struct PairAcc<'a> {
    /// The Gaussian's parameter gradients (summed over cameras).
    pub gauss: &'a mut GaussAcc,
    /// The camera's pose gradient (summed over Gaussians).
    pub cam: &'a mut CamAcc,
}

/// Backward of [`project`] for Gaussian `i` of `g` (prepared as `prep`), which was not culled:
/// accumulates into `acc`.
pub(crate) fn project_backward(
    g: &Gaussians,
    i: usize,
    prep: &Prep,
    cam: &Cam,
    s: &RenderSettings,
    v: &ProjGrad,
    acc: PairAcc<'_>,
) {
    let PairAcc { gauss: ga, cam: ca } = acc;
    let mean = g.means[i].map(f64::from);
    let geo = geometry(mean, &prep.cov, cam);
    let [x, y, z] = geo.pc;
    let eps = s.eps2d as f64;
    let [a0, b0, c0] = geo.cov2d;
    let (a, b, c) = (a0 + eps, b0, c0 + eps);
    let det = a * c - b * b;
    let comp = if s.antialiased {
        ((a0 * c0 - b0 * b0) / det).max(0.0).sqrt()
    } else {
        1.0
    };

    // Opacity = sigmoid(logit) · comp.
    let sig = prep.opacity;
    ga.opacity_logit += v.opacity * comp * sig * (1.0 - sig);

    // Colour through SH and the view direction (mean − centre, centre = −Rᵀt).
    let dir = sub3(mean, cam.center);
    let v_dir = sh::color_backward(g.sh_degree, &g.sh[i], dir, v.color, &mut ga.sh);
    let mut v_mean = v_dir;
    // centre_i = −Σ_j R_ji t_j.
    for j in 0..3 {
        for ii in 0..3 {
            ca.r[j][ii] += v_dir[ii] * cam.t[j];
        }
        ca.t[j] += (0..3).map(|ii| cam.r[j][ii] * v_dir[ii]).sum::<f64>();
    }

    // Conic (inverse of the filtered covariance) → filtered covariance (xx, xy, yy).
    let d2 = det * det;
    let [va, vb, vc] = v.conic;
    let mut g_xx = va * (-c * c / d2) + vb * (b * c / d2) + vc * (1.0 / det - a * c / d2);
    let mut g_yy = va * (1.0 / det - a * c / d2) + vb * (a * b / d2) + vc * (-a * a / d2);
    let mut g_xy =
        va * (2.0 * b * c / d2) + vb * (-1.0 / det - 2.0 * b * b / d2) + vc * (2.0 * a * b / d2);
    if s.antialiased && comp > 0.0 {
        // comp² = det0 / det with det0 the unfiltered determinant.
        let v_comp = v.opacity * sig;
        let det0 = a0 * c0 - b0 * b0;
        let k = v_comp / (2.0 * comp);
        g_xx += k * (c0 * det - det0 * c) / d2;
        g_yy += k * (a0 * det - det0 * a) / d2;
        g_xy += k * (-2.0 * b0 * det + det0 * 2.0 * b) / d2;
    }
    // Symmetric matrix gradient of Σ2D = J Σc Jᵀ.
    let gm = [[g_xx, 0.5 * g_xy], [0.5 * g_xy, g_yy]];
    let j = &geo.j;
    let mut v_cov_c = [[0.0; 3]; 3];
    for k in 0..3 {
        for l in 0..3 {
            let mut acc = 0.0;
            for p in 0..2 {
                for q in 0..2 {
                    acc += j[p][k] * gm[p][q] * j[q][l];
                }
            }
            v_cov_c[k][l] = acc;
        }
    }
    // v_J = 2 G J Σc.
    let mut v_j = [[0.0; 3]; 2];
    for p in 0..2 {
        for k in 0..3 {
            let mut acc = 0.0;
            for q in 0..2 {
                for l in 0..3 {
                    acc += gm[p][q] * j[q][l] * geo.cov_c[l][k];
                }
            }
            v_j[p][k] = 2.0 * acc;
        }
    }
    let (fx, fy) = (cam.fx, cam.fy);
    let tx = -j[0][2] * z * z / fx;
    let ty = -j[1][2] * z * z / fy;
    let z2 = z * z;
    let z3 = z2 * z;
    let mut v_pc = [0.0; 3];
    v_pc[2] += -fx / z2 * v_j[0][0] - fy / z2 * v_j[1][1]
        + 2.0 * fx * tx / z3 * v_j[0][2]
        + 2.0 * fy * ty / z3 * v_j[1][2];
    let v_tx = -fx / z2 * v_j[0][2];
    let v_ty = -fy / z2 * v_j[1][2];
    if geo.clamped[0] {
        // tx = z · limit.
        v_pc[2] += v_tx * (tx / z);
    } else {
        v_pc[0] += v_tx;
    }
    if geo.clamped[1] {
        v_pc[2] += v_ty * (ty / z);
    } else {
        v_pc[1] += v_ty;
    }
    // Focal lengths. Each row of J is its focal times a focal-free row, except the last entry
    // of a clamped coordinate: there t = z·limit with limit ∝ 1/f, so f·t is focal-free.
    // (The screen extent and the culling depend on f too but, as in gsplat, carry no gradient.)
    for (p, f) in [fx, fy].into_iter().enumerate() {
        let last = if geo.clamped[p] {
            0.0
        } else {
            v_j[p][2] * j[p][2]
        };
        ca.focal[p] += (v_j[p][p] * j[p][p] + last) / f;
    }
    ca.focal[0] += v.mean2d[0] * x / z;
    ca.focal[1] += v.mean2d[1] * y / z;
    // Mean: u = fx x/z + cx, v = fy y/z + cy.
    v_pc[0] += fx / z * v.mean2d[0];
    v_pc[1] += fy / z * v.mean2d[1];
    v_pc[2] += -fx * x / z2 * v.mean2d[0] - fy * y / z2 * v.mean2d[1];

    // Camera frame → world and pose.
    let r = &cam.r;
    for a in 0..3 {
        v_mean[a] += (0..3).map(|k| r[k][a] * v_pc[k]).sum::<f64>();
        ca.t[a] += v_pc[a];
        for bb in 0..3 {
            ca.r[a][bb] += v_pc[a] * mean[bb];
        }
    }
    // Σc = R Σ Rᵀ: v_R += 2 v_Σc R Σ (both symmetric); v_Σ = Rᵀ v_Σc R.
    let r_cov = mul3(r, &prep.cov);
    let t1 = mul3(&v_cov_c, &r_cov);
    let v_cov_w = mul3(&mul3(&transpose(r), &v_cov_c), r);
    for a in 0..3 {
        for bb in 0..3 {
            ca.r[a][bb] += 2.0 * t1[a][bb];
            ga.cov[a][bb] += v_cov_w[a][bb];
        }
    }
    for a in 0..3 {
        ga.mean[a] += v_mean[a];
    }
}

/// Chains a world-covariance gradient to the raw quaternion and the log-scales.
pub(crate) fn cov_backward(
    quat: [f32; 4],
    log_scale: [f32; 3],
    v_cov: &Mat3,
) -> ([f64; 4], [f64; 3]) {
    let q = quat.map(f64::from);
    let qn = normalize4(q);
    let rq = quat_to_rot(qn);
    let s = log_scale.map(|v| (v as f64).exp());
    // Σ = M Mᵀ with M = Rq S: v_M = (G + Gᵀ) M.
    let mut m = [[0.0; 3]; 3];
    for a in 0..3 {
        for k in 0..3 {
            m[a][k] = rq[a][k] * s[k];
        }
    }
    let gs = [0, 1, 2].map(|a| [0, 1, 2].map(|b| v_cov[a][b] + v_cov[b][a]));
    let v_m = mul3(&gs, &m);
    let mut v_rq = [[0.0; 3]; 3];
    let mut v_ls = [0.0; 3];
    for a in 0..3 {
        for k in 0..3 {
            v_rq[a][k] = v_m[a][k] * s[k];
            v_ls[k] += rq[a][k] * v_m[a][k] * s[k];
        }
    }
    let [w, x, y, z] = qn;
    // d R / d (w, x, y, z) contracted with v_rq.
    let vr = v_rq;
    let v_w = 2.0
        * (-z * vr[0][1] + y * vr[0][2] + z * vr[1][0] - x * vr[1][2] - y * vr[2][0]
            + x * vr[2][1]);
    let v_x = 2.0
        * (y * vr[0][1] + z * vr[0][2] + y * vr[1][0] - 2.0 * x * vr[1][1] - w * vr[1][2]
            + z * vr[2][0]
            + w * vr[2][1]
            - 2.0 * x * vr[2][2]);
    let v_y = 2.0
        * (-2.0 * y * vr[0][0] + x * vr[0][1] + w * vr[0][2] + x * vr[1][0] + z * vr[1][2]
            - w * vr[2][0]
            + z * vr[2][1]
            - 2.0 * y * vr[2][2]);
    let v_z = 2.0
        * (-2.0 * z * vr[0][0] - w * vr[0][1] + x * vr[0][2] + w * vr[1][0] - 2.0 * z * vr[1][1]
            + y * vr[1][2]
            + x * vr[2][0]
            + y * vr[2][1]);
    let v_qn = [v_w, v_x, v_y, v_z];
    let n = q.iter().map(|v| v * v).sum::<f64>().sqrt();
    let dot: f64 = (0..4).map(|k| v_qn[k] * qn[k]).sum();
    let v_q = [0, 1, 2, 3].map(|k| (v_qn[k] - dot * qn[k]) / n);
    (v_q, v_ls)
}

pub(crate) fn quat_to_rot(q: [f64; 4]) -> Mat3 {
    let [w, x, y, z] = q;
    [
        [
            1.0 - 2.0 * (y * y + z * z),
            2.0 * (x * y - w * z),
            2.0 * (x * z + w * y),
        ],
        [
            2.0 * (x * y + w * z),
            1.0 - 2.0 * (x * x + z * z),
            2.0 * (y * z - w * x),
        ],
        [
            2.0 * (x * z - w * y),
            2.0 * (y * z + w * x),
            1.0 - 2.0 * (x * x + y * y),
        ],
    ]
}

fn normalize4(q: [f64; 4]) -> [f64; 4] {
    let n = q.iter().map(|v| v * v).sum::<f64>().sqrt();
    q.map(|v| v / n)
}

pub(crate) fn mul3(a: &Mat3, b: &Mat3) -> Mat3 {
    let mut o = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            o[i][j] = (0..3).map(|k| a[i][k] * b[k][j]).sum();
        }
    }
    o
}

pub(crate) fn transpose(a: &Mat3) -> Mat3 {
    [0, 1, 2].map(|i| [0, 1, 2].map(|j| a[j][i]))
}

pub(crate) fn matvec(a: &Mat3, v: [f64; 3]) -> [f64; 3] {
    [0, 1, 2].map(|i| a[i][0] * v[0] + a[i][1] * v[1] + a[i][2] * v[2])
}

fn add3(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

fn sub3(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// Conversion from the f64 accumulators to an output precision.
pub(crate) trait Real: Copy + Send + Sync {
    fn from_f64(v: f64) -> Self;
}

impl Real for f32 {
    fn from_f64(v: f64) -> Self {
        v as f32
    }
}

impl Real for f64 {
    fn from_f64(v: f64) -> Self {
        v
    }
}

/// Per-Gaussian output gradient arrays (all of length N).
pub(crate) struct GradSlices<'a, T> {
    pub means: &'a mut [[T; 3]],
    pub quats: &'a mut [[T; 4]],
    pub log_scales: &'a mut [[T; 3]],
    pub opacity_logits: &'a mut [T],
    pub sh: &'a mut [[[T; 3]; 16]],
    pub mean2d_grad_norm: &'a mut [T],
    pub visible_count: &'a mut [u32],
}

/// Gaussians per parallel work item of [`backward_all`]; fixed so that the pose-gradient sums
/// are added in the same order whatever the number of threads.
const GRAD_CHUNK: usize = 512;

/// Projection/SH/covariance backward for every Gaussian in every camera. `upstream(c, i)` gives
/// the screen-space gradient of Gaussian `i` in camera `c`, `None` when it was culled there.
/// Writes the per-Gaussian gradients and returns the pose gradient of each camera.
pub(crate) fn backward_all<T: Real>(
    g: &Gaussians,
    cams: &[Cam],
    preps: &[Option<Prep>],
    s: &RenderSettings,
    upstream: &(dyn Fn(usize, usize) -> Option<ProjGrad> + Sync),
    out: GradSlices<'_, T>,
) -> Vec<CamAcc> {
    use rayon::prelude::*;
    let cam_parts: Vec<Vec<CamAcc>> = (
        out.means.par_chunks_mut(GRAD_CHUNK),
        out.quats.par_chunks_mut(GRAD_CHUNK),
        out.log_scales.par_chunks_mut(GRAD_CHUNK),
        out.opacity_logits.par_chunks_mut(GRAD_CHUNK),
        out.sh.par_chunks_mut(GRAD_CHUNK),
        out.mean2d_grad_norm.par_chunks_mut(GRAD_CHUNK),
        out.visible_count.par_chunks_mut(GRAD_CHUNK),
    )
        .into_par_iter()
        .enumerate()
        .map(
            |(chunk, (means, quats, log_scales, opac, shs, norms, counts))| {
                let mut cam_acc = vec![CamAcc::default(); cams.len()];
                for k in 0..means.len() {
                    let i = chunk * GRAD_CHUNK + k;
                    let mut ga = GaussAcc::default();
                    let mut norm = 0.0;
                    let mut count = 0u32;
                    if let Some(prep) = &preps[i] {
                        for (c, cam) in cams.iter().enumerate() {
                            if let Some(v) = upstream(c, i) {
                                count += 1;
                                norm += v.mean2d[0].hypot(v.mean2d[1]);
                                if v.is_zero() {
                                    continue;
                                }
                                let acc = PairAcc {
                                    gauss: &mut ga,
                                    cam: &mut cam_acc[c],
                                };
                                project_backward(g, i, prep, cam, s, &v, acc);
                            }
                        }
                    }
                    let (v_q, v_ls) = if count > 0 {
                        cov_backward(g.quats[i], g.log_scales[i], &ga.cov)
                    } else {
                        ([0.0; 4], [0.0; 3])
                    };
                    means[k] = ga.mean.map(T::from_f64);
                    quats[k] = v_q.map(T::from_f64);
                    log_scales[k] = v_ls.map(T::from_f64);
                    opac[k] = T::from_f64(ga.opacity_logit);
                    shs[k] = ga.sh.map(|row| row.map(T::from_f64));
                    norms[k] = T::from_f64(norm);
                    counts[k] = count;
                }
                cam_acc
            },
        )
        .collect();
    let mut total = vec![CamAcc::default(); cams.len()];
    for part in &cam_parts {
        for (t, p) in total.iter_mut().zip(part) {
            t.add(p);
        }
    }
    total
}

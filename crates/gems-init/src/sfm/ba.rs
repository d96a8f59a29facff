//! Robust bundle adjustment: Levenberg–Marquardt on poses, points and (optionally) a shared focal
//! length, with Huber-weighted reprojection residuals and a Schur complement over the points.
//!
//! The reduced camera system is dense (6 per free camera + 1 for the focal), which is small for
//! the ≤ 100 views this initialiser is meant for. The sum over points is done in fixed-size
//! chunks in parallel and reduced in chunk order, so the result does not depend on the number
//! of threads.

use gems_math::{Intrinsics, Se3, so3_left_jacobian_inv};
use nalgebra::{DMatrix, DVector, Matrix2x3, Matrix3, Rotation3, SMatrix, Vector2, Vector3};
use rayon::prelude::*;

/// One image measurement of a point, in pixels of the working level.
#[derive(Clone, Copy, Debug)]
pub struct Observation {
    pub cam: usize,
    pub point: usize,
    pub xy: Vector2<f64>,
}

/// Pinhole projection for the SfM. Its camera has one focal for both axes (fx = fy, which
/// [`bundle_adjust`] refines together) and the principal point held fixed.
pub trait Pinhole {
    /// Camera-frame point to pixels.
    fn project(&self, xc: &Vector3<f64>) -> Vector2<f64>;
    /// Pixel to normalised image coordinates.
    fn normalise(&self, p: &Vector2<f64>) -> Vector2<f64>;
}

impl Pinhole for Intrinsics {
    #[inline]
    fn project(&self, xc: &Vector3<f64>) -> Vector2<f64> {
        Vector2::new(
            self.fx * xc.x / xc.z + self.cx,
            self.fy * xc.y / xc.z + self.cy,
        )
    }
    #[inline]
    fn normalise(&self, p: &Vector2<f64>) -> Vector2<f64> {
        Vector2::new((p.x - self.cx) / self.fx, (p.y - self.cy) / self.fy)
    }
}

/// What [`bundle_adjust`] does with the shared focal.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Focal {
    /// Held at its value.
    Fixed,
    /// Refined with the poses and points.
    Free,
    /// Refined under a Gaussian prior: the cost gains ½((f − focal)/sigma)², both in pixels. A
    /// focal from EXIF is known to a few percent (the focal length and sensor size a camera
    /// writes are rounded, and a 35 mm equivalent is approximate); the photos may know it better.
    Prior { focal: f64, sigma: f64 },
}

impl Focal {
    fn refined(self) -> bool {
        self != Focal::Fixed
    }

    /// The prior's cost at focal `f`.
    fn cost(self, f: f64) -> f64 {
        match self {
            Focal::Prior { focal, sigma } => 0.5 * ((f - focal) / sigma).powi(2),
            Focal::Fixed | Focal::Free => 0.0,
        }
    }
}

/// Settings for [`bundle_adjust`].
#[derive(Clone, Copy, Debug)]
pub struct BaOptions<'a> {
    pub huber_px: f64,
    pub max_iters: usize,
    pub focal: Focal,
    /// Smooth motion in capture order, when the images are known to be ordered.
    pub path: Option<&'a PathPrior>,
}

/// A weak prior that the camera moves smoothly from one capture to the next (video frames,
/// photos numbered as they were taken). For every three consecutive captures a, b, c it
/// penalises
/// - the centres' second difference c_a − 2 c_b + c_c, in units of `centre_sigma` times the
///   mean distance between consecutive cameras (so the prior does not depend on the
///   reconstruction's free scale: the mean is taken at the current cameras and held while a
///   step is linearised), and
/// - the change of the rotation step, Log(R_b R_cᵀ) − Log(R_a R_bᵀ) (each step in the body
///   frame of the earlier camera; equal for a constant angular velocity), in units of
///   `rotation_sigma` radians.
///
/// Each residual is Huber-weighted at 1σ, so a capture that jumps (a dropped frame, a photo
/// taken from elsewhere) costs linearly instead of bending its neighbours. The same idea as a
/// motion prior between consecutive keyframes in visual odometry; COLMAP has no counterpart.
#[derive(Clone, Debug, PartialEq)]
pub struct PathPrior {
    /// Cameras in capture order. A triple takes part only when all three are in the adjustment
    /// (observed), so an unregistered frame splits the path instead of joining its neighbours.
    pub order: Vec<usize>,
    /// σ of the centres' second difference as a fraction of the mean step; 0 leaves centres out.
    pub centre_sigma: f64,
    /// σ of the change of the rotation step, radians; 0 leaves rotations out.
    pub rotation_sigma: f64,
}

/// One residual of [`PathPrior`] (in units of its σ) and its Jacobians with respect to the
/// three cameras' (ω, v), the update of [`bundle_adjust`].
struct PathResidual {
    cams: [usize; 3],
    r: Vector3<f64>,
    j: [SMatrix<f64, 3, 6>; 3],
}

impl PathPrior {
    /// Consecutive triples of cameras all present in the adjustment.
    fn triples<'a>(&'a self, present: &'a [bool]) -> impl Iterator<Item = [usize; 3]> + 'a {
        self.order
            .windows(3)
            .filter(|w| w.iter().all(|&c| present[c]))
            .map(|w| [w[0], w[1], w[2]])
    }

    /// Mean distance between consecutive present cameras; `None` when there is none or the
    /// cameras coincide.
    fn mean_step(&self, poses: &[Se3], present: &[bool]) -> Option<f64> {
        let (mut sum, mut n) = (0.0, 0usize);
        for w in self.order.windows(2) {
            if present[w[0]] && present[w[1]] {
                sum += (camera_center(&poses[w[1]]) - camera_center(&poses[w[0]])).norm();
                n += 1;
            }
        }
        (n > 0 && sum > 0.0).then(|| sum / n as f64)
    }

    fn residuals(&self, poses: &[Se3], present: &[bool], mean_step: f64) -> Vec<PathResidual> {
        let mut out = Vec::new();
        for cams in self.triples(present) {
            let [a, b, c] = cams.map(|i| &poses[i]);
            if self.centre_sigma > 0.0 {
                let s = 1.0 / (self.centre_sigma * mean_step);
                let r = (camera_center(a) - 2.0 * camera_center(b) + camera_center(c)) * s;
                // c = −Rᵀt; under R ← exp(ω)R, t ← t + v: dc/dω = −Rᵀ[t]×, dc/dv = −Rᵀ.
                let dc = |p: &Se3, k: f64| {
                    let mut j = SMatrix::<f64, 3, 6>::zeros();
                    j.fixed_view_mut::<3, 3>(0, 0)
                        .copy_from(&(-p.rot.transpose() * p.trans.cross_matrix() * (k * s)));
                    j.fixed_view_mut::<3, 3>(0, 3)
                        .copy_from(&(-p.rot.transpose() * (k * s)));
                    j
                };
                out.push(PathResidual {
                    cams,
                    r,
                    j: [dc(a, 1.0), dc(b, -2.0), dc(c, 1.0)],
                });
            }
            if self.rotation_sigma > 0.0 {
                let s = 1.0 / self.rotation_sigma;
                let m_ab = a.rot * b.rot.transpose();
                let m_bc = b.rot * c.rot.transpose();
                let (phi_ab, phi_bc) = (log_rotation(&m_ab), log_rotation(&m_bc));
                // Log(exp(ω_a) M exp(−ω_b)) ≈ φ + J_l⁻¹(φ)(ω_a − M ω_b).
                let (ja, jb) = (
                    so3_left_jacobian_inv(&phi_ab),
                    so3_left_jacobian_inv(&phi_bc),
                );
                let rot_block = |m: Matrix3<f64>| {
                    let mut j = SMatrix::<f64, 3, 6>::zeros();
                    j.fixed_view_mut::<3, 3>(0, 0).copy_from(&(m * s));
                    j
                };
                out.push(PathResidual {
                    cams,
                    r: (phi_bc - phi_ab) * s,
                    j: [
                        rot_block(-ja),
                        rot_block(jb + ja * m_ab),
                        rot_block(-jb * m_bc),
                    ],
                });
            }
        }
        out
    }

    /// The prior's robust cost at `poses`.
    pub fn cost(&self, poses: &[Se3], present: &[bool]) -> f64 {
        let Some(step) = self.mean_step(poses, present) else {
            return 0.0;
        };
        self.residuals(poses, present, step)
            .iter()
            .map(|r| huber_cost(r.r.norm_squared(), 1.0))
            .sum()
    }

    /// Adds the prior's Gauss–Newton terms (Huber-weighted JᵀJ and Jᵀr) to the reduced system.
    fn add_to(&self, system: &mut SchurSystem, poses: &[Se3], layout: &ParamLayout) {
        let Some(step) = self.mean_step(poses, &layout.present) else {
            return;
        };
        for res in self.residuals(poses, &layout.present, step) {
            let w = huber_weight(res.r.norm_squared(), 1.0);
            for (x, jx) in res.cams.iter().zip(&res.j) {
                let cx = layout.cam_col[*x];
                if cx == usize::MAX {
                    continue;
                }
                let g = jx.transpose() * res.r * w;
                for i in 0..6 {
                    system.b[cx + i] += g[i];
                }
                for (y, jy) in res.cams.iter().zip(&res.j) {
                    let cy = layout.cam_col[*y];
                    if cy == usize::MAX {
                        continue;
                    }
                    let h = jx.transpose() * jy * w;
                    for i in 0..6 {
                        for k in 0..6 {
                            system.s[(cx + i, cy + k)] += h[(i, k)];
                        }
                    }
                }
            }
        }
    }
}

#[inline]
fn camera_center(p: &Se3) -> Vector3<f64> {
    -(p.rot.transpose() * p.trans)
}

#[inline]
fn log_rotation(m: &Matrix3<f64>) -> Vector3<f64> {
    Rotation3::from_matrix_unchecked(*m).scaled_axis()
}

/// Outcome of [`bundle_adjust`]: robust cost before and after, iterations run.
#[derive(Clone, Copy, Debug)]
pub struct BaSummary {
    pub initial_cost: f64,
    pub final_cost: f64,
    pub iterations: usize,
}

#[inline]
fn huber_cost(r2: f64, d: f64) -> f64 {
    let r = r2.sqrt();
    if r <= d { 0.5 * r2 } else { d * (r - 0.5 * d) }
}

#[inline]
fn huber_weight(r2: f64, d: f64) -> f64 {
    let r = r2.sqrt();
    if r <= d { 1.0 } else { d / r }
}

/// Robust cost of the whole problem; observations behind a camera cost as a large residual.
pub fn total_cost(
    poses: &[Se3],
    points: &[Vector3<f64>],
    obs: &[Observation],
    k: &Intrinsics,
    huber_px: f64,
) -> f64 {
    obs.iter()
        .map(|o| {
            let xc = poses[o.cam].act(&points[o.point]);
            if xc.z <= 1e-9 {
                return huber_cost(1e6, huber_px);
            }
            huber_cost((k.project(&xc) - o.xy).norm_squared(), huber_px)
        })
        .sum()
}

/// Per-observation Jacobians and residual. Camera block columns: ω (3), v (3), f (1).
struct Lin {
    jc: SMatrix<f64, 2, 7>,
    jp: Matrix2x3<f64>,
    r: Vector2<f64>,
    w: f64,
}

fn linearise(
    pose: &Se3,
    x: &Vector3<f64>,
    o: &Vector2<f64>,
    k: &Intrinsics,
    huber: f64,
) -> Option<Lin> {
    let rx = pose.rot * x;
    let xc = rx + pose.trans;
    if xc.z <= 1e-9 {
        return None;
    }
    let iz = 1.0 / xc.z;
    let (xn, yn) = (xc.x * iz, xc.y * iz);
    let r = Vector2::new(k.fx * xn + k.cx - o.x, k.fy * yn + k.cy - o.y);
    let dpi = Matrix2x3::new(
        k.fx * iz,
        0.0,
        -k.fx * xn * iz,
        0.0,
        k.fy * iz,
        -k.fy * yn * iz,
    );
    let mut jc = SMatrix::<f64, 2, 7>::zeros();
    jc.fixed_view_mut::<2, 3>(0, 0)
        .copy_from(&(dpi * (-rx.cross_matrix())));
    jc.fixed_view_mut::<2, 3>(0, 3).copy_from(&dpi);
    jc[(0, 6)] = xn;
    jc[(1, 6)] = yn;
    let jp = dpi * pose.rot;
    Some(Lin {
        jc,
        jp,
        r,
        w: huber_weight(r.norm_squared(), huber),
    })
}

/// Bundle-adjust `poses` (indexed by `Observation::cam`), `points` and the focal `k.fx = k.fy` in place.
/// Cameras with `fixed[c]` keep their pose (the gauge); cameras without observations are untouched.
pub fn bundle_adjust(
    poses: &mut [Se3],
    fixed: &[bool],
    points: &mut [Vector3<f64>],
    obs: &[Observation],
    k: &mut Intrinsics,
    opts: &BaOptions,
) -> BaSummary {
    let layout = ParamLayout::new(poses.len(), fixed, obs, opts.focal.refined());
    let by_point = PointObservations::new(points.len(), obs);
    let cost_of = |poses: &[Se3], points: &[Vector3<f64>], k: &Intrinsics| {
        total_cost(poses, points, obs, k, opts.huber_px)
            + opts.focal.cost(k.fx)
            + opts.path.map_or(0.0, |p| p.cost(poses, &layout.present))
    };
    let initial_cost = cost_of(poses, points, k);
    let mut cost = initial_cost;
    let mut lambda = 1e-3;
    let mut iterations = 0;

    for _ in 0..opts.max_iters {
        iterations += 1;
        // Linearise once per outer iteration; retry damping without relinearising.
        let lins: Vec<Option<Lin>> = obs
            .par_iter()
            .map(|o| linearise(&poses[o.cam], &points[o.point], &o.xy, k, opts.huber_px))
            .collect();
        let mut accepted = false;
        for _attempt in 0..8 {
            let mut system = schur_system(&lins, obs, &layout, &by_point, lambda);
            if let (Some(fc), Focal::Prior { focal, sigma }) = (layout.focal_col, opts.focal) {
                // Residual (f − focal)/σ with Jacobian 1/σ: Gauss–Newton adds JᵀJ and Jᵀr.
                let w = 1.0 / (sigma * sigma);
                system.s[(fc, fc)] += w;
                system.b[fc] += w * (k.fx - focal);
            }
            if let Some(path) = opts.path {
                path.add_to(&mut system, poses, &layout);
            }
            let n = layout.n;
            for i in 0..n {
                system.s[(i, i)] += lambda * (system.s[(i, i)] + 1e-9);
            }
            let dc = if n > 0 {
                match system.s.clone().cholesky() {
                    Some(ch) => ch.solve(&(-&system.b)),
                    None => {
                        lambda *= 10.0;
                        continue;
                    }
                }
            } else {
                DVector::zeros(0)
            };
            let dps = back_substitute(&system, &dc, &lins, obs, &layout, &by_point);
            let mut new_poses = poses.to_vec();
            for (c, np) in new_poses.iter_mut().enumerate() {
                let col = layout.cam_col[c];
                if col == usize::MAX {
                    continue;
                }
                let w = Vector3::new(dc[col], dc[col + 1], dc[col + 2]);
                np.rot = Rotation3::new(w).into_inner() * np.rot;
                np.trans += Vector3::new(dc[col + 3], dc[col + 4], dc[col + 5]);
            }
            let new_points: Vec<Vector3<f64>> =
                points.iter().zip(&dps).map(|(x, d)| x + d).collect();
            let mut new_k = *k;
            if let Some(fc) = layout.focal_col {
                new_k.fx += dc[fc];
                new_k.fy += dc[fc];
            }
            let new_cost = if new_k.fx > 0.0 {
                cost_of(&new_poses, &new_points, &new_k)
            } else {
                f64::INFINITY
            };
            if new_cost < cost {
                let rel = (cost - new_cost) / cost.max(1e-300);
                poses.copy_from_slice(&new_poses);
                points.copy_from_slice(&new_points);
                *k = new_k;
                cost = new_cost;
                lambda = (lambda / 3.0).max(1e-9);
                accepted = true;
                if rel < 1e-7 {
                    return BaSummary {
                        initial_cost,
                        final_cost: cost,
                        iterations,
                    };
                }
                break;
            }
            lambda *= 4.0;
        }
        if !accepted {
            break;
        }
    }
    BaSummary {
        initial_cost,
        final_cost: cost,
        iterations,
    }
}

/// Columns of the reduced (camera and focal) system: free cameras with observations get 6
/// columns each (ω, v), then the focal when it is refined.
struct ParamLayout {
    /// First column of each camera; `usize::MAX` for a fixed or unobserved camera.
    cam_col: Vec<usize>,
    /// Cameras with observations (in the adjustment, free or fixed).
    present: Vec<bool>,
    focal_col: Option<usize>,
    /// Number of columns.
    n: usize,
}

impl ParamLayout {
    fn new(ncam: usize, fixed: &[bool], obs: &[Observation], refine_focal: bool) -> Self {
        let mut cam_col = vec![usize::MAX; ncam];
        let mut seen = vec![false; ncam];
        for o in obs {
            seen[o.cam] = true;
        }
        let mut n = 0;
        for c in 0..ncam {
            if seen[c] && !fixed[c] {
                cam_col[c] = n;
                n += 6;
            }
        }
        let focal_col = refine_focal.then_some(n);
        if refine_focal {
            n += 1;
        }
        ParamLayout {
            cam_col,
            present: seen,
            focal_col,
            n,
        }
    }

    /// Columns of an observation's 7 camera-side parameters (ω, v, f) in the reduced system.
    fn cols(&self, o: &Observation) -> [Option<usize>; 7] {
        let mut c = [None; 7];
        if self.cam_col[o.cam] != usize::MAX {
            for (i, ci) in c.iter_mut().take(6).enumerate() {
                *ci = Some(self.cam_col[o.cam] + i);
            }
        }
        c[6] = self.focal_col;
        c
    }
}

/// Observations grouped by point (CSR): those of point `p` are
/// `order[start[p]..start[p + 1]]`.
struct PointObservations {
    start: Vec<usize>,
    order: Vec<usize>,
}

impl PointObservations {
    fn new(npts: usize, obs: &[Observation]) -> Self {
        let mut start = vec![0usize; npts + 1];
        for o in obs {
            start[o.point + 1] += 1;
        }
        for i in 0..npts {
            start[i + 1] += start[i];
        }
        let mut order = vec![0usize; obs.len()];
        let mut fill = start.clone();
        for (i, o) in obs.iter().enumerate() {
            order[fill[o.point]] = i;
            fill[o.point] += 1;
        }
        PointObservations { start, order }
    }

    fn of(&self, p: usize) -> &[usize] {
        &self.order[self.start[p]..self.start[p + 1]]
    }

    fn points(&self) -> usize {
        self.start.len() - 1
    }
}

/// The reduced camera system after eliminating the points (Schur complement), before the
/// damping of its diagonal: `s · δc = −b`. Per point, the inverse damped 3×3 block (`None` when
/// singular) and the point gradient, for the back-substitution.
struct SchurSystem {
    s: DMatrix<f64>,
    b: DVector<f64>,
    vinv: Vec<Option<Matrix3<f64>>>,
    gps: Vec<Vector3<f64>>,
}

/// Points per parallel chunk of the Schur complement; the chunk sums are added in chunk order,
/// so the result does not depend on the thread count.
const SCHUR_CHUNK: usize = 256;

/// Builds the point blocks with damping `lambda` and folds them into the reduced system.
fn schur_system(
    lins: &[Option<Lin>],
    obs: &[Observation],
    layout: &ParamLayout,
    by_point: &PointObservations,
    lambda: f64,
) -> SchurSystem {
    let n = layout.n;
    let npts = by_point.points();
    let chunks: Vec<SchurSystem> = (0..npts.div_ceil(SCHUR_CHUNK))
        .into_par_iter()
        .map(|ch| {
            let mut s = DMatrix::<f64>::zeros(n, n);
            let mut b = DVector::<f64>::zeros(n);
            let mut vinv = Vec::with_capacity(SCHUR_CHUNK);
            let mut gps = Vec::with_capacity(SCHUR_CHUNK);
            let mut wblocks: Vec<(usize, SMatrix<f64, 7, 3>)> = Vec::new();
            for p in ch * SCHUR_CHUNK..((ch + 1) * SCHUR_CHUNK).min(npts) {
                let mut v = Matrix3::<f64>::zeros();
                let mut gp = Vector3::<f64>::zeros();
                wblocks.clear();
                for &oi in by_point.of(p) {
                    let Some(l) = &lins[oi] else { continue };
                    let o = &obs[oi];
                    v += l.jp.transpose() * l.jp * l.w;
                    gp += l.jp.transpose() * l.r * l.w;
                    let c = layout.cols(o);
                    let u = l.jc.transpose() * l.jc * l.w;
                    let gc = l.jc.transpose() * l.r * l.w;
                    for a in 0..7 {
                        let Some(ca) = c[a] else { continue };
                        b[ca] += gc[a];
                        for bb in 0..7 {
                            if let Some(cb) = c[bb] {
                                s[(ca, cb)] += u[(a, bb)];
                            }
                        }
                    }
                    wblocks.push((oi, l.jc.transpose() * l.jp * l.w));
                }
                for i in 0..3 {
                    v[(i, i)] += lambda * (v[(i, i)] + 1e-9);
                }
                let vi = v.try_inverse();
                if let Some(vi) = vi {
                    // S −= W V⁻¹ Wᵀ ; b −= W V⁻¹ g_p
                    for (oa, wa) in &wblocks {
                        let ca = layout.cols(&obs[*oa]);
                        let wv = wa * vi;
                        let bv = wv * gp;
                        for a in 0..7 {
                            if let Some(x) = ca[a] {
                                b[x] -= bv[a];
                            }
                        }
                        for (ob, wb) in &wblocks {
                            let cb = layout.cols(&obs[*ob]);
                            let m = wv * wb.transpose();
                            for a in 0..7 {
                                let Some(x) = ca[a] else { continue };
                                for bb in 0..7 {
                                    if let Some(y) = cb[bb] {
                                        s[(x, y)] -= m[(a, bb)];
                                    }
                                }
                            }
                        }
                    }
                }
                vinv.push(vi);
                gps.push(gp);
            }
            SchurSystem { s, b, vinv, gps }
        })
        .collect();
    let mut total = SchurSystem {
        s: DMatrix::<f64>::zeros(n, n),
        b: DVector::<f64>::zeros(n),
        vinv: Vec::with_capacity(npts),
        gps: Vec::with_capacity(npts),
    };
    for c in chunks {
        total.s += c.s;
        total.b += c.b;
        total.vinv.extend(c.vinv);
        total.gps.extend(c.gps);
    }
    total
}

/// Back-substitutes the points: δp = V⁻¹(−g_p − Wᵀ δc).
fn back_substitute(
    system: &SchurSystem,
    dc: &DVector<f64>,
    lins: &[Option<Lin>],
    obs: &[Observation],
    layout: &ParamLayout,
    by_point: &PointObservations,
) -> Vec<Vector3<f64>> {
    (0..by_point.points())
        .into_par_iter()
        .map(|p| {
            let Some(vi) = system.vinv[p] else {
                return Vector3::zeros();
            };
            let mut rhs = -system.gps[p];
            for &oi in by_point.of(p) {
                let Some(l) = &lins[oi] else { continue };
                let c = layout.cols(&obs[oi]);
                let w = l.jc.transpose() * l.jp * l.w;
                for (a, ca) in c.iter().enumerate() {
                    if let Some(x) = ca {
                        rhs -= w.row(a).transpose() * dc[*x];
                    }
                }
            }
            vi * rhs
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use gems_math::camera_center_from_w2c;
    use nalgebra::Vector6;

    /// Angle of the rotation between two poses' rotations.
    fn relative_angle(a: &Se3, b: &Se3) -> f64 {
        Rotation3::from_matrix_unchecked(a.rot.transpose() * b.rot).angle()
    }
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// A ring of cameras looking at a cloud; returns ground truth and noisy observations.
    fn problem(seed: u64) -> (Vec<Se3>, Vec<Vector3<f64>>, Vec<Observation>, Intrinsics) {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let k = Intrinsics {
            fx: 300.0,
            fy: 300.0,
            cx: 160.0,
            cy: 120.0,
            width: 320,
            height: 240,
        };
        let pts: Vec<Vector3<f64>> = (0..200)
            .map(|_| {
                Vector3::new(
                    rng.random_range(-1.0..1.0),
                    rng.random_range(-1.0..1.0),
                    rng.random_range(-1.0..1.0),
                )
            })
            .collect();
        let poses: Vec<Se3> = (0..6)
            .map(|i| {
                let a = -0.4 + 0.16 * i as f64;
                let r = Rotation3::new(Vector3::new(0.0, -a, 0.0));
                let c = Vector3::new(6.0 * a.sin(), 0.2 * i as f64 - 0.5, -6.0 * a.cos());
                Se3::new(r.into_inner(), -(r * c))
            })
            .collect();
        let mut obs = Vec::new();
        for (ci, p) in poses.iter().enumerate() {
            for (pi, x) in pts.iter().enumerate() {
                let xy = k.project(&p.act(x));
                obs.push(Observation {
                    cam: ci,
                    point: pi,
                    xy,
                });
            }
        }
        (poses, pts, obs, k)
    }

    #[test]
    fn ba_converges_to_zero_cost_from_perturbed_start() {
        let (gt_poses, gt_pts, obs, k) = problem(4);
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let mut poses = gt_poses.clone();
        for p in poses.iter_mut().skip(1) {
            p.rot = Rotation3::new(Vector3::new(
                rng.random_range(-0.02..0.02),
                rng.random_range(-0.02..0.02),
                rng.random_range(-0.02..0.02),
            ))
            .into_inner()
                * p.rot;
            p.trans += Vector3::new(
                rng.random_range(-0.1..0.1),
                rng.random_range(-0.1..0.1),
                0.0,
            );
        }
        // Fix two cameras so that the gauge (including scale) is pinned.
        let mut fixed = vec![false; poses.len()];
        fixed[0] = true;
        fixed[5] = true;
        poses[5] = gt_poses[5];
        let mut pts: Vec<_> = gt_pts
            .iter()
            .map(|x| x + Vector3::new(rng.random_range(-0.05..0.05), 0.03, -0.02))
            .collect();
        let mut kk = k;
        kk.fx = 310.0;
        kk.fy = 310.0;
        let s = bundle_adjust(
            &mut poses,
            &fixed,
            &mut pts,
            &obs,
            &mut kk,
            &BaOptions {
                huber_px: 2.0,
                max_iters: 100,
                focal: Focal::Free,
                path: None,
            },
        );
        assert!(s.final_cost < 1e-10 * s.initial_cost.max(1.0), "{s:?}");
        assert!((kk.fx - 300.0).abs() < 1e-4, "focal {}", kk.fx);
        for (p, g) in poses.iter().zip(&gt_poses) {
            assert!(relative_angle(p, g) < 1e-6);
            assert!((camera_center_from_w2c(p) - camera_center_from_w2c(g)).norm() < 1e-5);
        }
    }

    /// The focal under a prior lands between the prior's value and what the photos say, at
    /// either end in the limits of a sharp and a flat prior.
    #[test]
    fn focal_prior_weighs_the_given_focal_against_the_photos() {
        let (gt_poses, gt_pts, mut obs, k) = problem(6);
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        for o in &mut obs {
            o.xy += Vector2::new(rng.random_range(-0.5..0.5), rng.random_range(-0.5..0.5));
        }
        let mut fixed = vec![false; gt_poses.len()];
        fixed[0] = true;
        fixed[5] = true;
        let solve = |focal: Focal| {
            let (mut poses, mut pts, mut kk) = (gt_poses.clone(), gt_pts.clone(), k);
            kk.fx = 330.0;
            kk.fy = 330.0;
            let s = bundle_adjust(
                &mut poses,
                &fixed,
                &mut pts,
                &obs,
                &mut kk,
                &BaOptions {
                    huber_px: 2.0,
                    max_iters: 100,
                    focal,
                    path: None,
                },
            );
            assert!(s.final_cost <= s.initial_cost, "{s:?}");
            assert_eq!(kk.fx, kk.fy);
            kk.fx
        };
        let free = solve(Focal::Free);
        assert!((free - 300.0).abs() < 1.0, "the photos say {free}");
        let prior = |sigma| Focal::Prior {
            focal: 330.0,
            sigma,
        };
        let sharp = solve(prior(1e-4));
        assert!(
            (sharp - 330.0).abs() < 0.01,
            "a sharp prior holds it: {sharp}"
        );
        let flat = solve(prior(1e5));
        assert!(
            (flat - free).abs() < 0.01,
            "a flat prior lets it go: {flat}"
        );
        let between = solve(prior(0.5));
        assert!(
            between > free + 0.01 && between < 330.0 - 0.01,
            "{free} < {between} < 330"
        );
        assert_eq!(solve(Focal::Fixed), 330.0);
    }

    #[test]
    fn huber_limits_outlier_influence() {
        let (gt_poses, gt_pts, mut obs, k) = problem(5);
        for o in obs.iter_mut().step_by(23) {
            o.xy += Vector2::new(40.0, -25.0);
        }
        let mut poses = gt_poses.clone();
        let mut pts = gt_pts;
        let mut kk = k;
        let mut fixed = vec![false; poses.len()];
        fixed[0] = true;
        fixed[5] = true;
        bundle_adjust(
            &mut poses,
            &fixed,
            &mut pts,
            &obs,
            &mut kk,
            &BaOptions {
                huber_px: 1.0,
                max_iters: 50,
                focal: Focal::Fixed,
                path: None,
            },
        );
        for (p, g) in poses.iter().zip(&gt_poses) {
            assert!(
                (camera_center_from_w2c(p) - camera_center_from_w2c(g)).norm() < 0.05,
                "{}",
                (camera_center_from_w2c(p) - camera_center_from_w2c(g)).norm()
            );
        }
    }

    /// Cameras along a gently curving path, each looking a little differently.
    fn path_poses(n: usize) -> Vec<Se3> {
        (0..n)
            .map(|i| {
                let t = i as f64;
                let r = Rotation3::new(Vector3::new(0.01 * t, -0.03 * t, 0.002 * t * t));
                let c = Vector3::new(0.3 * t, 0.02 * t * t, 0.1 * (0.4 * t).sin());
                Se3::new(r.into_inner(), -(r * c))
            })
            .collect()
    }

    /// The path prior's residuals against central finite differences of the same residuals
    /// (with the mean step held, as in a linearisation), for every camera of a triple.
    #[test]
    fn path_prior_jacobians_match_finite_differences() {
        let poses = path_poses(4);
        let present = vec![true; 4];
        let prior = PathPrior {
            order: vec![0, 1, 2, 3],
            centre_sigma: 0.3,
            rotation_sigma: 0.01,
        };
        let step = prior.mean_step(&poses, &present).unwrap();
        let res = prior.residuals(&poses, &present, step);
        assert_eq!(res.len(), 4, "two triples, centre and rotation each");
        let h = 1e-6;
        for (ri, r) in res.iter().enumerate() {
            for (slot, &cam) in r.cams.iter().enumerate() {
                for i in 0..6 {
                    let at = |sign: f64| {
                        let mut p = poses.clone();
                        let mut d = Vector6::zeros();
                        d[i] = sign * h;
                        let w: Vector3<f64> = d.fixed_rows::<3>(0).into_owned();
                        let v: Vector3<f64> = d.fixed_rows::<3>(3).into_owned();
                        p[cam].rot = Rotation3::new(w).into_inner() * p[cam].rot;
                        p[cam].trans += v;
                        prior.residuals(&p, &present, step)[ri].r
                    };
                    let num = (at(1.0) - at(-1.0)) / (2.0 * h);
                    let an = r.j[slot].column(i);
                    assert!(
                        (num - an).norm() < 1e-5 * (1.0 + an.norm()),
                        "residual {ri}, camera {cam}, column {i}: {num} vs {an}"
                    );
                }
            }
        }
    }

    /// The prior does not depend on the reconstruction's scale, and a path with constant
    /// velocity and angular velocity costs nothing.
    #[test]
    fn path_prior_is_scale_free_and_zero_on_uniform_motion() {
        let poses = path_poses(6);
        let present = vec![true; 6];
        let prior = PathPrior {
            order: (0..6).collect(),
            centre_sigma: 0.2,
            rotation_sigma: 0.01,
        };
        let cost = prior.cost(&poses, &present);
        assert!(cost > 1e-3);
        let scaled: Vec<Se3> = poses
            .iter()
            .map(|p| Se3::new(p.rot, p.trans * 7.5))
            .collect();
        assert!((prior.cost(&scaled, &present) - cost).abs() < 1e-9 * cost);
        let step = Rotation3::new(Vector3::new(0.01, -0.03, 0.02));
        let uniform: Vec<Se3> = (0..6)
            .map(|i| {
                let r = step.powf(i as f64);
                Se3::new(
                    r.into_inner(),
                    -(r * Vector3::new(0.3 * i as f64, 0.1, 0.0)),
                )
            })
            .collect();
        assert!(prior.cost(&uniform, &present) < 1e-20);
        // A camera missing from the adjustment splits the path: no triple spans it.
        let mut gap = present.clone();
        gap[2] = false;
        assert_eq!(prior.triples(&gap).count(), 1);
    }

    /// Cameras moving evenly along a line; the middle one sees only two points, too few to
    /// place it. From a start off the line the prior brings it back; the photos alone leave it
    /// somewhere on the family of poses that see the two points where they are.
    #[test]
    fn path_prior_holds_a_camera_the_photos_barely_see_in_line() {
        let k = Intrinsics {
            fx: 200.0,
            fy: 200.0,
            cx: 100.0,
            cy: 100.0,
            width: 200,
            height: 200,
        };
        let gt: Vec<Se3> = (0..5)
            .map(|i| Se3::new(Matrix3::identity(), -Vector3::new(0.5 * i as f64, 0.0, 0.0)))
            .collect();
        let pts: Vec<Vector3<f64>> = (0..60)
            .map(|i| {
                let t = i as f64;
                Vector3::new(-1.0 + 0.07 * t, (t * 0.37).sin(), 5.0 + (t * 0.71).cos())
            })
            .collect();
        // Camera 2 sees two points: four equations for six unknowns.
        let mut obs = Vec::new();
        for (ci, p) in gt.iter().enumerate() {
            for (pi, x) in pts.iter().enumerate() {
                if ci == 2 && pi % 30 != 0 {
                    continue;
                }
                obs.push(Observation {
                    cam: ci,
                    point: pi,
                    xy: k.project(&p.act(x)),
                });
            }
        }
        let solve = |path: Option<&PathPrior>| {
            let mut poses = gt.clone();
            poses[2].trans += Vector3::new(0.0, 0.3, 0.0);
            let mut fixed = vec![false; 5];
            fixed[0] = true;
            fixed[4] = true;
            let (mut p, mut kk) = (pts.clone(), k);
            bundle_adjust(
                &mut poses,
                &fixed,
                &mut p,
                &obs,
                &mut kk,
                &BaOptions {
                    huber_px: 1.0,
                    max_iters: 100,
                    focal: Focal::Fixed,
                    path,
                },
            );
            (camera_center_from_w2c(&poses[2]) - camera_center_from_w2c(&gt[2])).norm()
        };
        let prior = PathPrior {
            order: (0..5).collect(),
            centre_sigma: 0.1,
            rotation_sigma: 0.01,
        };
        let (free, held) = (solve(None), solve(Some(&prior)));
        assert!(
            held < 1e-4,
            "with the prior the camera returns to the line: {held}"
        );
        assert!(free > 1e-2, "two points alone do not place it: {free}");
    }

    /// Central finite differences of the residual against the analytic Jacobian.
    #[test]
    fn jacobians_match_finite_differences() {
        let pose = Se3::new(
            Rotation3::new(Vector3::new(0.1, -0.2, 0.3)).into_inner(),
            Vector3::new(0.2, -0.1, 4.0),
        );
        let x = Vector3::new(0.3, -0.4, 0.5);
        let k = Intrinsics {
            fx: 250.0,
            fy: 250.0,
            cx: 100.0,
            cy: 80.0,
            width: 200,
            height: 160,
        };
        let o = Vector2::new(90.0, 70.0);
        let l = linearise(&pose, &x, &o, &k, 1e9).unwrap();
        let res = |p: &Se3, x: &Vector3<f64>, k: &Intrinsics| k.project(&p.act(x)) - o;
        let h = 1e-6;
        for i in 0..7 {
            let mut d = [0.0; 7];
            d[i] = h;
            let step = |s: f64| {
                let mut p = pose;
                p.rot = Rotation3::new(Vector3::new(d[0], d[1], d[2]) * s).into_inner() * p.rot;
                p.trans += Vector3::new(d[3], d[4], d[5]) * s;
                let mut kk = k;
                kk.fx += d[6] * s;
                kk.fy += d[6] * s;
                res(&p, &x, &kk)
            };
            let num = (step(1.0) - step(-1.0)) / (2.0 * h);
            let an = l.jc.column(i);
            assert!(
                (num - an).norm() < 1e-5 * (1.0 + an.norm()),
                "col {i}: {num} vs {an}"
            );
        }
        for i in 0..3 {
            let mut e = Vector3::zeros();
            e[i] = h;
            let num = (res(&pose, &(x + e), &k) - res(&pose, &(x - e), &k)) / (2.0 * h);
            let an = l.jp.column(i);
            assert!(
                (num - an).norm() < 1e-5 * (1.0 + an.norm()),
                "point col {i}"
            );
        }
    }
}

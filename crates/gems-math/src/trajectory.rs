//! Camera trajectories inside the exposure, u ∈ [0, 1], as right-composed deltas Δ(u) on a
//! camera-to-world pose: c2w(u) = c2w_init · Δ(u). Knots are se(3) vectors [ρ; φ].
//!
//! Every variant offers [`Trajectory::eval_with_jacobians`], whose J_j maps a change of knot j to
//! the RIGHT perturbation δ of Δ(u): Δ(u; ξ_j + dξ) ≈ Δ(u) · Exp(J_j dξ). Because c2w_init is a
//! constant left factor, δ is also the right perturbation of c2w(u), which is what
//! [`crate::posegrad::c2w_right_perturbation_gradient`] produces from renderer gradients.

use nalgebra::{Matrix3, Matrix6, Vector3, Vector6};

use crate::MathError;
use crate::se3::{Se3, se3_right_jacobian, se3_right_jacobian_inv};
use crate::so3::{So3, so3_left_jacobian_inv, so3_right_jacobian, so3_right_jacobian_inv};

/// Which curve family a trajectory uses (the paper's ablation). In configuration files:
/// `bezier`, `linear` or `spline`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum TrajectoryKind {
    /// GeMS Eq. (8): Δ(u) = Π_{j=0..M} Exp(b_j(u) ξ_j), Bernstein b_j of degree M, product in
    /// order j = 0..M (BAD-Gaussians / PRISM3D "right product").
    Bezier,
    /// Two knots T_k = Exp(ξ_k); split interpolation as BAD-Gaussians: t(u) = (1−u)t₀ + u t₁,
    /// R(u) = R₀ Exp(u Log(R₀ᵀR₁)).
    Linear,
    /// Four knots T_k = Exp(ξ_k); uniform cumulative cubic B-spline of BAD-Gaussians: translation
    /// with the plain B-spline basis, rotation R₀ Π_k Exp(B̃_k(u) Log(R_{k−1}ᵀR_k)).
    #[serde(rename = "spline")]
    CubicBSpline,
}

impl TrajectoryKind {
    /// The knot count the variant requires, or `None` when any count ≥ 1 is allowed (Bézier).
    pub fn required_knots(self) -> Option<usize> {
        match self {
            TrajectoryKind::Bezier => None,
            TrajectoryKind::Linear => Some(2),
            TrajectoryKind::CubicBSpline => Some(4),
        }
    }

    /// Default knot count: [`BEZIER_DEFAULT_KNOTS`] for Bézier, else the required one.
    pub fn default_knots(self) -> usize {
        self.knots(BEZIER_DEFAULT_KNOTS)
    }

    /// The knot count of this kind when a Bézier curve has `bezier_knots` control knots: the one
    /// place that says how many knots each kind has.
    pub fn knots(self, bezier_knots: usize) -> usize {
        self.required_knots().unwrap_or(bezier_knots)
    }
}

/// The Bézier control-point count of the GeMS paper ("For Bézier, we use 9 control points",
/// implementation details), i.e. degree 8.
pub const BEZIER_DEFAULT_KNOTS: usize = 9;

/// A camera trajectory over the exposure, parameterised by se(3) knots ([ρ; φ] each).
#[derive(Clone, Debug, PartialEq)]
pub enum Trajectory {
    Bezier(Vec<[f64; 6]>),
    Linear([[f64; 6]; 2]),
    CubicBSpline([[f64; 6]; 4]),
}

/// A 6×6 Jacobian, row-major: `j[r][c] = ∂δ_r / ∂ξ_c`.
pub type Jacobian6 = [[f64; 6]; 6];

fn to_rows(m: &Matrix6<f64>) -> Jacobian6 {
    let mut out = [[0.0; 6]; 6];
    for (r, row) in out.iter_mut().enumerate() {
        for (c, v) in row.iter_mut().enumerate() {
            *v = m[(r, c)];
        }
    }
    out
}

/// Bernstein basis of degree `n` at u: C(n, j)(1−u)^(n−j) u^j for j = 0..=n.
pub fn bernstein(n: usize, u: f64) -> Vec<f64> {
    let mut binom = 1.0f64;
    (0..=n)
        .map(|j| {
            let b = binom * (1.0 - u).powi((n - j) as i32) * u.powi(j as i32);
            binom = binom * (n - j) as f64 / (j + 1) as f64;
            b
        })
        .collect()
}

impl Trajectory {
    /// Builds a trajectory, checking the knot count of the variant.
    pub fn new(kind: TrajectoryKind, knots: Vec<[f64; 6]>) -> Result<Self, MathError> {
        let bad = |expected: usize| MathError::KnotCount {
            kind,
            expected,
            got: knots.len(),
        };
        Ok(match kind {
            TrajectoryKind::Bezier => {
                if knots.is_empty() {
                    return Err(bad(1));
                }
                Trajectory::Bezier(knots)
            }
            TrajectoryKind::Linear => {
                Trajectory::Linear(knots.as_slice().try_into().map_err(|_| bad(2))?)
            }
            TrajectoryKind::CubicBSpline => {
                Trajectory::CubicBSpline(knots.as_slice().try_into().map_err(|_| bad(4))?)
            }
        })
    }

    /// All knots zero: Δ(u) = identity for every u.
    pub fn identity(kind: TrajectoryKind, num_knots: usize) -> Result<Self, MathError> {
        Self::new(kind, vec![[0.0; 6]; num_knots])
    }

    pub fn kind(&self) -> TrajectoryKind {
        match self {
            Trajectory::Bezier(_) => TrajectoryKind::Bezier,
            Trajectory::Linear(_) => TrajectoryKind::Linear,
            Trajectory::CubicBSpline(_) => TrajectoryKind::CubicBSpline,
        }
    }

    pub fn knots(&self) -> &[[f64; 6]] {
        match self {
            Trajectory::Bezier(k) => k,
            Trajectory::Linear(k) => k,
            Trajectory::CubicBSpline(k) => k,
        }
    }

    fn knots_mut(&mut self) -> &mut [[f64; 6]] {
        match self {
            Trajectory::Bezier(k) => k,
            Trajectory::Linear(k) => k,
            Trajectory::CubicBSpline(k) => k,
        }
    }

    pub fn num_knots(&self) -> usize {
        self.knots().len()
    }

    /// Δ(u). `u` is clamped to [0, 1].
    pub fn eval(&self, u: f64) -> Se3 {
        let u = u.clamp(0.0, 1.0);
        match self {
            Trajectory::Bezier(k) => {
                let b = bernstein(k.len() - 1, u);
                k.iter().zip(&b).fold(Se3::identity(), |acc, (xi, &bj)| {
                    acc * Se3::exp(&(Vector6::from(*xi) * bj))
                })
            }
            Trajectory::Linear(k) => SplitSpline::new(k, u).pose(),
            Trajectory::CubicBSpline(k) => SplitSpline::new(k, u).pose(),
        }
    }

    /// Δ(u) and, per knot j, J_j with Δ(u; ξ_j + dξ) ≈ Δ(u) · Exp(J_j dξ).
    pub fn eval_with_jacobians(&self, u: f64) -> (Se3, Vec<Jacobian6>) {
        let u = u.clamp(0.0, 1.0);
        match self {
            Trajectory::Bezier(k) => bezier_with_jacobians(k, u),
            Trajectory::Linear(k) => SplitSpline::new(k, u).with_jacobians(),
            Trajectory::CubicBSpline(k) => SplitSpline::new(k, u).with_jacobians(),
        }
    }

    /// Adds J_jᵀ g to `out[j]` for every knot, where g = dL/dδ is the gradient w.r.t. the right
    /// perturbation of Δ(u) (equivalently of c2w(u)). Returns Δ(u). `out.len()` must equal the knot
    /// count.
    pub fn accumulate_knot_gradients(
        &self,
        u: f64,
        grad_delta: &[f64; 6],
        out: &mut [[f64; 6]],
    ) -> Se3 {
        assert_eq!(
            out.len(),
            self.num_knots(),
            "gradient buffer length != knot count"
        );
        let (pose, jacs) = self.eval_with_jacobians(u);
        for (o, j) in out.iter_mut().zip(&jacs) {
            for (c, oc) in o.iter_mut().enumerate() {
                *oc += (0..6).map(|r| j[r][c] * grad_delta[r]).sum::<f64>();
            }
        }
        pose
    }
}

/// Uneven-speed energy of the poses Δ(u_k) at `times` (sorted): Σ_k ‖Log(Δ(u_k)⁻¹ Δ(u_{k+1}))‖².
///
/// The blur model averages the renders at the times and is blind to how a path spends its
/// time, so a path may dwell at one end or fold back and still explain the blurry image; its
/// pose at u = ½ is then not the middle of the exposure. Along a fixed path this energy is
/// smallest when consecutive poses are equally far apart (for a sum of squares with a fixed sum,
/// equal terms), and it grows with folds, so a small multiple of it fixes that gauge: u = ½
/// becomes the middle of the path. It also pulls the path shorter, which is why its weight is
/// small.
///
/// Adds `weight` × its gradient with respect to the knots to `knot_grads` (one [ρ; φ] per knot,
/// as [`Trajectory::accumulate_knot_gradients`]) and returns `weight` × the energy.
pub fn uneven_speed_energy(
    traj: &Trajectory,
    times: &[f64],
    weight: f64,
    knot_grads: &mut [[f64; 6]],
) -> f64 {
    if times.len() < 2 || weight == 0.0 {
        return 0.0;
    }
    let poses: Vec<Se3> = times.iter().map(|&u| traj.eval(u)).collect();
    // dE/dδ_k for the right perturbation δ_k of Δ(u_k).
    let mut grads = vec![Vector6::<f64>::zeros(); times.len()];
    let mut energy = 0.0;
    for k in 0..times.len() - 1 {
        // ξ = Log(C), C = A⁻¹B. Right-perturbing B: ξ + J_r⁻¹(ξ) δ_B. Right-perturbing A:
        // Exp(−δ_A) C = C Exp(−Ad(C⁻¹) δ_A), so ξ − J_r⁻¹(ξ) Ad(C⁻¹) δ_A.
        let c = poses[k].inverse() * poses[k + 1];
        let xi = c.log();
        energy += xi.norm_squared();
        let g = se3_right_jacobian_inv(&xi).transpose() * xi * 2.0;
        grads[k + 1] += g;
        grads[k] -= c.inverse().adjoint().transpose() * g;
    }
    for (&u, g) in times.iter().zip(&grads) {
        let g: [f64; 6] = std::array::from_fn(|i| g[i] * weight);
        traj.accumulate_knot_gradients(u, &g, knot_grads);
    }
    weight * energy
}

/// Which pose of an exposure's set [`off_centre_energy`] holds the trajectory's u = ½ on. In
/// configuration files: `median` or `mean`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum PathCentre {
    /// The mean (1/n) Σ_k Log Δ(u_k): the middle of a straight path walked at even speed, but
    /// inside the bend of a curved one and toward the slow end of an uneven one.
    Mean,
    /// The median of the poses ordered along the set's principal direction: the middle in time
    /// of any path that moves steadily along that direction, curved or uneven in speed.
    Median,
}

/// Off-centre energy of the poses Δ(u_k) at `times`: ‖Log Δ(½) − c‖², where c is the set's
/// `centre` in the tangent space, [`PathCentre::Mean`] or [`PathCentre::Median`].
///
/// The blur model averages the renders and so sees the exposure's poses only as a set: the
/// order along the path is free, and the pose at u = ½, which gems reports as the sharp
/// mid-exposure view, can drift to one end of the set (a hooked path that dwells or folds). The
/// set, unlike its order, is fixed by the blurry image, and so is its centre. This energy pulls
/// Δ(½) onto that centre without pulling the path shorter (a rigid shift of the whole set leaves
/// the mean's residual unchanged; the median's is zero on any path that moves steadily).
///
/// The median orders the poses by their projection on the principal axis of the logs, with the
/// translation and rotation blocks each scaled to unit spread so that neither unit dominates;
/// for an even count it is the mean of the two middle logs. Which poses are the median is held
/// fixed for the gradient (it is piecewise constant in the knots).
///
/// Adds `weight` × its gradient with respect to the knots to `knot_grads` (one [ρ; φ] per knot,
/// as [`Trajectory::accumulate_knot_gradients`]) and returns `weight` × the energy.
pub fn off_centre_energy(
    traj: &Trajectory,
    times: &[f64],
    centre: PathCentre,
    weight: f64,
    knot_grads: &mut [[f64; 6]],
) -> f64 {
    if times.is_empty() || weight == 0.0 {
        return 0.0;
    }
    let mid = traj.eval(0.5).log();
    let logs: Vec<Vector6<f64>> = times.iter().map(|&u| traj.eval(u).log()).collect();
    // The centre as weights on the logs, c = Σ_k w_k ξ_k (the mean summed first, then scaled).
    let (c, centre_weights) = match centre {
        PathCentre::Mean => {
            let inv_n = 1.0 / times.len() as f64;
            (
                logs.iter().sum::<Vector6<f64>>() * inv_n,
                vec![inv_n; times.len()],
            )
        }
        PathCentre::Median => {
            let w = median_weights(&logs);
            (logs.iter().zip(&w).map(|(xi, &w)| xi * w).sum(), w)
        }
    };
    let r = mid - c;
    // d Log(Δ Exp(δ)) / dδ = J_r⁻¹(Log Δ), so dE/dδ = J_r⁻¹ᵀ ∂E/∂ξ with ∂E/∂ξ_mid = 2r and
    // ∂E/∂ξ_k = −2 w_k r.
    let mut add = |u: f64, xi: &Vector6<f64>, d_xi: Vector6<f64>| {
        let g = se3_right_jacobian_inv(xi).transpose() * d_xi * weight;
        traj.accumulate_knot_gradients(u, &std::array::from_fn(|i| g[i]), knot_grads);
    };
    add(0.5, &mid, r * 2.0);
    for ((&u, xi), &w) in times.iter().zip(&logs).zip(&centre_weights) {
        if w != 0.0 {
            add(u, xi, r * (-2.0 * w));
        }
    }
    weight * r.norm_squared()
}

/// Anchor energy of the poses Δ(u_k) at `times`: ‖(1/n) Σ_k Log Δ(u_k)‖², the squared distance
/// of the exposure's mean pose from the initial camera (Δ = identity). An SfM run on the blurry
/// photos places each camera near the mean of its exposure; when those cameras are accurate the
/// energy keeps the trained exposure there, where the Gaussians' frame was set, instead of
/// letting every path drift by a shared offset that the photometric loss cannot see (the gauge
/// of the mean pose). 0 weight: free paths (the GeMS paper).
///
/// Adds `weight` × its gradient with respect to the knots to `knot_grads` (one [ρ; φ] per knot)
/// and returns `weight` × the energy.
pub fn anchor_energy(
    traj: &Trajectory,
    times: &[f64],
    weight: f64,
    knot_grads: &mut [[f64; 6]],
) -> f64 {
    if times.is_empty() || weight == 0.0 {
        return 0.0;
    }
    let logs: Vec<Vector6<f64>> = times.iter().map(|&u| traj.eval(u).log()).collect();
    let inv_n = 1.0 / times.len() as f64;
    let c = logs.iter().sum::<Vector6<f64>>() * inv_n;
    // ∂E/∂ξ_k = 2c/n, through d Log(Δ Exp(δ)) / dδ = J_r⁻¹(Log Δ).
    for (&u, xi) in times.iter().zip(&logs) {
        let g = se3_right_jacobian_inv(xi).transpose() * c * (2.0 * inv_n * weight);
        traj.accumulate_knot_gradients(u, &std::array::from_fn(|i| g[i]), knot_grads);
    }
    weight * c.norm_squared()
}

/// Replaces the knots by their least-squares straight line: knot j (of K) becomes m + s·(t_j − ½),
/// t_j = j/(K−1), with m the knots' mean and s the least-squares slope, each of the six
/// coordinates on its own. Knots already on such a line are left unchanged.
///
/// Bézier knots evenly spaced on a line through the origin give a constant-speed screw motion:
/// the factors Exp(b_j(u) ξ_j) then commute, and with Σ_j b_j(u) t_j = u the product is
/// Exp(Σ_j b_j(u) ξ_j), linear in u. Linear and B-spline trajectories interpolate translation
/// and rotation apart, so for them this holds for a pure translation or rotation. The blur model sees an exposure's poses only as
/// a set, so a path may fold back on itself (a hook) and still fit the blurry image; a straight
/// path cannot, which is why the trainer projects onto this line early in the schedule
/// (`pose.straight_fraction`).
pub fn straighten_knots(knots: &mut [[f64; 6]]) {
    let k = knots.len();
    if k < 3 {
        // One or two points are their own least-squares line.
        return;
    }
    let t: Vec<f64> = (0..k).map(|j| j as f64 / (k - 1) as f64 - 0.5).collect();
    let tt: f64 = t.iter().map(|t| t * t).sum();
    for i in 0..6 {
        let mean = knots.iter().map(|x| x[i]).sum::<f64>() / k as f64;
        let slope = knots.iter().zip(&t).map(|(x, t)| x[i] * t).sum::<f64>() / tt;
        for (x, t) in knots.iter_mut().zip(&t) {
            x[i] = mean + slope * t;
        }
    }
}

/// Shifts every knot by one se(3) vector s so that the pose at u = ½ is the identity: the
/// exposure's midpoint is held on the initial camera, c2w(½) = c2w_init, while the path keeps its
/// shape about it (a common shift of the knots moves a path rigidly to first order, exactly for a
/// straight path of [`straighten_knots`]). s solves Log Δ(½; ξ + s) = 0 by Newton's method on the
/// right perturbation, Δ(½; ξ + s) ≈ Δ(½; ξ) · Exp((Σ_j J_j) s), with the J_j of
/// [`Trajectory::eval_with_jacobians`]; it stops below `tol` in the tangent space or after
/// `max_iter` iterations. Returns the final ‖Log Δ(½)‖.
///
/// The trainer applies it after every knot step (`pose.hold_midpoint`): a hard form of
/// [`anchor_energy`], for cameras measured to be more accurate than the blurry photos can place
/// them, which no weight of an energy holds without fighting the photometric gradient in Adam.
pub fn hold_midpoint(traj: &mut Trajectory, tol: f64, max_iter: usize) -> f64 {
    let mut residual = traj.eval(0.5).log();
    for _ in 0..max_iter {
        if residual.norm() <= tol {
            break;
        }
        let j_sum = midpoint_jacobians(traj)
            .iter()
            .fold(Matrix6::<f64>::zeros(), |acc, j| acc + j);
        // Δ · Exp(J s) = I  ⇔  J s = Log(Δ⁻¹) = −Log Δ; J is the identity for a path at rest.
        let s = j_sum.lu().solve(&(-residual)).unwrap_or(-residual);
        for k in traj.knots_mut() {
            for (x, d) in k.iter_mut().zip(s.iter()) {
                *x += d;
            }
        }
        residual = traj.eval(0.5).log();
    }
    residual.norm()
}

/// Projects a knot gradient onto the directions that keep the pose at u = ½ where it is, the
/// tangent of [`hold_midpoint`]'s constraint: g_j ← g_j − J_jᵀ λ with
/// λ = (Σ_j J_j J_jᵀ)⁻¹ Σ_j J_j g_j, the J_j of [`Trajectory::eval_with_jacobians`] at u = ½, so
/// that Σ_j J_j g_j = 0 afterwards. The trainer applies it before the knot Adam step when
/// midpoints are held: Adam scales each coordinate by its own history, so a photometric pull on
/// the midpoint that the hold undoes every step would otherwise dominate every knot's update and
/// leave the path's shape unlearned.
pub fn midpoint_tangent_gradient(traj: &Trajectory, grads: &mut [[f64; 6]]) {
    let js = midpoint_jacobians(traj);
    let jjt = js
        .iter()
        .fold(Matrix6::<f64>::zeros(), |acc, j| acc + j * j.transpose());
    let jg = js
        .iter()
        .zip(grads.iter())
        .fold(Vector6::<f64>::zeros(), |acc, (j, g)| {
            acc + j * Vector6::from(*g)
        });
    let Some(lambda) = jjt.lu().solve(&jg) else {
        return;
    };
    for (j, g) in js.iter().zip(grads.iter_mut()) {
        let d = j.transpose() * lambda;
        for (x, d) in g.iter_mut().zip(d.iter()) {
            *x -= d;
        }
    }
}

/// The knot Jacobians J_j of the pose at u = ½ ([`Trajectory::eval_with_jacobians`]).
fn midpoint_jacobians(traj: &Trajectory) -> Vec<Matrix6<f64>> {
    let (_, jacs) = traj.eval_with_jacobians(0.5);
    jacs.iter()
        .map(|j| Matrix6::from_fn(|r, c| j[r][c]))
        .collect()
}

/// Weights that pick the median of `logs` along their principal axis: 1 on the middle pose, or
/// ½ on each of the two middle poses of an even count.
fn median_weights(logs: &[Vector6<f64>]) -> Vec<f64> {
    let n = logs.len();
    let mean: Vector6<f64> = logs.iter().sum::<Vector6<f64>>() / n as f64;
    // Each block (translation ρ, rotation φ) scaled to unit RMS spread; a block that does not
    // move is left at zero rather than blown up.
    let spread = |block: usize| {
        let ms = logs
            .iter()
            .map(|xi| (xi - mean).fixed_rows::<3>(3 * block).norm_squared())
            .sum::<f64>()
            / n as f64;
        if ms > 1e-24 { 1.0 / ms.sqrt() } else { 0.0 }
    };
    let scale = [spread(0), spread(1)];
    let centred: Vec<Vector6<f64>> = logs
        .iter()
        .map(|xi| Vector6::from_fn(|i, _| (xi[i] - mean[i]) * scale[i / 3]))
        .collect();
    let cov: Matrix6<f64> = centred.iter().map(|y| y * y.transpose()).sum();
    let eig = cov.symmetric_eigen();
    let axis = eig.eigenvectors.column(eig.eigenvalues.imax()).into_owned();
    let along: Vec<f64> = centred.iter().map(|y| y.dot(&axis)).collect();
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&a, &b| along[a].total_cmp(&along[b]).then(a.cmp(&b)));
    let mut w = vec![0.0; n];
    if n % 2 == 1 {
        w[order[n / 2]] = 1.0;
    } else {
        w[order[n / 2 - 1]] = 0.5;
        w[order[n / 2]] = 0.5;
    }
    w
}

fn bezier_with_jacobians(knots: &[[f64; 6]], u: f64) -> (Se3, Vec<Jacobian6>) {
    let b = bernstein(knots.len() - 1, u);
    let scaled: Vec<Vector6<f64>> = knots
        .iter()
        .zip(&b)
        .map(|(k, &bj)| Vector6::from(*k) * bj)
        .collect();
    let factors: Vec<Se3> = scaled.iter().map(Se3::exp).collect();
    // suffix[j] = E_{j+1} ··· E_M: the part of the product to the right of factor j.
    let mut suffix = vec![Se3::identity(); knots.len()];
    for j in (0..knots.len() - 1).rev() {
        suffix[j] = factors[j + 1] * suffix[j + 1];
    }
    let pose = factors[0] * suffix[0];
    // A E_j Exp(η) S = A E_j S Exp(Ad(S⁻¹) η), and E_j(ξ_j + dξ) ≈ E_j Exp(b_j 𝒥_r(b_j ξ_j) dξ).
    let jacs = (0..knots.len())
        .map(|j| to_rows(&(suffix[j].inverse().adjoint() * se3_right_jacobian(&scaled[j]) * b[j])))
        .collect();
    (pose, jacs)
}

/// Shared machinery of the linear and cubic B-spline variants: translations blended with weights
/// `tw`, rotations as R₀ · Π_k Exp(c_k Log(R_{k−1}ᵀ R_k)).
struct SplitSpline {
    xi: Vec<Vector6<f64>>,
    knots: Vec<Se3>,
    tw: Vec<f64>,
    cw: Vec<f64>,
    rel: Vec<Vector3<f64>>,
    factors: Vec<Matrix3<f64>>,
}

impl SplitSpline {
    fn new(knots: &[[f64; 6]], u: f64) -> Self {
        let (tw, cw) = if knots.len() == 2 {
            (vec![1.0 - u, u], vec![u])
        } else {
            let (u2, u3) = (u * u, u * u * u);
            (
                vec![
                    (1.0 - 3.0 * u + 3.0 * u2 - u3) / 6.0,
                    (4.0 - 6.0 * u2 + 3.0 * u3) / 6.0,
                    (1.0 + 3.0 * u + 3.0 * u2 - 3.0 * u3) / 6.0,
                    u3 / 6.0,
                ],
                vec![
                    (5.0 + 3.0 * u - 3.0 * u2 + u3) / 6.0,
                    (1.0 + 3.0 * u + 3.0 * u2 - 2.0 * u3) / 6.0,
                    u3 / 6.0,
                ],
            )
        };
        let xi: Vec<Vector6<f64>> = knots.iter().map(|k| Vector6::from(*k)).collect();
        let poses: Vec<Se3> = xi.iter().map(Se3::exp).collect();
        // rel[k-1] = Log(R_{k−1}ᵀ R_k), factors[k-1] = Exp(c_k rel[k-1]) for k = 1..K−1.
        let rel: Vec<Vector3<f64>> = poses
            .windows(2)
            .map(|w| So3(w[0].rot.transpose() * w[1].rot).log())
            .collect();
        let factors = rel
            .iter()
            .zip(&cw)
            .map(|(r, &c)| So3::exp(&(r * c)).0)
            .collect();
        SplitSpline {
            xi,
            knots: poses,
            tw,
            cw,
            rel,
            factors,
        }
    }

    fn rotation(&self) -> Matrix3<f64> {
        self.factors
            .iter()
            .fold(self.knots[0].rot, |acc, f| acc * f)
    }

    fn pose(&self) -> Se3 {
        let t = self
            .knots
            .iter()
            .zip(&self.tw)
            .fold(Vector3::zeros(), |acc, (k, &w)| acc + k.trans * w);
        Se3::new(self.rotation(), t)
    }

    fn with_jacobians(&self) -> (Se3, Vec<Jacobian6>) {
        let pose = self.pose();
        let n = self.knots.len();
        let segs = self.factors.len();
        // suffix[k] = F_{k+1} ··· F_last (segment indices 0-based), so Π F = F_0 · suffix[0].
        let mut suffix = vec![Matrix3::identity(); segs];
        for k in (0..segs - 1).rev() {
            suffix[k] = self.factors[k + 1] * suffix[k + 1];
        }
        let all = self.factors[0] * suffix[0];
        // g[k]: right-perturbation of R(u) per unit change of rel[k].
        let g: Vec<Matrix3<f64>> = (0..segs)
            .map(|k| {
                suffix[k].transpose() * so3_right_jacobian(&(self.rel[k] * self.cw[k])) * self.cw[k]
            })
            .collect();
        let jacs = (0..n)
            .map(|i| {
                // Rotation block: a right perturbation a of R_i changes R₀ (if i = 0), rel[i−1]
                // by J_r⁻¹ a and rel[i] by −J_l⁻¹ a.
                let mut drot = Matrix3::zeros();
                if i == 0 {
                    drot += all.transpose();
                }
                if i >= 1 {
                    drot += g[i - 1] * so3_right_jacobian_inv(&self.rel[i - 1]);
                }
                if i < segs {
                    drot -= g[i] * so3_left_jacobian_inv(&self.rel[i]);
                }
                // Translation block: a right perturbation η_ρ of T_i moves t_i by R_i η_ρ.
                let dtrans = pose.rot.transpose() * self.knots[i].rot * self.tw[i];
                let mut m = Matrix6::zeros();
                m.fixed_view_mut::<3, 3>(0, 0).copy_from(&dtrans);
                m.fixed_view_mut::<3, 3>(3, 3).copy_from(&drot);
                to_rows(&(m * se3_right_jacobian(&self.xi[i])))
            })
            .collect();
        (pose, jacs)
    }
}

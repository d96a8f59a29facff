//! Global re-initialisation of an incremental reconstruction: rotation averaging over all
//! verified pairs, then camera positions from the known-rotation linear problem.
//!
//! Why: under heavy blur the tracks are short (a few neighbouring views) and each two-view
//! geometry has a weak rotation/translation (bas-relief) direction. Registering views one by one
//! chains those weak directions into a bent camera path whose reprojection error is barely
//! higher than the true one's, so bundle adjustment stays there. Averaging the relative rotations
//! of every overlapping pair at once, and solving for all positions jointly with those rotations
//! held, starts the final bundle adjustment in the right basin.

use super::PairCorr;
use super::ba::Intrinsics;
use super::geometry::{self, Pose};
use super::incremental::Recon;
use nalgebra::{DMatrix, Matrix3, Rotation3, SymmetricEigen, Vector3};

/// One relative rotation: R_j = r · R_i, with its inlier count as weight.
pub(crate) struct RelRot {
    pub i: usize,
    pub j: usize,
    pub r: Matrix3<f64>,
    pub weight: f64,
}

/// Relative rotations of every pair with at least `min_inliers` essential-matrix inliers.
pub(crate) fn relative_rotations(
    pairs: &[PairCorr],
    k: &Intrinsics,
    thresh_px: f64,
    min_inliers: usize,
    seed: u64,
) -> Vec<RelRot> {
    use rayon::prelude::*;
    pairs
        .par_iter()
        .filter_map(|pc| {
            let x1: Vec<_> = pc.x1.iter().map(|p| k.normalise(p)).collect();
            let x2: Vec<_> = pc.x2.iter().map(|p| k.normalise(p)).collect();
            let s = seed.wrapping_add(0x3000 + (pc.i * 7919 + pc.j) as u64);
            let (e, mask) = geometry::ransac_epipolar(&x1, &x2, true, thresh_px / k.f, 1000, s)?;
            let (a, b): (Vec<_>, Vec<_>) = (0..x1.len())
                .filter(|&i| mask[i])
                .map(|i| (x1[i], x2[i]))
                .unzip();
            if a.len() < min_inliers {
                return None;
            }
            let (rel, _) = geometry::decompose_essential(&e, &a, &b)?;
            Some(RelRot {
                i: pc.i,
                j: pc.j,
                r: rel.r.into_inner(),
                weight: a.len() as f64,
            })
        })
        .collect()
}

fn project_so3(m: &Matrix3<f64>) -> Option<Matrix3<f64>> {
    let svd = m.svd(true, true);
    let (u, vt) = (svd.u?, svd.v_t?);
    let mut r = u * vt;
    if r.determinant() < 0.0 {
        let mut u2 = u;
        u2.column_mut(2).neg_mut();
        r = u2 * vt;
    }
    Some(r)
}

/// Robust chordal rotation averaging by weighted Gauss–Seidel sweeps from `init` (views with
/// None stay None); the first registered view is held (the gauge). Each edge is re-weighted by
/// a Cauchy function of its angular residual (2° scale), so a few wrong pairs cannot bend it.
pub(crate) fn average_rotations(
    init: &[Option<Matrix3<f64>>],
    rels: &[RelRot],
    sweeps: usize,
) -> Vec<Option<Matrix3<f64>>> {
    let mut r = init.to_vec();
    let Some(anchor) = r.iter().position(|x| x.is_some()) else {
        return r;
    };
    let scale = 2f64.to_radians();
    for _ in 0..sweeps {
        for v in 0..r.len() {
            if v == anchor || r[v].is_none() {
                continue;
            }
            let mut m = Matrix3::zeros();
            for e in rels {
                // Estimates of R_v from the edge and the other view's current rotation.
                let est = if e.i == v {
                    r[e.j].map(|rj| e.r.transpose() * rj)
                } else if e.j == v {
                    r[e.i].map(|ri| e.r * ri)
                } else {
                    None
                };
                let Some(est) = est else { continue };
                let cur = r[v].expect("registered");
                let ang = Rotation3::from_matrix_unchecked(est * cur.transpose()).angle();
                let w = e.weight / (1.0 + (ang / scale).powi(2));
                m += est * w;
            }
            if let Some(p) = project_so3(&m) {
                r[v] = Some(p);
            }
        }
    }
    r
}

/// Camera translations from fixed rotations and the reconstruction's active observations:
/// each observation gives [x]ₓ(R·X + t) = 0, linear in t and X. Points are eliminated
/// (Schur complement) and the smallest eigenvector of the reduced camera system, with the
/// first registered camera at t = 0, gives all translations up to scale; the sign that puts most
/// points in front of the cameras is taken. None when the system is degenerate.
pub(crate) fn positions_from_rotations(
    r: &Recon,
    rot: &[Option<Matrix3<f64>>],
) -> Option<Vec<Option<Pose>>> {
    let views: Vec<usize> = (0..rot.len()).filter(|&v| rot[v].is_some()).collect();
    if views.len() < 3 {
        return None;
    }
    let anchor = views[0];
    let mut col = vec![usize::MAX; rot.len()];
    for (k, &v) in views[1..].iter().enumerate() {
        col[v] = 3 * k;
    }
    let n = 3 * (views.len() - 1);
    let mut s = DMatrix::<f64>::zeros(n, n);
    for t in &r.tracks {
        if t.xyz.is_none() {
            continue;
        }
        let obs: Vec<_> = t
            .obs
            .iter()
            .filter(|o| o.active && rot[o.view].is_some())
            .collect();
        if obs.len() < 2 {
            continue;
        }
        // Per observation rows: A_t = [x]ₓ (on t), A_x = [x]ₓ R (on X); unit bearings so the
        // residual is an angle, not scaled by depth.
        let mut axx = Matrix3::<f64>::zeros();
        let mut blocks: Vec<(usize, Matrix3<f64>, Matrix3<f64>)> = Vec::with_capacity(obs.len());
        for o in &obs {
            let xn = r.k.normalise(&o.xy);
            let b = Vector3::new(xn.x, xn.y, 1.0).normalize();
            let cx = b.cross_matrix();
            let ax = cx * rot[o.view].expect("rotation");
            axx += ax.transpose() * ax;
            blocks.push((o.view, cx, ax));
        }
        let Some(inv) = axx.try_inverse() else {
            continue;
        };
        // S += Σ A_tᵀA_t (diagonal) − (Σ A_tᵀA_x) inv (Σ A_xᵀA_t).
        let mut atx: Vec<(usize, Matrix3<f64>)> = Vec::with_capacity(blocks.len());
        for (v, cx, ax) in &blocks {
            if col[*v] == usize::MAX {
                continue;
            }
            let c = col[*v];
            let att = cx.transpose() * cx;
            for a in 0..3 {
                for b in 0..3 {
                    s[(c + a, c + b)] += att[(a, b)];
                }
            }
            atx.push((*v, cx.transpose() * ax));
        }
        for (va, ma) in &atx {
            for (vb, mb) in &atx {
                let blk = ma * inv * mb.transpose();
                let (ca, cb) = (col[*va], col[*vb]);
                for a in 0..3 {
                    for b in 0..3 {
                        s[(ca + a, cb + b)] -= blk[(a, b)];
                    }
                }
            }
        }
    }
    let eig = SymmetricEigen::new(s);
    let imin = eig
        .eigenvalues
        .iter()
        .enumerate()
        .min_by(|a, b| a.1.total_cmp(b.1))
        .map(|(i, _)| i)?;
    let sol = eig.eigenvectors.column(imin).into_owned();
    if !sol.iter().all(|x| x.is_finite()) {
        return None;
    }
    let build = |sign: f64| -> Vec<Option<Pose>> {
        (0..rot.len())
            .map(|v| {
                let rm = rot[v]?;
                let t = if v == anchor {
                    Vector3::zeros()
                } else {
                    let c = col[v];
                    Vector3::new(sol[c], sol[c + 1], sol[c + 2]) * sign
                };
                Some(Pose {
                    r: Rotation3::from_matrix_unchecked(rm),
                    t,
                })
            })
            .collect()
    };
    // Cheirality vote over a sample of tracks.
    let mut best: Option<(usize, Vec<Option<Pose>>)> = None;
    for sign in [1.0, -1.0] {
        let poses = build(sign);
        let mut front = 0;
        for t in r.tracks.iter().filter(|t| t.xyz.is_some()).step_by(7) {
            let obs: Vec<(Pose, nalgebra::Vector2<f64>)> = t
                .obs
                .iter()
                .filter(|o| o.active)
                .filter_map(|o| poses[o.view].map(|p| (p, r.k.normalise(&o.xy))))
                .collect();
            if let Some(x) = geometry::triangulate(&obs) {
                front += obs.iter().filter(|(p, _)| p.transform(&x).z > 0.0).count();
            }
        }
        if best.as_ref().is_none_or(|b| front > b.0) {
            best = Some((front, poses));
        }
    }
    best.map(|b| b.1)
}

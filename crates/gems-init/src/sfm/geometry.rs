//! Multi-view geometry in f64: normalised eight-point fundamental/essential estimation with
//! RANSAC, essential decomposition with the cheirality test, DLT triangulation, DLT PnP with
//! RANSAC and Gauss–Newton pose refinement.
//!
//! Poses are cam_from_world [`Se3`]s: X_cam = R·X_world + t (OpenCV camera, z forward).

use gems_math::Se3;
use nalgebra::{DMatrix, Matrix3, Matrix3x4, Rotation3, SVD, SymmetricEigen, Vector2, Vector3};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// The 3×4 projection matrix [R | t] of a cam_from_world pose.
fn projection_matrix(pose: &Se3) -> Matrix3x4<f64> {
    let mut m = Matrix3x4::zeros();
    m.fixed_view_mut::<3, 3>(0, 0).copy_from(&pose.rot);
    m.set_column(3, &pose.trans);
    m
}

/// Eigenvector of the smallest eigenvalue of AᵀA (the least-squares null vector of A).
fn null_vector(a: &DMatrix<f64>) -> nalgebra::DVector<f64> {
    let ata = a.transpose() * a;
    let eig = SymmetricEigen::new(ata);
    let imin = eig
        .eigenvalues
        .iter()
        .enumerate()
        .min_by(|x, y| x.1.total_cmp(y.1))
        .map(|(i, _)| i)
        .unwrap_or(0);
    eig.eigenvectors.column(imin).into_owned()
}

/// Similarity that moves the centroid to 0 and makes the mean distance √2 (Hartley).
fn normaliser(pts: &[Vector2<f64>]) -> Matrix3<f64> {
    let n = pts.len().max(1) as f64;
    let c = pts.iter().fold(Vector2::zeros(), |a, p| a + p) / n;
    let d = pts.iter().map(|p| (p - c).norm()).sum::<f64>() / n;
    let s = if d > 1e-12 { 2f64.sqrt() / d } else { 1.0 };
    Matrix3::new(s, 0.0, -s * c.x, 0.0, s, -s * c.y, 0.0, 0.0, 1.0)
}

fn apply_h(h: &Matrix3<f64>, p: &Vector2<f64>) -> Vector2<f64> {
    let v = h * Vector3::new(p.x, p.y, 1.0);
    Vector2::new(v.x / v.z, v.y / v.z)
}

/// Eight-point estimate of F with x2ᵀ F x1 = 0 (Hartley-normalised). With `essential` the two
/// non-zero singular values are equalised (calibrated input), otherwise rank 2 is enforced.
pub fn eight_point(
    x1: &[Vector2<f64>],
    x2: &[Vector2<f64>],
    essential: bool,
) -> Option<Matrix3<f64>> {
    let n = x1.len();
    if n < 8 || x2.len() != n {
        return None;
    }
    let t1 = normaliser(x1);
    let t2 = normaliser(x2);
    let mut a = DMatrix::zeros(n, 9);
    for i in 0..n {
        let p = apply_h(&t1, &x1[i]);
        let q = apply_h(&t2, &x2[i]);
        let row = [
            q.x * p.x,
            q.x * p.y,
            q.x,
            q.y * p.x,
            q.y * p.y,
            q.y,
            p.x,
            p.y,
            1.0,
        ];
        for (k, v) in row.iter().enumerate() {
            a[(i, k)] = *v;
        }
    }
    let f = null_vector(&a);
    let fm = Matrix3::from_row_slice(f.as_slice());
    let svd = SVD::new(fm, true, true);
    let (u, vt) = (svd.u?, svd.v_t?);
    let s = svd.singular_values;
    let d = Matrix3::from_diagonal(&Vector3::new(s[0], s[1], 0.0));
    let f = t2.transpose() * (u * d * vt) * t1;
    // The essential constraint holds in the calibrated frame, so it is enforced after
    // de-normalisation.
    if essential {
        let svd = SVD::new(f, true, true);
        let (u, vt) = (svd.u?, svd.v_t?);
        let e = u * Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, 0.0)) * vt;
        return Some(e / e.norm());
    }
    Some(f / f.norm())
}

/// Squared Sampson distance of a correspondence to the epipolar geometry F.
#[inline]
pub fn sampson_sq(f: &Matrix3<f64>, p: &Vector2<f64>, q: &Vector2<f64>) -> f64 {
    let x1 = Vector3::new(p.x, p.y, 1.0);
    let x2 = Vector3::new(q.x, q.y, 1.0);
    let fx1 = f * x1;
    let ftx2 = f.transpose() * x2;
    let num = x2.dot(&fx1);
    let den = fx1.x * fx1.x + fx1.y * fx1.y + ftx2.x * ftx2.x + ftx2.y * ftx2.y;
    if den <= 1e-300 {
        return f64::INFINITY;
    }
    num * num / den
}

/// RANSAC over eight-point samples. `thresh` is the Sampson threshold in the units of the input.
/// Returns the model refitted on all inliers and the inlier mask.
pub fn ransac_epipolar(
    x1: &[Vector2<f64>],
    x2: &[Vector2<f64>],
    essential: bool,
    thresh: f64,
    max_iters: usize,
    seed: u64,
) -> Option<(Matrix3<f64>, Vec<bool>)> {
    let n = x1.len();
    if n < 12 {
        return None;
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let t2 = thresh * thresh;
    let count = |f: &Matrix3<f64>| -> usize {
        (0..n)
            .filter(|&i| sampson_sq(f, &x1[i], &x2[i]) < t2)
            .count()
    };
    let mut best: Option<(Matrix3<f64>, usize)> = None;
    let mut iters = max_iters;
    let mut it = 0;
    let mut s1 = Vec::with_capacity(8);
    let mut s2 = Vec::with_capacity(8);
    while it < iters {
        it += 1;
        let idx = sample_distinct(&mut rng, n, 8);
        s1.clear();
        s2.clear();
        for &i in &idx {
            s1.push(x1[i]);
            s2.push(x2[i]);
        }
        let Some(f) = eight_point(&s1, &s2, essential) else {
            continue;
        };
        let c = count(&f);
        if best.as_ref().is_none_or(|b| c > b.1) {
            best = Some((f, c));
            iters = iters.min(adaptive_iters(c as f64 / n as f64, 8, max_iters));
        }
    }
    let (mut f, _) = best?;
    // Two rounds of refitting on the inliers (local optimisation).
    for _ in 0..2 {
        let (a, b): (Vec<_>, Vec<_>) = (0..n)
            .filter(|&i| sampson_sq(&f, &x1[i], &x2[i]) < t2)
            .map(|i| (x1[i], x2[i]))
            .unzip();
        match eight_point(&a, &b, essential) {
            Some(g) if count(&g) >= count(&f) => f = g,
            _ => break,
        }
    }
    let mask: Vec<bool> = (0..n)
        .map(|i| sampson_sq(&f, &x1[i], &x2[i]) < t2)
        .collect();
    Some((f, mask))
}

fn adaptive_iters(inlier_ratio: f64, sample: i32, max_iters: usize) -> usize {
    let p = inlier_ratio.powi(sample).clamp(1e-12, 1.0 - 1e-12);
    let k = (1.0f64 - 0.999).ln() / (1.0 - p).ln();
    (k.ceil() as usize).clamp(50, max_iters)
}

fn sample_distinct(rng: &mut ChaCha8Rng, n: usize, k: usize) -> Vec<usize> {
    let mut out = Vec::with_capacity(k);
    while out.len() < k {
        let i = rng.random_range(0..n);
        if !out.contains(&i) {
            out.push(i);
        }
    }
    out
}

/// Linear (DLT) triangulation from calibrated observations `(pose, normalised xy)`.
pub fn triangulate(obs: &[(Se3, Vector2<f64>)]) -> Option<Vector3<f64>> {
    if obs.len() < 2 {
        return None;
    }
    let mut a = DMatrix::zeros(2 * obs.len(), 4);
    for (k, (pose, x)) in obs.iter().enumerate() {
        let p = projection_matrix(pose);
        for c in 0..4 {
            a[(2 * k, c)] = x.x * p[(2, c)] - p[(0, c)];
            a[(2 * k + 1, c)] = x.y * p[(2, c)] - p[(1, c)];
        }
    }
    let v = null_vector(&a);
    if v[3].abs() < 1e-12 {
        return None;
    }
    let x = Vector3::new(v[0] / v[3], v[1] / v[3], v[2] / v[3]);
    x.iter().all(|c| c.is_finite()).then_some(x)
}

/// The four (R, t) factorisations of E; the one putting most points in front of both cameras
/// wins. Returns the pose of camera 2 relative to camera 1 and the per-correspondence cheirality.
pub fn decompose_essential(
    e: &Matrix3<f64>,
    x1: &[Vector2<f64>],
    x2: &[Vector2<f64>],
) -> Option<(Se3, Vec<bool>)> {
    let svd = SVD::new(*e, true, true);
    let (mut u, mut vt) = (svd.u?, svd.v_t?);
    if u.determinant() < 0.0 {
        u = -u;
    }
    if vt.determinant() < 0.0 {
        vt = -vt;
    }
    let w = Matrix3::new(0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0);
    let t = u.column(2).into_owned();
    let mut best: Option<(Se3, Vec<bool>, usize)> = None;
    for r in [u * w * vt, u * w.transpose() * vt] {
        for s in [1.0, -1.0] {
            let pose = Se3::new(r, t * s);
            let front: Vec<bool> = x1
                .iter()
                .zip(x2)
                .map(|(a, b)| {
                    triangulate(&[(Se3::identity(), *a), (pose, *b)])
                        .is_some_and(|x| x.z > 0.0 && pose.act(&x).z > 0.0)
                })
                .collect();
            let c = front.iter().filter(|&&f| f).count();
            if best.as_ref().is_none_or(|b| c > b.2) {
                best = Some((pose, front, c));
            }
        }
    }
    best.map(|(p, f, _)| (p, f))
}

/// Linear PnP from ≥ 6 world points and calibrated observations; R is projected onto SO(3).
pub fn pnp_dlt(xw: &[Vector3<f64>], xn: &[Vector2<f64>]) -> Option<Se3> {
    let n = xw.len();
    if n < 6 {
        return None;
    }
    // Normalise the 3-D points for conditioning.
    let c = xw.iter().fold(Vector3::zeros(), |a, p| a + p) / n as f64;
    let s = xw.iter().map(|p| (p - c).norm()).sum::<f64>() / n as f64;
    if s < 1e-12 {
        return None;
    }
    let s = 3f64.sqrt() / s;
    let mut a = DMatrix::zeros(2 * n, 12);
    for i in 0..n {
        let p = (xw[i] - c) * s;
        let (u, v) = (xn[i].x, xn[i].y);
        let ph = [p.x, p.y, p.z, 1.0];
        for k in 0..4 {
            a[(2 * i, k)] = ph[k];
            a[(2 * i, 8 + k)] = -u * ph[k];
            a[(2 * i + 1, 4 + k)] = ph[k];
            a[(2 * i + 1, 8 + k)] = -v * ph[k];
        }
    }
    let v = null_vector(&a);
    let mut m = Matrix3x4::from_row_slice(v.as_slice());
    // Sign: points must be in front.
    let front = (0..n)
        .filter(|&i| {
            let p = (xw[i] - c) * s;
            (m.row(2) * nalgebra::Vector4::new(p.x, p.y, p.z, 1.0))[0] > 0.0
        })
        .count();
    if front * 2 < n {
        m = -m;
    }
    let r = m.fixed_view::<3, 3>(0, 0).into_owned();
    let svd = SVD::new(r, true, true);
    let (u, vt) = (svd.u?, svd.v_t?);
    let mut rot = u * vt;
    let scale = svd.singular_values.mean();
    if rot.determinant() < 0.0 || scale < 1e-12 {
        return None;
    }
    if !rot.iter().all(|x| x.is_finite()) {
        return None;
    }
    let t_norm = m.column(3) / scale;
    // Undo the point normalisation: X' = s(X − c)  ⇒  t = t' − R·c·… (t' is for X').
    // R X' + t' = s·R X − s·R c + t' ; dividing by s: R X + (t' / s − R c).
    let t = t_norm / s - rot * c;
    rot = Rotation3::from_matrix(&rot).into_inner();
    Some(Se3::new(rot, t))
}

/// Robust Gauss–Newton refinement of a single pose on calibrated observations (Huber on the
/// normalised reprojection error, `huber` in normalised units).
pub fn refine_pose(
    pose: Se3,
    xw: &[Vector3<f64>],
    xn: &[Vector2<f64>],
    huber: f64,
    iters: usize,
) -> Se3 {
    let mut p = pose;
    for _ in 0..iters {
        let mut h = nalgebra::Matrix6::<f64>::zeros();
        let mut g = nalgebra::Vector6::<f64>::zeros();
        for (x, o) in xw.iter().zip(xn) {
            let rx = p.rot * x;
            let xc = rx + p.trans;
            if xc.z <= 1e-9 {
                continue;
            }
            let iz = 1.0 / xc.z;
            let r = Vector2::new(xc.x * iz - o.x, xc.y * iz - o.y);
            let nr = r.norm();
            let w = if nr <= huber { 1.0 } else { huber / nr };
            let dpi = nalgebra::Matrix2x3::new(iz, 0.0, -xc.x * iz * iz, 0.0, iz, -xc.y * iz * iz);
            let mut j = nalgebra::Matrix2x6::<f64>::zeros();
            // δ = (ω, v): Xc = exp(ω)·R·X + t + v  ⇒  ∂Xc/∂ω = −[R X]×, ∂Xc/∂v = I.
            let skew = -rx.cross_matrix();
            j.fixed_view_mut::<2, 3>(0, 0).copy_from(&(dpi * skew));
            j.fixed_view_mut::<2, 3>(0, 3).copy_from(&dpi);
            h += j.transpose() * j * w;
            g += j.transpose() * r * w;
        }
        for i in 0..6 {
            h[(i, i)] += 1e-9 + 1e-6 * h[(i, i)];
        }
        let Some(d) = h.cholesky().map(|c| c.solve(&(-g))) else {
            break;
        };
        let w = Vector3::new(d[0], d[1], d[2]);
        p.rot = Rotation3::new(w).into_inner() * p.rot;
        p.trans += Vector3::new(d[3], d[4], d[5]);
        if d.norm() < 1e-10 {
            break;
        }
    }
    p
}

/// RANSAC PnP: DLT on 6-point samples, Gauss–Newton on the inliers. `thresh` is in normalised
/// image units. Returns the pose and inlier mask.
pub fn ransac_pnp(
    xw: &[Vector3<f64>],
    xn: &[Vector2<f64>],
    thresh: f64,
    max_iters: usize,
    seed: u64,
) -> Option<(Se3, Vec<bool>)> {
    let n = xw.len();
    if n < 8 {
        return None;
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let inl = |p: &Se3| -> Vec<bool> {
        xw.iter()
            .zip(xn)
            .map(|(x, o)| {
                let c = p.act(x);
                c.z > 0.0 && (Vector2::new(c.x / c.z, c.y / c.z) - o).norm() < thresh
            })
            .collect()
    };
    let mut best: Option<(Se3, usize)> = None;
    let mut iters = max_iters;
    let mut it = 0;
    while it < iters {
        it += 1;
        let idx = sample_distinct(&mut rng, n, 6);
        let sw: Vec<_> = idx.iter().map(|&i| xw[i]).collect();
        let sn: Vec<_> = idx.iter().map(|&i| xn[i]).collect();
        let Some(p) = pnp_dlt(&sw, &sn) else { continue };
        let c = inl(&p).iter().filter(|&&b| b).count();
        if best.as_ref().is_none_or(|b| c > b.1) {
            best = Some((p, c));
            iters = iters.min(adaptive_iters(c as f64 / n as f64, 6, max_iters));
        }
    }
    let (mut p, _) = best?;
    for _ in 0..3 {
        let mask = inl(&p);
        let (a, b): (Vec<_>, Vec<_>) = (0..n).filter(|&i| mask[i]).map(|i| (xw[i], xn[i])).unzip();
        if a.len() < 6 {
            return None;
        }
        p = refine_pose(p, &a, &b, thresh * 0.5, 10);
    }
    let mask = inl(&p);
    Some((p, mask))
}

/// Angle (radians) between the rays from two camera centres to `x`.
pub fn triangulation_angle(c1: &Vector3<f64>, c2: &Vector3<f64>, x: &Vector3<f64>) -> f64 {
    let a = (x - c1).normalize();
    let b = (x - c2).normalize();
    a.dot(&b).clamp(-1.0, 1.0).acos()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Angle of the rotation between two poses' rotations.
    fn relative_angle(a: &Se3, b: &Se3) -> f64 {
        Rotation3::from_matrix_unchecked(a.rot.transpose() * b.rot).angle()
    }
    use rand::RngExt;

    fn random_scene(seed: u64, n: usize) -> (Vec<Vector3<f64>>, Se3, Se3) {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let pts = (0..n)
            .map(|_| {
                Vector3::new(
                    rng.random_range(-1.0..1.0),
                    rng.random_range(-1.0..1.0),
                    rng.random_range(3.0..6.0),
                )
            })
            .collect();
        let p2 = Se3::new(
            Rotation3::new(Vector3::new(0.05, -0.1, 0.02)).into_inner(),
            Vector3::new(-0.6, 0.1, 0.05),
        );
        (pts, Se3::identity(), p2)
    }

    fn project(p: &Se3, x: &Vector3<f64>) -> Vector2<f64> {
        let c = p.act(x);
        Vector2::new(c.x / c.z, c.y / c.z)
    }

    #[test]
    fn essential_ransac_recovers_relative_pose_with_outliers() {
        let (pts, p1, p2) = random_scene(1, 150);
        let mut x1: Vec<_> = pts.iter().map(|x| project(&p1, x)).collect();
        let x2: Vec<_> = pts.iter().map(|x| project(&p2, x)).collect();
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        for x in x1.iter_mut().take(30) {
            *x += Vector2::new(rng.random_range(-0.2..0.2), rng.random_range(-0.2..0.2));
        }
        let (e, mask) = ransac_epipolar(&x1, &x2, true, 1e-3, 2000, 3).unwrap();
        assert!(mask[30..].iter().all(|&b| b));
        assert!(mask[..30].iter().filter(|&&b| b).count() < 5);
        let (a, b): (Vec<_>, Vec<_>) = (0..150)
            .filter(|&i| mask[i])
            .map(|i| (x1[i], x2[i]))
            .unzip();
        let (rel, _) = decompose_essential(&e, &a, &b).unwrap();
        let rerr = relative_angle(&rel, &p2);
        assert!(rerr < 1e-6, "rotation error {rerr}");
        let terr = rel.trans.normalize().dot(&p2.trans.normalize());
        assert!(terr > 1.0 - 1e-9, "translation direction cos {terr}");
    }

    #[test]
    fn pnp_recovers_pose_and_triangulation_is_exact() {
        let (pts, _, p2) = random_scene(2, 80);
        let mut xn: Vec<_> = pts.iter().map(|x| project(&p2, x)).collect();
        for x in xn.iter_mut().take(15) {
            *x += Vector2::new(0.3, -0.2);
        }
        let (p, mask) = ransac_pnp(&pts, &xn, 2e-3, 500, 5).unwrap();
        assert!(mask[15..].iter().all(|&b| b) && !mask[..15].iter().any(|&b| b));
        // acos near 1 limits the angle to ~1e-8 even for identical rotations.
        assert!(relative_angle(&p, &p2) < 1e-6);
        assert!((p.trans - p2.trans).norm() < 1e-8);

        let x = pts[20];
        let tri = triangulate(&[
            (Se3::identity(), project(&Se3::identity(), &x)),
            (p2, project(&p2, &x)),
        ])
        .unwrap();
        assert!((tri - x).norm() < 1e-9);
    }

    #[test]
    fn refine_pose_converges_from_perturbation() {
        let (pts, _, p2) = random_scene(3, 40);
        let xn: Vec<_> = pts.iter().map(|x| project(&p2, x)).collect();
        let start = Se3::new(
            Rotation3::new(Vector3::new(0.03, 0.02, -0.01)).into_inner() * p2.rot,
            p2.trans + Vector3::new(0.05, -0.05, 0.1),
        );
        let p = refine_pose(start, &pts, &xn, 1.0, 30);
        assert!(relative_angle(&p, &p2) < 1e-9);
        assert!((p.trans - p2.trans).norm() < 1e-9);
    }
}

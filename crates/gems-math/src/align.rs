//! Umeyama alignment (Sim(3) or SE(3)) of point sets and APE translation statistics, both exactly
//! as evo computes them (`evo.core.geometry.umeyama_alignment`, `evo.core.metrics.APE`).

use nalgebra::{Matrix3, Vector3};

use crate::{MathError, Se3, So3};

/// A similarity transform p ↦ s·R·p + t.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sim3 {
    pub scale: f64,
    pub rot: Matrix3<f64>,
    pub trans: Vector3<f64>,
}

impl Sim3 {
    pub fn identity() -> Self {
        Sim3 {
            scale: 1.0,
            rot: Matrix3::identity(),
            trans: Vector3::zeros(),
        }
    }

    pub fn act(&self, p: &[f64; 3]) -> [f64; 3] {
        (self.rot * Vector3::from(*p) * self.scale + self.trans).into()
    }

    /// A camera (camera-to-world pose) carried by this similarity: its centre mapped, its
    /// orientation rotated; the scale changes only where the centre lies.
    pub fn act_c2w(&self, c2w: &Se3) -> Se3 {
        Se3::new(
            self.rot * c2w.rot,
            self.scale * (self.rot * c2w.trans) + self.trans,
        )
    }
}

/// Least-squares (s, R, t) minimising Σ‖dst_i − (s R src_i + t)‖² (Umeyama 1991, evo's variant):
/// Σxy = (1/n) Σ (y−μy)(x−μx)ᵀ = U D Vᵀ, S = diag(1, 1, ±1) fixing reflections,
/// R = U S Vᵀ, s = tr(D S)/σx² (or 1 without scale), t = μy − s R μx.
pub fn umeyama(src: &[[f64; 3]], dst: &[[f64; 3]], with_scale: bool) -> Result<Sim3, MathError> {
    if src.len() != dst.len() {
        return Err(MathError::LengthMismatch {
            est: src.len(),
            reference: dst.len(),
        });
    }
    let n = src.len();
    if n == 0 {
        return Err(MathError::Degenerate("no points to align".into()));
    }
    let x: Vec<Vector3<f64>> = src.iter().map(|p| Vector3::from(*p)).collect();
    let y: Vec<Vector3<f64>> = dst.iter().map(|p| Vector3::from(*p)).collect();
    let nf = n as f64;
    let mx = x.iter().sum::<Vector3<f64>>() / nf;
    let my = y.iter().sum::<Vector3<f64>>() / nf;
    let sigma_x = x.iter().map(|p| (p - mx).norm_squared()).sum::<f64>() / nf;
    let cov = x.iter().zip(&y).fold(Matrix3::zeros(), |acc, (px, py)| {
        acc + (py - my) * (px - mx).transpose()
    }) / nf;
    let svd = cov.svd(true, true);
    let (u, vt) = (svd.u.expect("requested U"), svd.v_t.expect("requested V"));
    let d = svd.singular_values;
    // evo: fewer than m−1 singular values above machine epsilon → degenerate.
    if d.iter().filter(|&&s| s > f64::EPSILON).count() < 2 {
        return Err(MathError::Degenerate(
            "point sets are (nearly) collinear or coincident".into(),
        ));
    }
    let mut s = Matrix3::identity();
    // nalgebra sorts singular values in descending order, so index 2 is the smallest one.
    if u.determinant() * vt.determinant() < 0.0 {
        s[(2, 2)] = -1.0;
    }
    let rot = u * s * vt;
    let scale = if with_scale {
        if sigma_x <= 0.0 {
            return Err(MathError::Degenerate(
                "source points have zero spread".into(),
            ));
        }
        (Matrix3::from_diagonal(&d) * s).trace() / sigma_x
    } else {
        1.0
    };
    let trans = my - rot * mx * scale;
    Ok(Sim3 { scale, rot, trans })
}

/// The similarity taking one set of cameras onto another, from pairs of camera-to-world poses
/// of the same cameras (`(in A, in B)`): its rotation the chordal mean of the rotations'
/// differences R_B R_Aᵀ, its scale and translation by least squares on the camera centres under
/// that rotation. Unlike a centre-only Umeyama it needs no spread of centres across two
/// directions: a straight camera path leaves the rotation about it undetermined, the cameras'
/// orientations do not. `None` with fewer than two pairs or coincident centres.
pub fn camera_similarity(pairs: &[(Se3, Se3)]) -> Option<Sim3> {
    if pairs.len() < 2 {
        return None;
    }
    let sum = pairs.iter().fold(Matrix3::zeros(), |acc, (a, b)| {
        acc + b.rot * a.rot.transpose()
    });
    let rot = *So3::from_matrix_orthonormalized(&sum).matrix();
    let n = pairs.len() as f64;
    let mean_a = pairs.iter().map(|(a, _)| a.trans).sum::<Vector3<f64>>() / n;
    let mean_b = pairs.iter().map(|(_, b)| b.trans).sum::<Vector3<f64>>() / n;
    let (num, den) = pairs.iter().fold((0.0, 0.0), |(num, den), (a, b)| {
        let x = rot * (a.trans - mean_a);
        (num + (b.trans - mean_b).dot(&x), den + x.norm_squared())
    });
    if den <= f64::EPSILON {
        return None;
    }
    let scale = num / den;
    Some(Sim3 {
        scale,
        rot,
        trans: mean_b - scale * (rot * mean_a),
    })
}

/// How far one set of cameras lies from another after the first's best similarity onto the
/// second ([`camera_similarity`]), so that a change of frame, scale or gauge counts for nothing
/// and a change of shape for everything.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CameraDiscrepancy {
    /// RMSE of the centres, in % of the second set's extent (its largest centre distance).
    pub centre_pct: f64,
    /// RMSE of the relative rotations, in degrees.
    pub rotation_deg: f64,
    /// The share of the centres' difference that varies smoothly along the cameras' path, in
    /// [0, 1]: after the centres' own best similarity ([`umeyama`], so that the orientations'
    /// fit leaves no rotation of the path behind), the part of the squared differences a
    /// quadratic in the position along the second set's principal axis explains, fitted per
    /// coordinate. A bend or stretch of the path is systematic (near 1); each camera off on its
    /// own puts about 3 / (number of cameras) here by chance. 0 with fewer than four cameras
    /// or centres on one line.
    pub systematic_share: f64,
}

/// The [`CameraDiscrepancy`] of the pairs `(in A, in B)` (camera-to-world poses): A carried onto
/// B. `None` where the similarity is undetermined or B's centres coincide.
pub fn camera_discrepancy(pairs: &[(Se3, Se3)]) -> Option<CameraDiscrepancy> {
    let sim = camera_similarity(pairs)?;
    let extent = pairs
        .iter()
        .flat_map(|(_, a)| pairs.iter().map(move |(_, b)| (a.trans - b.trans).norm()))
        .fold(0.0, f64::max);
    if extent <= 0.0 {
        return None;
    }
    let n = pairs.len() as f64;
    let (c, r) = pairs.iter().fold((0.0, 0.0), |(c, r), (a, b)| {
        let a = sim.act_c2w(a);
        let dr = So3::from_matrix_orthonormalized(&(a.rot.transpose() * b.rot))
            .log()
            .norm();
        (
            c + (a.trans - b.trans).norm_squared(),
            r + dr.to_degrees().powi(2),
        )
    });
    Some(CameraDiscrepancy {
        centre_pct: 100.0 * (c / n).sqrt() / extent,
        rotation_deg: (r / n).sqrt(),
        systematic_share: systematic_share(pairs),
    })
}

/// [`CameraDiscrepancy::systematic_share`] of the pairs `(in A, in B)`.
fn systematic_share(pairs: &[(Se3, Se3)]) -> f64 {
    let a: Vec<[f64; 3]> = pairs.iter().map(|(a, _)| a.trans.into()).collect();
    let b: Vec<[f64; 3]> = pairs.iter().map(|(_, b)| b.trans.into()).collect();
    let Ok(sim) = umeyama(&a, &b, true) else {
        return 0.0;
    };
    let centres: Vec<Vector3<f64>> = b.iter().map(|&p| p.into()).collect();
    let diffs: Vec<Vector3<f64>> = a
        .iter()
        .zip(&centres)
        .map(|(p, q)| Vector3::from(sim.act(p)) - q)
        .collect();
    let total: f64 = diffs.iter().map(|d| d.norm_squared()).sum();
    if total <= 0.0 {
        return 0.0;
    }
    (smooth_part(&centres, &diffs) / total).clamp(0.0, 1.0)
}

/// The squared norm, summed over the cameras, of the least-squares fit of `values` (one per
/// camera) by a quadratic in each camera's position along the principal axis of `centres`:
/// what of the values changes smoothly along the path. 0 with fewer than four cameras, where a
/// quadratic fits anything, or when the centres coincide.
fn smooth_part(centres: &[Vector3<f64>], values: &[Vector3<f64>]) -> f64 {
    let n = centres.len();
    if n < 4 {
        return 0.0;
    }
    let mean = centres.iter().sum::<Vector3<f64>>() / n as f64;
    let cov = centres.iter().fold(Matrix3::zeros(), |acc, c| {
        let d = c - mean;
        acc + d * d.transpose()
    });
    let eig = cov.symmetric_eigen();
    let axis = eig.eigenvectors.column(eig.eigenvalues.imax()).into_owned();
    let along: Vec<f64> = centres.iter().map(|c| (c - mean).dot(&axis)).collect();
    let half = along.iter().fold(0.0f64, |m, &t| m.max(t.abs()));
    if half <= 0.0 {
        return 0.0;
    }
    let basis: Vec<Vector3<f64>> = along
        .iter()
        .map(|&t| {
            let t = t / half;
            Vector3::new(1.0, t, t * t)
        })
        .collect();
    let gram = basis
        .iter()
        .fold(Matrix3::zeros(), |acc, v| acc + v * v.transpose());
    let Some(inv) = gram.try_inverse() else {
        return 0.0;
    };
    // One right-hand side per coordinate: columns of Σ basis ⊗ value.
    let rhs = basis
        .iter()
        .zip(values)
        .fold(Matrix3::zeros(), |acc, (v, y)| acc + v * y.transpose());
    let coef = inv * rhs;
    basis
        .iter()
        .map(|v| (coef.transpose() * v).norm_squared())
        .sum()
}

/// Error statistics with evo's definitions (population std, numpy median).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ApeStats {
    pub rmse: f64,
    pub mean: f64,
    pub median: f64,
    pub std: f64,
    pub min: f64,
    pub max: f64,
    pub sse: f64,
}

/// Statistics of a list of per-pose errors. Errors on an empty list.
pub fn error_stats(errors: &[f64]) -> Result<ApeStats, MathError> {
    if errors.is_empty() {
        return Err(MathError::Degenerate("no errors to summarise".into()));
    }
    let n = errors.len() as f64;
    let sse: f64 = errors.iter().map(|e| e * e).sum();
    let mean = errors.iter().sum::<f64>() / n;
    let std = (errors.iter().map(|e| (e - mean) * (e - mean)).sum::<f64>() / n).sqrt();
    let mut sorted = errors.to_vec();
    sorted.sort_by(f64::total_cmp);
    let m = sorted.len();
    let median = if m % 2 == 1 {
        sorted[m / 2]
    } else {
        0.5 * (sorted[m / 2 - 1] + sorted[m / 2])
    };
    Ok(ApeStats {
        rmse: (sse / n).sqrt(),
        mean,
        median,
        std,
        min: sorted[0],
        max: sorted[m - 1],
        sse,
    })
}

/// How the estimate is aligned to the reference before measuring errors.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Alignment {
    /// No alignment.
    None,
    /// Rigid (evo `-a`).
    Se3,
    /// Similarity (evo `-as`), for scale-free SfM estimates.
    Sim3,
}

/// APE translation part: aligns the estimated positions to the reference, then
/// e_i = ‖p'_est,i − p_ref,i‖. Returns the statistics and the alignment used.
pub fn ape_translation(
    est: &[[f64; 3]],
    reference: &[[f64; 3]],
    alignment: Alignment,
) -> Result<(ApeStats, Sim3), MathError> {
    if est.len() != reference.len() {
        return Err(MathError::LengthMismatch {
            est: est.len(),
            reference: reference.len(),
        });
    }
    let sim = match alignment {
        Alignment::None => Sim3::identity(),
        Alignment::Se3 => umeyama(est, reference, false)?,
        Alignment::Sim3 => umeyama(est, reference, true)?,
    };
    let errors: Vec<f64> = est
        .iter()
        .zip(reference)
        .map(|(p, r)| (Vector3::from(sim.act(p)) - Vector3::from(*r)).norm())
        .collect();
    Ok((error_stats(&errors)?, sim))
}

//! Scene normalisation as PRISM3D (nerfstudio `auto_orient_and_center_poses`, method "up",
//! centre "poses", then `auto_scale_poses` and a fixed scale factor), and its exact inverse so
//! trained scenes can be exported in the input coordinate frame.
//!
//! The similarity is x_n = s · R · (x − c):
//! * R rotates the mean camera "up" vector onto +z. Cameras are OpenCV (y down), so a camera's
//!   up vector is the negated second column of its camera-to-world rotation.
//! * c is the mean camera centre.
//! * s = scale_factor / max |component| of the rotated, centred camera centres.
//!
//! Gaussians map back with means x = Rᵀ x_n / s + c, scales / s, rotations Rᵀ·q, and the SH
//! bands rotated (each band l by a (2l+1)² matrix fitted on sampled directions).

use gems_splat::Gaussians;
use nalgebra::{DMatrix, Matrix3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

/// The similarity x_n = scale · rotation · (x − center) from the input to the normalised frame.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Normalization {
    /// Row-major rotation.
    pub rotation: [[f64; 3]; 3],
    pub center: [f64; 3],
    pub scale: f64,
}

impl Default for Normalization {
    fn default() -> Self {
        Self::identity()
    }
}

/// Rotation taking unit vector `a` onto unit vector `b` (Rodrigues; antiparallel handled).
fn rotation_between(a: &Vector3<f64>, b: &Vector3<f64>) -> Matrix3<f64> {
    let v = a.cross(b);
    let c = a.dot(b);
    if c < -1.0 + 1e-9 {
        // 180° about any axis perpendicular to a.
        let axis = if a.x.abs() < 0.9 {
            Vector3::x()
        } else {
            Vector3::y()
        };
        let axis = a.cross(&axis).normalize();
        return UnitQuaternion::from_axis_angle(
            &nalgebra::Unit::new_normalize(axis),
            std::f64::consts::PI,
        )
        .to_rotation_matrix()
        .into_inner();
    }
    let k = Matrix3::new(0.0, -v.z, v.y, v.z, 0.0, -v.x, -v.y, v.x, 0.0);
    Matrix3::identity() + k + k * k / (1.0 + c)
}

impl Normalization {
    pub fn identity() -> Self {
        Self {
            rotation: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            center: [0.0; 3],
            scale: 1.0,
        }
    }

    /// Computes the normalisation from camera-to-world poses (OpenCV cameras).
    pub fn from_cameras(c2w: &[(Matrix3<f64>, Vector3<f64>)], scale_factor: f64) -> Self {
        if c2w.is_empty() {
            return Self::identity();
        }
        let n = c2w.len() as f64;
        let center = c2w.iter().fold(Vector3::zeros(), |acc, (_, t)| acc + t) / n;
        let up = c2w
            .iter()
            .fold(Vector3::zeros(), |acc, (r, _)| acc - r.column(1))
            / n;
        let rot = if up.norm() > 1e-12 {
            rotation_between(&up.normalize(), &Vector3::z())
        } else {
            Matrix3::identity()
        };
        let max_abs = c2w
            .iter()
            .map(|(_, t)| (rot * (t - center)).abs().max())
            .fold(0.0f64, f64::max);
        // A single camera (or coincident ones) has no extent; keep the scale then.
        let scale = if max_abs > 1e-12 {
            scale_factor / max_abs
        } else {
            scale_factor
        };
        let rotation = std::array::from_fn(|i| std::array::from_fn(|j| rot[(i, j)]));
        Self {
            rotation,
            center: center.into(),
            scale,
        }
    }

    pub fn rotation_matrix(&self) -> Matrix3<f64> {
        Matrix3::from_fn(|i, j| self.rotation[i][j])
    }

    /// Input → normalised point.
    pub fn apply_point(&self, p: &Vector3<f64>) -> Vector3<f64> {
        self.scale * (self.rotation_matrix() * (p - Vector3::from(self.center)))
    }

    /// Normalised → input point.
    pub fn invert_point(&self, p: &Vector3<f64>) -> Vector3<f64> {
        self.rotation_matrix().transpose() * p / self.scale + Vector3::from(self.center)
    }

    /// Input → normalised camera-to-world pose.
    pub fn apply_c2w(&self, r: &Matrix3<f64>, t: &Vector3<f64>) -> (Matrix3<f64>, Vector3<f64>) {
        (self.rotation_matrix() * r, self.apply_point(t))
    }

    /// Normalised → input camera-to-world pose.
    pub fn invert_c2w(&self, r: &Matrix3<f64>, t: &Vector3<f64>) -> (Matrix3<f64>, Vector3<f64>) {
        (self.rotation_matrix().transpose() * r, self.invert_point(t))
    }

    /// Gaussians from the normalised frame back to the input frame (means, scales, rotations, SH).
    pub fn gaussians_to_input_frame(&self, g: &Gaussians) -> Gaussians {
        let rt = self.rotation_matrix().transpose();
        let q_rt = UnitQuaternion::from_matrix(&rt);
        let ln_s = self.scale.ln() as f32;
        let bands = sh_band_rotations(&rt);
        let mut out = g.clone();
        for i in 0..g.len() {
            let m = g.means[i];
            let p = self.invert_point(&Vector3::new(m[0] as f64, m[1] as f64, m[2] as f64));
            out.means[i] = [p.x as f32, p.y as f32, p.z as f32];
            out.log_scales[i] = g.log_scales[i].map(|l| l - ln_s);
            let [w, x, y, z] = g.quats[i].map(|c| c as f64);
            let q = q_rt.into_inner() * nalgebra::Quaternion::new(w, x, y, z);
            out.quats[i] = [q.w as f32, q.i as f32, q.j as f32, q.k as f32];
            rotate_sh(&mut out.sh[i], &g.sh[i], &bands);
        }
        out
    }
}

/// The real SH basis of degree 3 at unit direction `d` (gems-splat's: gsplat's constants, order
/// and signs); index 0 is band 0, then bands 1..=3.
fn sh_basis(d: &Vector3<f64>) -> [f64; 16] {
    let mut y = [0.0; 16];
    gems_splat::sh::basis(3, [d.x, d.y, d.z], &mut y, None);
    y
}

/// Band offsets within the 15 non-dc coefficients (basis and SH index 1 + offset).
const BANDS: [(usize, usize); 3] = [(0, 3), (3, 5), (8, 7)];

/// For each band l, the matrix T with c_new = T c_old such that
/// Σ c_new Y(d) = Σ c_old Y(Q d) for the rotation Q that maps new-frame directions to old-frame
/// ones (here Q = R: input direction d_in ↦ normalised d_n = R d_in, and `rt` = Rᵀ).
fn sh_band_rotations(rt: &Matrix3<f64>) -> [DMatrix<f64>; 3] {
    let q = rt.transpose();
    // Deterministic, well-spread sample directions (Fibonacci sphere).
    let k = 64;
    let dirs: Vec<Vector3<f64>> = (0..k)
        .map(|i| {
            let zc = 1.0 - 2.0 * (i as f64 + 0.5) / k as f64;
            let r = (1.0 - zc * zc).sqrt();
            let phi = i as f64 * std::f64::consts::PI * (3.0 - 5f64.sqrt());
            Vector3::new(r * phi.cos(), r * phi.sin(), zc)
        })
        .collect();
    let ya: Vec<[f64; 16]> = dirs.iter().map(sh_basis).collect();
    let yb: Vec<[f64; 16]> = dirs.iter().map(|d| sh_basis(&(q * d))).collect();
    BANDS.map(|(off, len)| {
        let a = DMatrix::from_fn(k, len, |i, j| ya[i][1 + off + j]);
        let b = DMatrix::from_fn(k, len, |i, j| yb[i][1 + off + j]);
        // Y_old(Q d) = M Y(d) row-wise: B = A Mᵀ; then c_new = Mᵀ c_old.
        let mt = a
            .svd(true, true)
            .solve(&b, 1e-12)
            .expect("SVD solve of a full-rank basis");
        mt.transpose()
    })
}

fn rotate_sh(out: &mut [[f32; 3]; 16], sh: &[[f32; 3]; 16], bands: &[DMatrix<f64>; 3]) {
    for (band, &(off, len)) in bands.iter().zip(&BANDS) {
        for ch in 0..3 {
            for r in 0..len {
                let v: f64 = (0..len)
                    .map(|c| band[(c, r)] * sh[1 + off + c][ch] as f64)
                    .sum();
                out[1 + off + r][ch] = v as f32;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn c2w_look(
        eye: Vector3<f64>,
        target: Vector3<f64>,
        up: Vector3<f64>,
    ) -> (Matrix3<f64>, Vector3<f64>) {
        let z = (target - eye).normalize();
        let x = (-z.cross(&up)).normalize();
        let y = z.cross(&x);
        (Matrix3::from_columns(&[x, y, z]), eye)
    }

    fn sample_cameras() -> Vec<(Matrix3<f64>, Vector3<f64>)> {
        // Cameras around a point with world up = +x (so the rotation is non-trivial).
        let up = Vector3::new(1.0, 0.2, 0.0).normalize();
        (0..6)
            .map(|i| {
                let a = i as f64 * 0.4;
                let eye = Vector3::new(3.0 + 0.5 * a.sin(), 4.0 * a.cos(), 4.0 * a.sin())
                    + Vector3::new(10.0, -2.0, 5.0);
                c2w_look(eye, Vector3::new(10.0, -2.0, 5.0), up)
            })
            .collect()
    }

    #[test]
    fn cameras_become_centred_up_aligned_and_scaled() {
        let cams = sample_cameras();
        let n = Normalization::from_cameras(&cams, 0.25);
        let normed: Vec<_> = cams.iter().map(|(r, t)| n.apply_c2w(r, t)).collect();
        let mean = normed.iter().fold(Vector3::zeros(), |a, (_, t)| a + t) / normed.len() as f64;
        assert!(mean.norm() < 1e-9);
        let max_abs = normed
            .iter()
            .map(|(_, t)| t.abs().max())
            .fold(0.0, f64::max);
        assert!((max_abs - 0.25).abs() < 1e-9);
        let up = normed
            .iter()
            .fold(Vector3::zeros(), |a, (r, _)| a - r.column(1))
            .normalize();
        assert!((up - Vector3::z()).norm() < 1e-9, "{up}");
        // Rotations stay rotations.
        for (r, _) in &normed {
            assert!((r.transpose() * r - Matrix3::identity()).norm() < 1e-9);
        }
    }

    #[test]
    fn points_and_poses_round_trip() {
        let n = Normalization::from_cameras(&sample_cameras(), 0.25);
        let p = Vector3::new(1.0, -7.0, 2.5);
        assert!((n.invert_point(&n.apply_point(&p)) - p).norm() < 1e-9);
        let (r, t) = sample_cameras()[2];
        let (r2, t2) = n.apply_c2w(&r, &t);
        let (r3, t3) = n.invert_c2w(&r2, &t2);
        assert!((r3 - r).norm() < 1e-9 && (t3 - t).norm() < 1e-9);
    }

    #[test]
    fn antiparallel_up_is_handled() {
        let r = rotation_between(&Vector3::new(0.0, 0.0, -1.0), &Vector3::z());
        assert!((r * Vector3::new(0.0, 0.0, -1.0) - Vector3::z()).norm() < 1e-9);
        assert!((r.determinant() - 1.0).abs() < 1e-9);
    }

    /// Colour of SH coefficients (bands 1..3 only) in direction d.
    fn sh_eval(sh: &[[f32; 3]; 16], d: &Vector3<f64>, ch: usize) -> f64 {
        let y = sh_basis(d);
        (1..16).map(|k| y[k] * sh[k][ch] as f64).sum()
    }

    #[test]
    fn exported_gaussians_look_the_same_from_the_same_physical_direction() {
        let n = Normalization::from_cameras(&sample_cameras(), 0.25);
        let mut g = Gaussians::with_degree(3);
        let mut sh = [[0.0f32; 3]; 16];
        for (k, c) in sh.iter_mut().enumerate() {
            *c = [
                0.1 * k as f32 - 0.7,
                (k as f32 * 0.37).sin(),
                0.05 * k as f32,
            ];
        }
        g.push(
            [0.1, -0.2, 0.05],
            [0.9, 0.1, -0.3, 0.2],
            [-3.0, -2.5, -4.0],
            0.3,
            sh,
        );
        let out = n.gaussians_to_input_frame(&g);
        // Mean maps like a point.
        let m = n.invert_point(&Vector3::new(0.1, -0.2, 0.05));
        assert!((out.means[0][0] as f64 - m.x).abs() < 1e-5);
        // Scales divide by s.
        assert!((out.log_scales[0][0] as f64 - (-3.0 - n.scale.ln())).abs() < 1e-5);
        // View-dependent colour: the input-frame direction d_in sees what d_n = R d_in saw.
        let r = n.rotation_matrix();
        for d in [Vector3::new(0.3, -0.5, 0.8), Vector3::new(-1.0, 0.1, 0.2)] {
            let d_in = d.normalize();
            let d_n = r * d_in;
            for ch in 0..3 {
                let a = sh_eval(&out.sh[0], &d_in, ch);
                let b = sh_eval(&g.sh[0], &d_n, ch);
                assert!((a - b).abs() < 1e-4, "{a} vs {b}");
            }
        }
        // Covariance rotates: R_in = Rᵀ R_n.
        let qn = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(0.9, 0.1, -0.3, 0.2));
        let [w, x, y, z] = out.quats[0].map(|c| c as f64);
        let qi = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(w, x, y, z));
        let diff = qi.to_rotation_matrix().into_inner()
            - r.transpose() * qn.to_rotation_matrix().into_inner();
        assert!(diff.norm() < 1e-5);
    }
}

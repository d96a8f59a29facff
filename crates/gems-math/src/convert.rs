//! Conversions between rotation representations, camera conventions and the renderer's f32 arrays.

use nalgebra::{Matrix3, Vector3};

use crate::se3::Se3;
use crate::so3::{SMALL_ANGLE, So3};

/// Unit quaternion (w, x, y, z) of a rotation matrix, with w ≥ 0. Shepperd's method: picks the
/// largest of the four diagonal combinations so no division by a small number occurs.
pub fn rotation_to_quat_wxyz(r: &Matrix3<f64>) -> [f64; 4] {
    let tr = r.trace();
    let (w, x, y, z);
    if tr >= r[(0, 0)] && tr >= r[(1, 1)] && tr >= r[(2, 2)] {
        let s = 2.0 * (1.0 + tr).max(0.0).sqrt();
        w = 0.25 * s;
        x = (r[(2, 1)] - r[(1, 2)]) / s;
        y = (r[(0, 2)] - r[(2, 0)]) / s;
        z = (r[(1, 0)] - r[(0, 1)]) / s;
    } else if r[(0, 0)] >= r[(1, 1)] && r[(0, 0)] >= r[(2, 2)] {
        let s = 2.0 * (1.0 + r[(0, 0)] - r[(1, 1)] - r[(2, 2)]).max(0.0).sqrt();
        w = (r[(2, 1)] - r[(1, 2)]) / s;
        x = 0.25 * s;
        y = (r[(0, 1)] + r[(1, 0)]) / s;
        z = (r[(0, 2)] + r[(2, 0)]) / s;
    } else if r[(1, 1)] >= r[(2, 2)] {
        let s = 2.0 * (1.0 + r[(1, 1)] - r[(0, 0)] - r[(2, 2)]).max(0.0).sqrt();
        w = (r[(0, 2)] - r[(2, 0)]) / s;
        x = (r[(0, 1)] + r[(1, 0)]) / s;
        y = 0.25 * s;
        z = (r[(1, 2)] + r[(2, 1)]) / s;
    } else {
        let s = 2.0 * (1.0 + r[(2, 2)] - r[(0, 0)] - r[(1, 1)]).max(0.0).sqrt();
        w = (r[(1, 0)] - r[(0, 1)]) / s;
        x = (r[(0, 2)] + r[(2, 0)]) / s;
        y = (r[(1, 2)] + r[(2, 1)]) / s;
        z = 0.25 * s;
    }
    let n = (w * w + x * x + y * y + z * z).sqrt();
    let sign = if w < 0.0 { -1.0 } else { 1.0 };
    [sign * w / n, sign * x / n, sign * y / n, sign * z / n]
}

/// Rotation matrix of a quaternion (w, x, y, z); the quaternion is normalised first.
pub fn quat_wxyz_to_rotation(q: [f64; 4]) -> Matrix3<f64> {
    let n = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]).sqrt();
    let (w, x, y, z) = (q[0] / n, q[1] / n, q[2] / n, q[3] / n);
    Matrix3::new(
        1.0 - 2.0 * (y * y + z * z),
        2.0 * (x * y - w * z),
        2.0 * (x * z + w * y),
        2.0 * (x * y + w * z),
        1.0 - 2.0 * (x * x + z * z),
        2.0 * (y * z - w * x),
        2.0 * (x * z - w * y),
        2.0 * (y * z + w * x),
        1.0 - 2.0 * (x * x + y * y),
    )
}

/// Axis-angle vector of a unit quaternion: θ = 2·atan2(|v|, w) along v/|v| (atan2 keeps full
/// precision at both θ ≈ 0 and θ ≈ π).
pub(crate) fn quat_wxyz_log(q: [f64; 4]) -> Vector3<f64> {
    let (w, v) = if q[0] < 0.0 {
        (-q[0], Vector3::new(-q[1], -q[2], -q[3]))
    } else {
        (q[0], Vector3::new(q[1], q[2], q[3]))
    };
    let n = v.norm();
    // 2·atan2(n, w)/n → 2/w·(1 − n²/(3w²)) as n → 0 (w ≈ 1 there).
    let f = if n < SMALL_ANGLE * 0.5 {
        2.0 / w * (1.0 - n * n / (3.0 * w * w))
    } else {
        2.0 * n.atan2(w) / n
    };
    v * f
}

/// Rotation from a unit axis and an angle in radians (the axis is normalised).
pub fn axis_angle_to_rotation(axis: &Vector3<f64>, angle: f64) -> So3 {
    So3::exp(&(axis.normalize() * angle))
}

/// Unit axis and angle ∈ [0, π] of a rotation; the axis is +x for the identity.
pub fn rotation_to_axis_angle(r: &So3) -> (Vector3<f64>, f64) {
    let phi = r.log();
    let angle = phi.norm();
    if angle == 0.0 {
        (Vector3::x(), 0.0)
    } else {
        (phi / angle, angle)
    }
}

/// Camera-to-world pose of an OpenCV camera (x right, y down, z forward) at `eye` looking at
/// `target`, with `up` the world direction that should appear upwards in the image (−y). Returns
/// `None` when the view direction is (anti)parallel to `up` or `eye == target`.
pub fn look_at_c2w(eye: &Vector3<f64>, target: &Vector3<f64>, up: &Vector3<f64>) -> Option<Se3> {
    let z = (target - eye).try_normalize(1e-12)?;
    let x = z.cross(up).try_normalize(1e-12)?;
    let y = z.cross(&x);
    Some(Se3::new(Matrix3::from_columns(&[x, y, z]), *eye))
}

/// World-to-camera from camera-to-world (and vice versa: both are the rigid inverse).
pub fn c2w_to_w2c(c2w: &Se3) -> Se3 {
    c2w.inverse()
}

/// Camera-to-world from world-to-camera.
pub fn w2c_to_c2w(w2c: &Se3) -> Se3 {
    w2c.inverse()
}

/// Camera centre in world coordinates of a world-to-camera pose: −Rᵀ t.
pub fn camera_center_from_w2c(w2c: &Se3) -> Vector3<f64> {
    -(w2c.rot.transpose() * w2c.trans)
}

impl Se3 {
    /// Row-major f32 rotation and f32 translation, as the renderer's `Camera` stores a
    /// world-to-camera pose.
    pub fn to_f32_arrays(&self) -> ([[f32; 3]; 3], [f32; 3]) {
        let mut r = [[0f32; 3]; 3];
        for (i, row) in r.iter_mut().enumerate() {
            for (j, v) in row.iter_mut().enumerate() {
                *v = self.rot[(i, j)] as f32;
            }
        }
        (
            r,
            [
                self.trans.x as f32,
                self.trans.y as f32,
                self.trans.z as f32,
            ],
        )
    }

    /// Inverse of [`Se3::to_f32_arrays`]. The rotation is re-orthonormalised because f32 rounding
    /// leaves it ~1e-7 off SO(3), which would bias Log and the Jacobians.
    pub fn from_f32_arrays(rot: &[[f32; 3]; 3], trans: &[f32; 3]) -> Se3 {
        let m = Matrix3::from_fn(|i, j| rot[i][j] as f64);
        Se3::new(
            So3::from_matrix_orthonormalized(&m).0,
            Vector3::new(trans[0] as f64, trans[1] as f64, trans[2] as f64),
        )
    }

    /// Row-major f64 arrays (plain types for serialisation and other crates).
    pub fn to_arrays(&self) -> ([[f64; 3]; 3], [f64; 3]) {
        let mut r = [[0f64; 3]; 3];
        for (i, row) in r.iter_mut().enumerate() {
            for (j, v) in row.iter_mut().enumerate() {
                *v = self.rot[(i, j)];
            }
        }
        (r, [self.trans.x, self.trans.y, self.trans.z])
    }

    /// From row-major f64 arrays; the rotation is taken as given.
    pub fn from_arrays(rot: &[[f64; 3]; 3], trans: &[f64; 3]) -> Se3 {
        Se3::new(Matrix3::from_fn(|i, j| rot[i][j]), Vector3::from(*trans))
    }

    /// 4×4 homogeneous matrix, row-major.
    pub fn to_matrix4(&self) -> [[f64; 4]; 4] {
        let mut m = [[0.0; 4]; 4];
        for (i, row) in m.iter_mut().take(3).enumerate() {
            for (j, v) in row.iter_mut().take(3).enumerate() {
                *v = self.rot[(i, j)];
            }
            row[3] = self.trans[i];
        }
        m[3][3] = 1.0;
        m
    }

    /// Translation and unit quaternion (w, x, y, z).
    pub fn to_translation_quat_wxyz(&self) -> ([f64; 3], [f64; 4]) {
        (
            [self.trans.x, self.trans.y, self.trans.z],
            rotation_to_quat_wxyz(&self.rot),
        )
    }

    pub fn from_translation_quat_wxyz(t: [f64; 3], q: [f64; 4]) -> Se3 {
        Se3::new(quat_wxyz_to_rotation(q), Vector3::from(t))
    }
}

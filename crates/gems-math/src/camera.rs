//! The camera vocabulary shared by every gems crate: one [`Pose`] (a rigid transform in plain
//! arrays, what files store) and one [`Intrinsics`] (pinhole, f64), beside [`Se3`] for the maths.
//!
//! Convention: a scene's [`Pose`] is **world-to-camera** (`x_cam = R · x_world + t`) with an
//! OpenCV camera frame (x right, y down, z forward), in f64. Readers of other conventions (LLFF,
//! nerfstudio/OpenGL) convert on load; writers convert back. A field named `c2w_*` holds the
//! inverse transform in the same type (the trained trajectories are camera-to-world).

use serde::{Deserialize, Serialize};

use crate::Se3;

/// A rigid world-to-camera transform: `x_cam = rotation · x_world + translation`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Pose {
    /// Row-major rotation matrix (world → camera).
    pub rotation: [[f64; 3]; 3],
    /// Translation (world → camera).
    pub translation: [f64; 3],
}

impl Pose {
    /// The identity pose (camera at the origin looking down +z).
    pub const IDENTITY: Pose = Pose {
        rotation: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        translation: [0.0, 0.0, 0.0],
    };

    /// Pose from a Hamilton unit quaternion `[w, x, y, z]` (normalised here) and a translation,
    /// both world-to-camera as COLMAP stores them.
    pub fn from_quaternion(q: [f64; 4], translation: [f64; 3]) -> Pose {
        let m = crate::convert::quat_wxyz_to_rotation(q);
        let rotation = std::array::from_fn(|i| std::array::from_fn(|j| m[(i, j)]));
        Pose {
            rotation,
            translation,
        }
    }

    /// The rotation as a unit quaternion `[w, x, y, z]` with `w >= 0`.
    pub fn quaternion(&self) -> [f64; 4] {
        let r = &self.rotation;
        let trace = r[0][0] + r[1][1] + r[2][2];
        // Shepperd's method: branch on the largest diagonal term for numerical stability.
        let q = if trace > 0.0 {
            let s = (trace + 1.0).sqrt() * 2.0;
            [
                0.25 * s,
                (r[2][1] - r[1][2]) / s,
                (r[0][2] - r[2][0]) / s,
                (r[1][0] - r[0][1]) / s,
            ]
        } else if r[0][0] > r[1][1] && r[0][0] > r[2][2] {
            let s = (1.0 + r[0][0] - r[1][1] - r[2][2]).sqrt() * 2.0;
            [
                (r[2][1] - r[1][2]) / s,
                0.25 * s,
                (r[0][1] + r[1][0]) / s,
                (r[0][2] + r[2][0]) / s,
            ]
        } else if r[1][1] > r[2][2] {
            let s = (1.0 + r[1][1] - r[0][0] - r[2][2]).sqrt() * 2.0;
            [
                (r[0][2] - r[2][0]) / s,
                (r[0][1] + r[1][0]) / s,
                0.25 * s,
                (r[1][2] + r[2][1]) / s,
            ]
        } else {
            let s = (1.0 + r[2][2] - r[0][0] - r[1][1]).sqrt() * 2.0;
            [
                (r[1][0] - r[0][1]) / s,
                (r[0][2] + r[2][0]) / s,
                (r[1][2] + r[2][1]) / s,
                0.25 * s,
            ]
        };
        let n = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]).sqrt();
        let sign = if q[0] < 0.0 { -1.0 } else { 1.0 };
        [
            sign * q[0] / n,
            sign * q[1] / n,
            sign * q[2] / n,
            sign * q[3] / n,
        ]
    }

    /// Pose from a camera-to-world rotation (OpenCV axes as columns) and the camera centre.
    pub fn from_camera_to_world(rotation_c2w: [[f64; 3]; 3], center: [f64; 3]) -> Pose {
        let rotation = transpose(rotation_c2w);
        let t = mat_vec(&rotation, center);
        Pose {
            rotation,
            translation: [-t[0], -t[1], -t[2]],
        }
    }

    /// Camera-to-world rotation (columns = camera x/y/z axes in world coordinates).
    pub fn rotation_c2w(&self) -> [[f64; 3]; 3] {
        transpose(self.rotation)
    }

    /// Camera centre in world coordinates, `−Rᵀ t`.
    pub fn center(&self) -> [f64; 3] {
        let c = mat_vec(&transpose(self.rotation), self.translation);
        [-c[0], -c[1], -c[2]]
    }

    /// The inverse transform (camera-to-world expressed as a `Pose`-shaped struct).
    pub fn inverse(&self) -> Pose {
        Pose {
            rotation: transpose(self.rotation),
            translation: self.center(),
        }
    }

    /// Maps a world point into the camera frame.
    pub fn transform_point(&self, p: [f64; 3]) -> [f64; 3] {
        let r = mat_vec(&self.rotation, p);
        [
            r[0] + self.translation[0],
            r[1] + self.translation[1],
            r[2] + self.translation[2],
        ]
    }

    /// 4×4 row-major world-to-camera matrix.
    pub fn to_matrix4(&self) -> [[f64; 4]; 4] {
        let r = &self.rotation;
        let t = &self.translation;
        [
            [r[0][0], r[0][1], r[0][2], t[0]],
            [r[1][0], r[1][1], r[1][2], t[1]],
            [r[2][0], r[2][1], r[2][2], t[2]],
            [0.0, 0.0, 0.0, 1.0],
        ]
    }

    /// True when every entry is finite.
    pub fn is_finite(&self) -> bool {
        self.rotation.iter().flatten().all(|v| v.is_finite())
            && self.translation.iter().all(|v| v.is_finite())
    }

    /// Largest deviation of `RᵀR` from the identity, plus `|det R − 1|`: 0 for a true rotation.
    pub fn rotation_error(&self) -> f64 {
        rotation_error(&self.rotation)
    }
}

/// Largest entry of `|RᵀR − I|` plus `|det R − 1|`.
pub fn rotation_error(r: &[[f64; 3]; 3]) -> f64 {
    let mut err: f64 = 0.0;
    for i in 0..3 {
        for j in 0..3 {
            let dot: f64 = (0..3).map(|k| r[k][i] * r[k][j]).sum();
            let target = if i == j { 1.0 } else { 0.0 };
            err = err.max((dot - target).abs());
        }
    }
    let det = r[0][0] * (r[1][1] * r[2][2] - r[1][2] * r[2][1])
        - r[0][1] * (r[1][0] * r[2][2] - r[1][2] * r[2][0])
        + r[0][2] * (r[1][0] * r[2][1] - r[1][1] * r[2][0]);
    if det.is_nan() {
        return f64::NAN;
    }
    err + (det - 1.0).abs()
}

pub(crate) fn transpose(m: [[f64; 3]; 3]) -> [[f64; 3]; 3] {
    [
        [m[0][0], m[1][0], m[2][0]],
        [m[0][1], m[1][1], m[2][1]],
        [m[0][2], m[1][2], m[2][2]],
    ]
}

pub(crate) fn mat_vec(m: &[[f64; 3]; 3], v: [f64; 3]) -> [f64; 3] {
    [
        m[0][0] * v[0] + m[0][1] * v[1] + m[0][2] * v[2],
        m[1][0] * v[0] + m[1][1] * v[1] + m[1][2] * v[2],
        m[2][0] * v[0] + m[2][1] * v[1] + m[2][2] * v[2],
    ]
}

/// Pinhole intrinsics in pixels for an image of `width × height`, pixel centres at `+0.5`
/// (COLMAP/OpenCV convention: the top-left corner of the image is (0, 0)).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Intrinsics {
    /// Focal length along x, pixels.
    pub fx: f64,
    /// Focal length along y, pixels.
    pub fy: f64,
    /// Principal point x, pixels.
    pub cx: f64,
    /// Principal point y, pixels.
    pub cy: f64,
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
}

impl Intrinsics {
    /// Square pixels, centred principal point, horizontal field of view `fov_x_deg`.
    pub fn from_fov(width: u32, height: u32, fov_x_deg: f64) -> Self {
        let f = 0.5 * f64::from(width) / (0.5 * fov_x_deg.to_radians()).tan();
        Self {
            width,
            height,
            fx: f,
            fy: f,
            cx: 0.5 * f64::from(width),
            cy: 0.5 * f64::from(height),
        }
    }

    /// The same camera for an image resized to `width × height` (e.g. a downscaled copy): focal
    /// lengths and principal point scale with the per-axis size ratio.
    pub fn resized(&self, width: u32, height: u32) -> Intrinsics {
        let sx = f64::from(width) / f64::from(self.width);
        let sy = f64::from(height) / f64::from(self.height);
        Intrinsics {
            fx: self.fx * sx,
            fy: self.fy * sy,
            cx: self.cx * sx,
            cy: self.cy * sy,
            width,
            height,
        }
    }

    /// The same camera with both focal lengths multiplied by `factor` (a zoom about the
    /// principal point).
    pub fn with_focal_scaled(&self, factor: f64) -> Intrinsics {
        Intrinsics {
            fx: self.fx * factor,
            fy: self.fy * factor,
            ..*self
        }
    }

    /// Row-major 3×3 calibration matrix K.
    pub fn matrix(&self) -> [[f64; 3]; 3] {
        [
            [self.fx, 0.0, self.cx],
            [0.0, self.fy, self.cy],
            [0.0, 0.0, 1.0],
        ]
    }
}

impl From<&Pose> for Se3 {
    /// The same transform as an [`Se3`] (`p ↦ R p + t`).
    fn from(p: &Pose) -> Self {
        Se3::from_arrays(&p.rotation, &p.translation)
    }
}

impl From<Pose> for Se3 {
    fn from(p: Pose) -> Self {
        Se3::from(&p)
    }
}

impl From<&Se3> for Pose {
    /// An [`Se3`] as a plain [`Pose`].
    fn from(s: &Se3) -> Self {
        let (rotation, translation) = s.to_arrays();
        Pose {
            rotation,
            translation,
        }
    }
}

impl From<Se3> for Pose {
    fn from(s: Se3) -> Self {
        Pose::from(&s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #[test]
        fn quaternion_round_trip(w in -1.0f64..1.0, x in -1.0f64..1.0, y in -1.0f64..1.0, z in -1.0f64..1.0) {
            let n = (w * w + x * x + y * y + z * z).sqrt();
            prop_assume!(n > 0.1);
            let p = Pose::from_quaternion([w, x, y, z], [1.0, 2.0, 3.0]);
            prop_assert!(p.rotation_error() < 1e-12);
            let q = p.quaternion();
            let s = if w < 0.0 { -1.0 } else { 1.0 };
            for (a, b) in q.iter().zip([w, x, y, z]) {
                prop_assert!((a - s * b / n).abs() < 1e-9, "{q:?} vs {:?}", [w, x, y, z]);
            }
        }

        #[test]
        fn center_inverts_transform(w in -1.0f64..1.0, x in -1.0f64..1.0, y in -1.0f64..1.0, z in -1.0f64..1.0,
                                    tx in -5.0f64..5.0, ty in -5.0f64..5.0, tz in -5.0f64..5.0) {
            prop_assume!((w * w + x * x + y * y + z * z).sqrt() > 0.1);
            let p = Pose::from_quaternion([w, x, y, z], [tx, ty, tz]);
            let c = p.transform_point(p.center());
            prop_assert!(c.iter().all(|v| v.abs() < 1e-9));
            let q = Pose::from_camera_to_world(p.rotation_c2w(), p.center());
            for (a, b) in q.translation.iter().zip(p.translation) {
                prop_assert!((a - b).abs() < 1e-9);
            }
        }
    }

    #[test]
    fn rotation_error_flags_non_rotations() {
        assert!(Pose::IDENTITY.rotation_error() == 0.0);
        let mut p = Pose::IDENTITY;
        p.rotation[2][2] = -1.0; // a reflection: orthonormal but det −1
        assert!(p.rotation_error() > 1.0);
        p.rotation[0][0] = f64::NAN;
        assert!(p.rotation_error().is_nan());
    }

    #[test]
    fn resized_intrinsics_scale_per_axis() {
        let k = Intrinsics {
            fx: 100.0,
            fy: 110.0,
            cx: 50.0,
            cy: 40.0,
            width: 100,
            height: 80,
        };
        let r = k.resized(50, 20);
        assert_eq!((r.fx, r.fy, r.cx, r.cy), (50.0, 27.5, 25.0, 10.0));
    }
}

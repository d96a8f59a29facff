//! Pinhole cameras, the view path, and the random camera motion inside each exposure.
//!
//! Camera convention: OpenCV (x right, y down, z forward); a [`CameraPose`] stores the
//! camera-to-world rotation and the camera centre. Pixel (i, j) covers [i, i+1)×[j, j+1), so its
//! centre is at (i + 0.5, j + 0.5) and the principal point of a centred camera is (W/2, H/2), as in
//! COLMAP.

use crate::geom::{
    M3, V3, add3, cross3, mat_mul, mat_t_vec, mat_vec, norm3, scale3, so3_exp, sub3,
};
use gems_math::{Intrinsics, Pose};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use serde::Serialize;

/// A camera pose: camera-to-world rotation (columns = camera x, y, z axes in world) and centre.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct CameraPose {
    pub rotation: M3,
    pub centre: [f64; 3],
}

impl CameraPose {
    /// Camera at `centre` looking at `target`, with image "up" as close to world `up` as possible.
    pub fn look_at(centre: [f64; 3], target: [f64; 3], up: [f64; 3]) -> Self {
        let f = sub3(target, centre);
        let f = scale3(f, 1.0 / norm3(f));
        let r = cross3(f, up);
        let r = scale3(r, 1.0 / norm3(r));
        let d = cross3(f, r);
        let rotation = [[r[0], d[0], f[0]], [r[1], d[1], f[1]], [r[2], d[2], f[2]]];
        Self { rotation, centre }
    }

    /// The same pose in gems-data's world-to-camera convention.
    pub fn to_pose(&self) -> Pose {
        Pose::from_camera_to_world(self.rotation, self.centre)
    }

    /// World point → camera frame.
    pub fn to_camera(&self, p: [f64; 3]) -> [f64; 3] {
        mat_t_vec(&self.rotation, sub3(p, self.centre))
    }

    /// Projects a world point to pixel coordinates; `None` when it is not in front of the camera.
    pub fn project(&self, k: &Intrinsics, p: [f64; 3]) -> Option<[f64; 2]> {
        let c = self.to_camera(p);
        (c[2] > 1e-6).then(|| [k.fx * c[0] / c[2] + k.cx, k.fy * c[1] / c[2] + k.cy])
    }

    /// The ray through pixel coordinates (u, v): origin and unit direction, in f32 for the caster.
    pub fn ray(&self, k: &Intrinsics, u: f64, v: f64) -> (V3, V3) {
        let d = mat_vec(&self.rotation, [(u - k.cx) / k.fx, (v - k.cy) / k.fy, 1.0]);
        let o = self.centre;
        (
            V3::new(o[0] as f32, o[1] as f32, o[2] as f32),
            V3::new(d[0] as f32, d[1] as f32, d[2] as f32).normalized(),
        )
    }

    /// This pose moved by `delta` = (rotation vector ω, translation t), both expressed in this
    /// camera's own frame: R' = R·Exp(ω), C' = C + R·t (right composition, as GeMS/BAD apply
    /// their trajectory deltas).
    pub fn compose_local(&self, delta: &[f64; 6]) -> Self {
        let w = [delta[0], delta[1], delta[2]];
        let t = [delta[3], delta[4], delta[5]];
        Self {
            rotation: mat_mul(&self.rotation, &so3_exp(w)),
            centre: add3(self.centre, mat_vec(&self.rotation, t)),
        }
    }
}

/// `n` views on a horizontal arc of `arc_deg` degrees around `target`, all facing it, with a gentle
/// height wave so the camera centres are not exactly coplanar with the target (as for handheld
/// LLFF captures).
pub fn arc_path(n: usize, target: V3, radius: f64, height: f64, arc_deg: f64) -> Vec<CameraPose> {
    let t = [
        f64::from(target.x),
        f64::from(target.y),
        f64::from(target.z),
    ];
    (0..n)
        .map(|i| {
            let s = if n > 1 {
                i as f64 / (n - 1) as f64 - 0.5
            } else {
                0.0
            };
            let a = (s * arc_deg).to_radians();
            let wave = 0.15 * (s * std::f64::consts::TAU * 1.5).sin();
            let c = [
                t[0] + radius * a.sin(),
                t[1] + height + wave,
                t[2] + radius * a.cos(),
            ];
            CameraPose::look_at(c, t, [0.0, 1.0, 0.0])
        })
        .collect()
}

/// A smooth random camera motion over one exposure: a cubic Bézier curve in the 6-D local tangent
/// space (ω, t), re-centred so that u = 0.5 is the identity (the mid-exposure pose is the ground
/// truth pose), multiplied by a calibrated `scale`.
#[derive(Clone, Debug, PartialEq)]
pub struct ExposureMotion {
    controls: [[f64; 6]; 4],
    /// Multiplier on the unit-size curve, set by calibration to the requested blur.
    pub scale: f64,
}

impl ExposureMotion {
    /// A random sweep: the curve runs from about −d to +d along a random direction d with random
    /// curvature. Rotation is mostly pan/tilt (roll ×0.3, as in handheld shake); translation is
    /// in units of `depth` (the median scene depth), so both move the image by comparable amounts.
    pub fn random(rng: &mut ChaCha8Rng, depth: f64) -> Self {
        let mut g = || -> f64 { StandardNormal.sample(&mut *rng) };
        let weights = [1.0, 1.0, 0.3, 0.5 * depth, 0.5 * depth, 0.25 * depth];
        let d: [f64; 6] = std::array::from_fn(|i| g() * weights[i]);
        let bend: [f64; 6] = std::array::from_fn(|i| g() * weights[i] * 0.5);
        let mut controls = [[0.0; 6]; 4];
        for (j, c) in controls.iter_mut().enumerate() {
            let s = [-1.0, -1.0 / 3.0, 1.0 / 3.0, 1.0][j];
            // The inner control points pull the sweep sideways: a curved, not straight, path.
            let b = if j == 1 || j == 2 { 1.0 } else { 0.0 };
            for i in 0..6 {
                c[i] = s * d[i] + b * bend[i] + 0.15 * g() * weights[i];
            }
        }
        Self {
            controls,
            scale: 1.0,
        }
    }

    fn bezier(&self, u: f64) -> [f64; 6] {
        let v = 1.0 - u;
        let b = [v * v * v, 3.0 * v * v * u, 3.0 * v * u * u, u * u * u];
        std::array::from_fn(|i| (0..4).map(|j| b[j] * self.controls[j][i]).sum())
    }

    /// Local delta (ω, t) at exposure fraction `u` ∈ [0, 1]; zero at u = 0.5.
    pub fn delta(&self, u: f64) -> [f64; 6] {
        let (a, m) = (self.bezier(u), self.bezier(0.5));
        std::array::from_fn(|i| (a[i] - m[i]) * self.scale)
    }

    /// Pose at exposure fraction `u` for the mid-exposure pose `mid`.
    pub fn pose_at(&self, mid: &CameraPose, u: f64) -> CameraPose {
        mid.compose_local(&self.delta(u))
    }
}

/// Mean image-space path length (pixels) of `points` over the pose sequence `poses`: for each
/// point, the length of the polyline through its projections; points behind any camera are
/// skipped. This is the blur extent the generator calibrates to.
pub fn mean_path_length_px(points: &[[f64; 3]], k: &Intrinsics, poses: &[CameraPose]) -> f64 {
    let (mut sum, mut count) = (0.0, 0usize);
    'points: for &p in points {
        let mut len = 0.0;
        let mut prev: Option<[f64; 2]> = None;
        for pose in poses {
            let Some(q) = pose.project(k, p) else {
                continue 'points;
            };
            if let Some(pr) = prev {
                len += ((q[0] - pr[0]).powi(2) + (q[1] - pr[1]).powi(2)).sqrt();
            }
            prev = Some(q);
        }
        sum += len;
        count += 1;
    }
    if count == 0 { 0.0 } else { sum / count as f64 }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn look_at_projects_target_to_principal_point() {
        let k = Intrinsics::from_fov(200, 100, 60.0);
        let pose = CameraPose::look_at([1.0, 2.0, 5.0], [0.0, 0.5, -1.0], [0.0, 1.0, 0.0]);
        let q = pose.project(&k, [0.0, 0.5, -1.0]).unwrap();
        assert!((q[0] - 100.0).abs() < 1e-9 && (q[1] - 50.0).abs() < 1e-9);
        // A point above the target appears higher in the image (smaller v): y is down.
        assert!(pose.project(&k, [0.0, 1.5, -1.0]).unwrap()[1] < 50.0);
        // The image edge is at half the field of view.
        let (_, d) = pose.ray(&k, 0.0, 50.0);
        let fwd = pose.ray(&k, 100.0, 50.0).1;
        assert!((f64::from(d.dot(fwd)).acos().to_degrees() - 30.0).abs() < 1e-3);
    }

    #[test]
    fn motion_is_identity_at_mid_exposure_and_scales_linearly() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let mut m = ExposureMotion::random(&mut rng, 4.0);
        assert!(m.delta(0.5).iter().all(|v| v.abs() < 1e-15));
        let d1 = m.delta(0.0);
        m.scale = 2.0;
        let d2 = m.delta(0.0);
        for i in 0..6 {
            assert!((d2[i] - 2.0 * d1[i]).abs() < 1e-12);
        }
        assert!(d1.iter().any(|v| v.abs() > 1e-3));
    }

    #[test]
    fn path_length_of_pure_pan_matches_focal_times_angle() {
        let k = Intrinsics::from_fov(400, 300, 60.0);
        let mid = CameraPose::look_at([0.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]);
        // Pan about the camera's y axis by ±0.01 rad: a point on the axis moves fx·0.02 px.
        let poses: Vec<_> = (0..=50)
            .map(|i| mid.compose_local(&[0.0, -0.01 + 0.0004 * f64::from(i), 0.0, 0.0, 0.0, 0.0]))
            .collect();
        let len = mean_path_length_px(&[[0.0, 0.0, -5.0]], &k, &poses);
        assert!(
            (len - k.fx * 0.02).abs() < 1e-3 * len,
            "{len} vs {}",
            k.fx * 0.02
        );
    }
}

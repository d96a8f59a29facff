//! Surface depth: where a pixel's ray meets the surface the Gaussians draw.
//!
//! Expected depth (`RenderSettings::compute_depth`), the composited mean of the Gaussians'
//! centre depths, lies in front of a slanted surface: the Gaussians whose centres are nearer
//! the camera come first and take most of the weight. Surface depth instead takes the Gaussian
//! at which the pixel's transmittance first falls to one half (the median depth of 2DGS, Huang
//! et al. 2024, section 4.2) and the point of its ray where that Gaussian's density peaks,
//! `t* = dᵀΣ⁻¹μ / dᵀΣ⁻¹d` for the ray `t·d` from the camera centre (Gaussian Opacity Fields,
//! Yu et al. 2024, section 3.1): on a flat Gaussian lying in a surface this is where the ray
//! crosses the surface, not the Gaussian's centre depth. Forward only, for geometry (dense
//! points), never for training.

use crate::Gaussians;
use crate::project::{Cam, Mat3, mul3, quat_to_rot};

/// Transmittance at which a pixel's ray is taken to have reached the surface.
pub const SURFACE_TRANSMITTANCE: f64 = 0.5;

/// How far from its centre depth a Gaussian's ray depth may lie, in the larger of its largest
/// scale and a pixel's width at its depth. A ray grazing a Gaussian seen nearly edge-on peaks
/// far from it, which says nothing about the surface; but the renderer widens every footprint
/// to about a pixel (`eps2d`), so a Gaussian smaller than a pixel is drawn where its own
/// ellipsoid does not reach, and there its plane, not its extent, tells where the surface is.
const REACH: f64 = 3.0;

/// One Gaussian in one camera's frame, ready to meet that camera's rays.
#[derive(Clone, Copy, Debug)]
pub(crate) struct RayDepth {
    /// `Σ⁻¹` in the camera frame.
    inv_cov: Mat3,
    /// `Σ⁻¹ μ` in the camera frame.
    inv_cov_mean: [f64; 3],
    /// Camera depth of the centre.
    mean_z: f64,
    /// [`REACH`] times the larger of the largest scale and a pixel's width at the centre.
    reach: f64,
}

impl RayDepth {
    /// Gaussian `i` seen from `cam`, or `None` when its parameters are not finite or a scale is
    /// zero (the renderer culls such Gaussians).
    pub(crate) fn new(g: &Gaussians, i: usize, cam: &Cam) -> Option<RayDepth> {
        let q = g.quats[i].map(f64::from);
        let qn = q.iter().map(|v| v * v).sum::<f64>().sqrt();
        let scales = g.log_scales[i].map(|v| f64::from(v).exp());
        let m = g.means[i].map(f64::from);
        if !(qn > 1e-12
            && scales.iter().all(|s| s.is_finite() && *s > 0.0)
            && m.iter().all(|v| v.is_finite()))
        {
            return None;
        }
        // Σ⁻¹ = R S⁻² Rᵀ in the world, then rotated into the camera: W R S⁻² Rᵀ Wᵀ.
        let rot = mul3(&cam.r, &quat_to_rot(q.map(|v| v / qn)));
        let mut inv_cov = [[0.0; 3]; 3];
        for a in 0..3 {
            for b in 0..3 {
                inv_cov[a][b] = (0..3)
                    .map(|k| rot[a][k] * rot[b][k] / (scales[k] * scales[k]))
                    .sum();
            }
        }
        let mean = [0, 1, 2].map(|a| (0..3).map(|k| cam.r[a][k] * m[k]).sum::<f64>() + cam.t[a]);
        let inv_cov_mean = [0, 1, 2].map(|a| (0..3).map(|k| inv_cov[a][k] * mean[k]).sum());
        Some(RayDepth {
            inv_cov,
            inv_cov_mean,
            mean_z: mean[2],
            reach: REACH
                * scales
                    .iter()
                    .copied()
                    .fold(mean[2] / cam.fx.min(cam.fy), f64::max),
        })
    }

    /// Camera depth at which the ray through the image point `(px, py)` (pixel units, a pixel's
    /// centre at `x + 0.5`) passes this Gaussian's densest point, kept within the Gaussian's
    /// reach of its centre depth.
    pub(crate) fn at(&self, cam: &Cam, px: f64, py: f64) -> f64 {
        let d = [(px - cam.cx) / cam.fx, (py - cam.cy) / cam.fy, 1.0];
        let a = &self.inv_cov;
        let ad = [0, 1, 2].map(|r| a[r][0] * d[0] + a[r][1] * d[1] + a[r][2] * d[2]);
        let den = d[0] * ad[0] + d[1] * ad[1] + d[2] * ad[2];
        let num = (0..3).map(|k| d[k] * self.inv_cov_mean[k]).sum::<f64>();
        let t = num / den;
        if !(t.is_finite() && den > 0.0) {
            return self.mean_z;
        }
        t.clamp(self.mean_z - self.reach, self.mean_z + self.reach)
    }
}

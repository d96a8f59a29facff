//! Differentiable 3D Gaussian splatting on the CPU, with gradients for every camera pose.
//!
//! The semantics are those of gsplat 1.5 (classic or antialiased rasterisation, pinhole camera):
//! EWA projection with eps2d 0.3, near 0.01 / far 1e10, the 0.3·tan_fov Jacobian guard band,
//! per-axis radius `ceil(3.33·σ)`, 16×16 tiles with per-tile depth-sorted lists,
//! `α = min(0.999, o·exp(−σ))`, skip `α < 1/255`, stop before a Gaussian that would bring the
//! transmittance to ≤ 1e-4, colour `max(SH(mean − camera centre) + 0.5, 0)`, background `T·bg`.
//!
//! API overview:
//! * [`Gaussians`] — the scene, structure of arrays (means, wxyz quats, log-scales, opacity
//!   logits, 16 SH coefficients per channel and an active degree).
//! * [`Camera`] — pinhole intrinsics and an OpenCV world-to-camera pose
//!   (`x_cam = rotation · x_world + translation`).
//! * [`Renderer`] — the fast f32 tile renderer: [`Renderer::forward`] renders C cameras of one
//!   scene in one call (all of one size) and remembers what [`Renderer::backward`] needs;
//!   `backward` turns `dL/dRGB` (and optionally `dL/dalpha`) into [`Gradients`] for every
//!   Gaussian parameter, every background and every camera's rotation and translation, plus
//!   densification statistics. Buffers are reused across calls. After a forward,
//!   [`Renderer::surface_depth`] gives each pixel's surface depth (where its ray meets the
//!   Gaussian that halves its transmittance), for geometry rather than training.
//! * [`reference`] — a slow, dense, f64 renderer with the same semantics; the fast path and
//!   the gsplat test vectors are checked against it and it is checked by finite differences.
//! * [`ply`] — Inria-layout PLY read/write (opens in common splat viewers).
//! * [`activation`] — the opacity logit ↔ opacity maps (`sigmoid`, `logit`).
//! * [`sh`] — the real SH basis ([`sh::basis`], [`sh::C0`]) colours are evaluated with.
//! * [`write_png`] — one camera of a [`RenderOutput`] as an 8-bit PNG, written atomically.
//!
//! Per-(camera, Gaussian) projection, SH colour and their backward are computed in f64 by one
//! shared implementation (`project`); it is cheap next to the per-pixel work, which is f32 in the
//! fast path and f64 in the reference. Results do not depend on the number of rayon threads:
//! every parallel reduction is over fixed chunks summed in a fixed order.

// Small fixed-size matrix and channel loops read best with explicit indices.
#![allow(clippy::needless_range_loop)]

pub mod activation;
pub mod ply;
mod png;
mod project;
mod raster;
pub mod reference;
pub mod sh;
mod surface;

pub use png::write_png;
pub use raster::Renderer;
pub use surface::SURFACE_TRANSMITTANCE;

use gems_math::{Intrinsics, Se3};

/// Number of SH coefficients per colour channel stored per Gaussian (degree 3).
pub const SH_COEFFS: usize = 16;

/// Errors of the splatting engine.
#[derive(Debug, thiserror::Error)]
pub enum SplatError {
    /// The scene's arrays disagree in length or the SH degree is out of range.
    #[error("invalid Gaussians: {0}")]
    InvalidGaussians(String),
    /// A camera has non-finite or non-positive intrinsics, an empty image or a non-finite pose.
    #[error("invalid camera {index}: {reason}")]
    InvalidCamera { index: usize, reason: String },
    /// Cameras, backgrounds and gradient buffers do not fit together.
    #[error("shape mismatch: {0}")]
    Shape(String),
    /// `backward` was called without a matching `forward`.
    #[error("backward called without a matching forward: {0}")]
    NoForward(String),
    /// Reading or writing a PLY file failed.
    #[error("PLY file {path}: {reason}")]
    Ply {
        path: std::path::PathBuf,
        reason: String,
    },
    /// Writing an image failed.
    #[error("image file {path}: {reason}")]
    Image {
        path: std::path::PathBuf,
        reason: String,
    },
}

/// Structure-of-arrays Gaussians. quats wxyz, not necessarily normalised.
///
/// Gaussians with non-finite parameters or a (near-)zero quaternion are culled by the renderer
/// (they draw nothing and get zero gradients) rather than rejected.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Gaussians {
    pub means: Vec<[f32; 3]>,
    pub quats: Vec<[f32; 4]>,
    pub log_scales: Vec<[f32; 3]>,
    pub opacity_logits: Vec<f32>,
    /// SH coefficients `[coefficient][channel]`; those above `sh_degree` are ignored.
    pub sh: Vec<[[f32; 3]; SH_COEFFS]>,
    /// Active SH degree, 0..=3.
    pub sh_degree: u32,
}

impl Gaussians {
    /// Number of Gaussians.
    pub fn len(&self) -> usize {
        self.means.len()
    }

    pub fn is_empty(&self) -> bool {
        self.means.is_empty()
    }

    /// Every parameter's bit pattern (means, quaternions, log-scales, opacity logits, SH), for
    /// bit-identity checks: comparing the f32 values would take 0.0 for −0.0.
    pub fn parameter_bits(&self) -> Vec<u32> {
        let means = self.means.iter().flatten();
        let quats = self.quats.iter().flatten();
        let scales = self.log_scales.iter().flatten();
        let sh = self.sh.iter().flatten().flatten();
        means
            .chain(quats)
            .chain(scales)
            .chain(&self.opacity_logits)
            .chain(sh)
            .map(|x| x.to_bits())
            .collect()
    }

    /// Checks that all arrays have the same length and the SH degree is at most 3.
    pub fn validate(&self) -> Result<(), SplatError> {
        let n = self.means.len();
        let lens = [
            ("quats", self.quats.len()),
            ("log_scales", self.log_scales.len()),
            ("opacity_logits", self.opacity_logits.len()),
            ("sh", self.sh.len()),
        ];
        for (name, len) in lens {
            if len != n {
                return Err(SplatError::InvalidGaussians(format!(
                    "{name} has {len} entries but means has {n}"
                )));
            }
        }
        if self.sh_degree > 3 {
            return Err(SplatError::InvalidGaussians(format!(
                "sh_degree {} is above 3",
                self.sh_degree
            )));
        }
        Ok(())
    }

    /// Appends one Gaussian.
    pub fn push(
        &mut self,
        mean: [f32; 3],
        quat: [f32; 4],
        log_scale: [f32; 3],
        opacity_logit: f32,
        sh: [[f32; 3]; SH_COEFFS],
    ) {
        self.means.push(mean);
        self.quats.push(quat);
        self.log_scales.push(log_scale);
        self.opacity_logits.push(opacity_logit);
        self.sh.push(sh);
    }

    /// An empty scene with the given SH degree.
    pub fn with_degree(sh_degree: u32) -> Self {
        Gaussians {
            sh_degree,
            ..Default::default()
        }
    }
}

/// Pinhole camera, world-to-camera in OpenCV convention: x_cam = rotation * x_world + translation (row-major rotation).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    pub fx: f32,
    pub fy: f32,
    pub cx: f32,
    pub cy: f32,
    pub width: u32,
    pub height: u32,
    pub rotation: [[f32; 3]; 3],
    pub translation: [f32; 3],
}

impl Camera {
    /// Camera centre in world coordinates, `−Rᵀ t`.
    pub fn center(&self) -> [f32; 3] {
        let r = &self.rotation;
        let t = &self.translation;
        let mut c = [0.0f32; 3];
        for (i, ci) in c.iter_mut().enumerate() {
            *ci = -(r[0][i] * t[0] + r[1][i] * t[1] + r[2][i] * t[2]);
        }
        c
    }

    /// The renderer camera of a world-to-camera pose: the f64 camera vocabulary of gems-math
    /// meets the f32 renderer here and nowhere else.
    pub fn new(k: &Intrinsics, w2c: &Se3) -> Camera {
        let (rotation, translation) = w2c.to_f32_arrays();
        Camera::with_pose(k, rotation, translation)
    }

    /// `k` narrowed to f32 with an f32 world-to-camera pose.
    fn with_pose(k: &Intrinsics, rotation: [[f32; 3]; 3], translation: [f32; 3]) -> Camera {
        Camera {
            fx: k.fx as f32,
            fy: k.fy as f32,
            cx: k.cx as f32,
            cy: k.cy as f32,
            width: k.width,
            height: k.height,
            rotation,
            translation,
        }
    }

    /// The renderer camera of a camera-to-world pose (the trajectories' convention).
    pub fn from_c2w(k: &Intrinsics, c2w: &Se3) -> Camera {
        Camera::new(k, &c2w.inverse())
    }

    /// A camera at `position` looking at `target`, with image "up" (−y in OpenCV) as close to
    /// `up` as possible. Returns `None` when the view direction is degenerate.
    pub fn look_at(
        k: &Intrinsics,
        position: [f32; 3],
        target: [f32; 3],
        up: [f32; 3],
    ) -> Option<Camera> {
        let sub = |a: [f32; 3], b: [f32; 3]| [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
        let cross = |a: [f32; 3], b: [f32; 3]| {
            [
                a[1] * b[2] - a[2] * b[1],
                a[2] * b[0] - a[0] * b[2],
                a[0] * b[1] - a[1] * b[0],
            ]
        };
        let normalize = |a: [f32; 3]| {
            let n = (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt();
            (n > 1e-12 && n.is_finite()).then(|| [a[0] / n, a[1] / n, a[2] / n])
        };
        let z = normalize(sub(target, position))?;
        // OpenCV (x right, y down, z forward, x × y = z): x = z × up makes y = z × x the
        // component of −up orthogonal to z.
        let x = normalize(cross(z, up))?;
        let y = cross(z, x);
        let rotation = [x, y, z];
        let mut translation = [0.0f32; 3];
        for (i, ti) in translation.iter_mut().enumerate() {
            *ti = -(rotation[i][0] * position[0]
                + rotation[i][1] * position[1]
                + rotation[i][2] * position[2]);
        }
        Some(Camera::with_pose(k, rotation, translation))
    }

    pub(crate) fn check(&self, index: usize) -> Result<(), SplatError> {
        let bad = |reason: &str| SplatError::InvalidCamera {
            index,
            reason: reason.to_owned(),
        };
        let intr = [self.fx, self.fy, self.cx, self.cy];
        if !intr.iter().all(|v| v.is_finite()) || self.fx <= 0.0 || self.fy <= 0.0 {
            return Err(bad("fx, fy must be finite and positive, cx, cy finite"));
        }
        if self.width == 0 || self.height == 0 {
            return Err(bad("image size must be positive"));
        }
        if !self.rotation.iter().flatten().all(|v| v.is_finite())
            || !self.translation.iter().all(|v| v.is_finite())
        {
            return Err(bad("pose must be finite"));
        }
        Ok(())
    }
}

/// Rasterisation settings; `Default` gives gsplat 1.5's defaults (classic mode, no depth).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RenderSettings {
    /// Mip-Splatting opacity compensation `sqrt(det Σ2D / det(Σ2D + eps2d·I))`.
    pub antialiased: bool,
    /// Also output expected depth `Σ w·z / Σ w` (0 where nothing is drawn); forward only.
    pub compute_depth: bool,
    /// Low-pass filter added to the 2D covariance diagonal.
    pub eps2d: f32,
    pub near_plane: f32,
    pub far_plane: f32,
    /// Opacity clamp.
    pub alpha_max: f32,
    /// Gaussians with smaller α at a pixel are skipped there.
    pub alpha_min: f32,
    /// A pixel stops before the Gaussian that would bring T to at most this.
    pub transmittance_min: f32,
    /// Radius of the screen-space box in standard deviations (per axis, rounded up).
    pub radius_extent: f32,
}

impl Default for RenderSettings {
    fn default() -> Self {
        RenderSettings {
            antialiased: false,
            compute_depth: false,
            eps2d: 0.3,
            near_plane: 0.01,
            far_plane: 1e10,
            alpha_max: 0.999,
            alpha_min: 1.0 / 255.0,
            transmittance_min: 1e-4,
            radius_extent: 3.33,
        }
    }
}

/// Rendered images of C cameras.
#[derive(Clone, Debug, PartialEq)]
pub struct RenderOutput {
    pub width: u32,
    pub height: u32,
    pub num_cameras: usize,
    /// `[C,H,W,3]`, background included.
    pub rgb: Vec<f32>,
    /// `[C,H,W]`, `1 − T`.
    pub alpha: Vec<f32>,
    /// `[C,H,W]` expected depth when requested.
    pub depth: Option<Vec<f32>>,
    /// `[C,N,2]` per-axis screen radius in pixels; 0 means culled for that camera.
    pub radii: Vec<[i32; 2]>,
}

/// Gradients of a scalar loss, from [`Renderer::backward`] or [`reference::backward`].
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Gradients {
    pub means: Vec<[f32; 3]>,
    /// W.r.t. the raw (unnormalised) quaternion.
    pub quats: Vec<[f32; 4]>,
    pub log_scales: Vec<[f32; 3]>,
    pub opacity_logits: Vec<f32>,
    pub sh: Vec<[[f32; 3]; SH_COEFFS]>,
    /// Per camera.
    pub backgrounds: Vec<[f32; 3]>,
    /// Euclidean dL/dR per camera.
    pub cam_rotation: Vec<[[f32; 3]; 3]>,
    pub cam_translation: Vec<[f32; 3]>,
    /// (dL/dfx, dL/dfy) per camera.
    pub cam_focal: Vec<[f32; 2]>,
    /// Per Gaussian, summed over cameras: `|dL/d mean2d|` (pixel units) of each camera.
    pub mean2d_grad_norm: Vec<f32>,
    /// Per Gaussian: the number of cameras in which it was not culled (radius > 0).
    pub visible_count: Vec<u32>,
}

/// Checks one render call's inputs as [`Renderer::forward`] does (valid scene, at least one
/// camera, valid cameras all of one size, one background per camera); returns the image size.
/// Public so that other engines (the GPU one) apply exactly the same rules.
pub fn check_inputs(
    g: &Gaussians,
    cams: &[Camera],
    backgrounds: &[[f32; 3]],
) -> Result<(u32, u32), SplatError> {
    g.validate()?;
    let first = cams
        .first()
        .ok_or_else(|| SplatError::Shape("at least one camera is needed".into()))?;
    for (i, c) in cams.iter().enumerate() {
        c.check(i)?;
        if c.width != first.width || c.height != first.height {
            return Err(SplatError::Shape(format!(
                "camera {i} is {}x{} but camera 0 is {}x{}; all cameras of a call share one size",
                c.width, c.height, first.width, first.height
            )));
        }
    }
    if backgrounds.len() != cams.len() {
        return Err(SplatError::Shape(format!(
            "{} backgrounds for {} cameras",
            backgrounds.len(),
            cams.len()
        )));
    }
    Ok((first.width, first.height))
}

/// The shape of one render call: Gaussians, cameras, width and height.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BatchShape {
    pub gaussians: usize,
    pub cameras: usize,
    pub width: usize,
    pub height: usize,
}

/// Checks that a backward call has the shape of the forward it follows (both engines keep
/// what backward needs from the last forward).
pub fn check_same_batch(forward: BatchShape, backward: BatchShape) -> Result<(), SplatError> {
    if forward == backward {
        return Ok(());
    }
    Err(SplatError::NoForward(format!(
        "forward had {} Gaussians, {} cameras of {}x{}; backward got {}, {} of {}x{}",
        forward.gaussians,
        forward.cameras,
        forward.width,
        forward.height,
        backward.gaussians,
        backward.cameras,
        backward.width,
        backward.height
    )))
}

//! The physical blur model and its gradient chain.
//!
//! For a training view with initial camera-to-world pose c2w₀ and trajectory Δ(u), the n virtual
//! cameras are c2w_k = c2w₀·Δ(u_k), u_k = linspace(0, 1, n). All n are rendered in ONE renderer
//! call; the synthesised blurry image is their mean in sRGB (GeMS Eq. 1, BAD-Gaussians).
//!
//! Backward: dL/d(render_k) = dL/d(blurred) / n for every k; the renderer turns these into
//! Gaussian gradients and per-camera Euclidean dL/dR, dL/dt (world-to-camera); those become the
//! gradient w.r.t. the right perturbation of c2w_k (= of Δ(u_k), since c2w₀ is a constant left
//! factor), and each knot j receives Σ_k J_jkᵀ · g_k.

use gems_gpu::Engine;
use gems_math::{Intrinsics, Se3, Trajectory, c2w_right_perturbation_gradient};
use gems_splat::{Camera, Gaussians, Gradients};

use crate::TrainError;

/// One blurry image's exposure as the blur model sees it: the initial camera-to-world pose, the
/// trajectory Δ(u) over the exposure, the virtual-camera times u_k and the camera.
#[derive(Clone, Copy, Debug)]
pub struct Exposure<'a> {
    pub c2w_init: &'a Se3,
    pub trajectory: &'a Trajectory,
    pub times: &'a [f64],
    pub intrinsics: &'a Intrinsics,
}

/// A differentiable renderer of C cameras of one scene (the CPU or GPU engine, or the f64
/// reference in tests).
pub trait Rasterizer {
    /// Renders `cams`; returns RGB `[C,H,W,3]`.
    fn render(
        &mut self,
        g: &Gaussians,
        cams: &[Camera],
        bgs: &[[f32; 3]],
    ) -> Result<Vec<f32>, TrainError>;
    /// Gradients of a loss with dL/dRGB = `d_rgb` for the last `render` of the same inputs.
    fn gradients(
        &mut self,
        g: &Gaussians,
        cams: &[Camera],
        bgs: &[[f32; 3]],
        d_rgb: &[f32],
    ) -> Result<Gradients, TrainError>;
}

/// Both engines through [`Engine`], which dispatches to the one a run chose.
impl Rasterizer for Engine {
    fn render(
        &mut self,
        g: &Gaussians,
        cams: &[Camera],
        bgs: &[[f32; 3]],
    ) -> Result<Vec<f32>, TrainError> {
        Ok(self
            .forward(g, cams, bgs, &gems_splat::RenderSettings::default())?
            .rgb)
    }

    fn gradients(
        &mut self,
        g: &Gaussians,
        cams: &[Camera],
        bgs: &[[f32; 3]],
        d_rgb: &[f32],
    ) -> Result<Gradients, TrainError> {
        Ok(self.backward(g, cams, bgs, d_rgb, None)?)
    }
}

/// The n virtual camera-to-world poses c2w₀·Δ(u_k).
pub fn virtual_c2w(c2w_init: &Se3, traj: &Trajectory, times: &[f64]) -> Vec<Se3> {
    times.iter().map(|&u| *c2w_init * traj.eval(u)).collect()
}

/// Reusable per-step buffers (no allocation per step once sized).
#[derive(Default)]
pub struct BlurWorkspace {
    pub cams: Vec<Camera>,
    pub bgs: Vec<[f32; 3]>,
    /// Mean of the virtual renders, `[H,W,3]`.
    pub blurred: Vec<f32>,
    /// dL/d(render) of every virtual camera, `[C,H,W,3]`.
    pub d_rgb: Vec<f32>,
}

/// Renders the blurred image of a view into `ws.blurred` (and keeps the cameras in `ws.cams`).
pub fn render_blurred<R: Rasterizer + ?Sized>(
    r: &mut R,
    g: &Gaussians,
    exposure: &Exposure,
    bg: [f32; 3],
    ws: &mut BlurWorkspace,
) -> Result<(), TrainError> {
    let (times, k) = (exposure.times, exposure.intrinsics);
    virtual_cameras(exposure, &mut ws.cams);
    ws.bgs.clear();
    ws.bgs.resize(times.len(), bg);
    let rgb = r.render(g, &ws.cams, &ws.bgs)?;
    let img = (k.width * k.height * 3) as usize;
    ws.blurred.clear();
    ws.blurred.resize(img, 0.0);
    let inv_n = 1.0 / times.len() as f32;
    for view in rgb.chunks_exact(img) {
        for (b, v) in ws.blurred.iter_mut().zip(view) {
            *b += v * inv_n;
        }
    }
    Ok(())
}

/// Back-propagates dL/d(blurred) (`d_blurred`, `[H,W,3]`) through the blur model for the cameras
/// of the last [`render_blurred`]: returns the renderer's gradients (Gaussians and per-camera
/// poses) and adds each knot's gradient to `knot_grads` (one [ρ; φ] per knot).
pub fn backward_blurred<R: Rasterizer + ?Sized>(
    r: &mut R,
    g: &Gaussians,
    exposure: &Exposure,
    d_blurred: &[f32],
    ws: &mut BlurWorkspace,
    knot_grads: &mut [[f64; 6]],
) -> Result<Gradients, TrainError> {
    let times = exposure.times;
    let inv_n = 1.0 / times.len() as f32;
    ws.d_rgb.clear();
    for _ in 0..times.len() {
        ws.d_rgb.extend(d_blurred.iter().map(|d| d * inv_n));
    }
    let grads = r.gradients(g, &ws.cams, &ws.bgs, &ws.d_rgb)?;
    accumulate_knot_gradients(
        exposure.trajectory,
        times,
        &ws.cams,
        &grads.cam_rotation,
        &grads.cam_translation,
        knot_grads,
    );
    Ok(grads)
}

/// The n virtual cameras of a view (world-to-camera, for the renderer) into `out`.
pub fn virtual_cameras(exposure: &Exposure, out: &mut Vec<Camera>) {
    let Exposure {
        c2w_init,
        trajectory,
        times,
        intrinsics,
    } = *exposure;
    out.clear();
    out.extend(
        times
            .iter()
            .map(|&u| Camera::from_c2w(intrinsics, &(*c2w_init * trajectory.eval(u)))),
    );
}

/// Adds each knot's gradient to `knot_grads` from the renderer's per-camera Euclidean pose
/// gradients (`d_rotation[k]` = dL/dR, `d_translation[k]` = dL/dt of `cams[k]`, rendered at
/// `times[k]`): the chain from the renderer's cameras to the trajectory, for either engine.
pub fn accumulate_knot_gradients(
    traj: &Trajectory,
    times: &[f64],
    cams: &[Camera],
    d_rotation: &[[[f32; 3]; 3]],
    d_translation: &[[f32; 3]],
    knot_grads: &mut [[f64; 6]],
) {
    for (k, &u) in times.iter().enumerate() {
        let w2c = Se3::from_f32_arrays(&cams[k].rotation, &cams[k].translation);
        let dr = d_rotation[k].map(|row| row.map(|v| v as f64));
        let dt = d_translation[k].map(|v| v as f64);
        let g_delta = c2w_right_perturbation_gradient(&w2c, &dr, &dt);
        traj.accumulate_knot_gradients(u, &g_delta, knot_grads);
    }
}

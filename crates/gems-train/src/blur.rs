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
use gems_math::{Intrinsics, Se3, Trajectory, Vector3, c2w_right_perturbation_gradient};
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

/// Exposure times of `n` virtual cameras: linspace(0, 1, n) with both ends, or the midpoint
/// alone for one camera.
pub fn exposure_times(n: usize) -> Vec<f64> {
    match n {
        0 => Vec::new(),
        1 => vec![0.5],
        _ => (0..n).map(|k| k as f64 / (n - 1) as f64).collect(),
    }
}

/// The scene depths at which a view's blur length is measured: the 10th percentile (near
/// content, which translation blurs most) and the median of the depths of `means` that lie in
/// front of the camera `c2w` and inside its image; `None` when fewer than 8 do. At most about
/// 20 000 points are read (an even stride), so the cost does not grow with the scene.
pub fn blur_depths(means: &[[f32; 3]], c2w: &Se3, k: &Intrinsics) -> Option<[f32; 2]> {
    let w2c = c2w.inverse();
    let stride = means.len().div_ceil(20_000).max(1);
    let mut depths: Vec<f64> = means
        .iter()
        .step_by(stride)
        .filter_map(|m| {
            let p = w2c.act(&Vector3::new(m[0] as f64, m[1] as f64, m[2] as f64));
            let x = k.fx * p.x / p.z + k.cx;
            let y = k.fy * p.y / p.z + k.cy;
            let inside = p.z > 0.0
                && (0.0..k.width as f64).contains(&x)
                && (0.0..k.height as f64).contains(&y);
            inside.then_some(p.z)
        })
        .collect();
    if depths.len() < 8 {
        return None;
    }
    depths.sort_by(f64::total_cmp);
    let at = |q: f64| depths[((depths.len() - 1) as f64 * q).round() as usize] as f32;
    Some([at(0.1), at(0.5)])
}

/// Samples of the exposure at which [`blur_length_px`] places the probes.
const PATH_SAMPLES: usize = 17;

/// The blur's extent in pixels (of `k`): the widest spread of the image positions that nine
/// probe points take over the exposure (the largest distance between two of a probe's positions,
/// the largest over probes). The probes are a 3×3 grid of pixels at 1/6, 1/2 and 5/6 of the
/// image, each at both `depths`, placed by the mid-exposure camera c2w₀·Δ(½) and followed
/// through the cameras c2w₀·Δ(u) at 17 evenly spaced times. Rotation moves every probe and
/// translation the near ones most, so the widest spread bounds the blur the photo shows. The
/// spread, not the path's length: trained paths wiggle (on a `gems synth` scene with 3 px of
/// blur the centre probe's path was 9 px long within a 3 px spread, BENCHMARKS.md), and the
/// time-average of images along a path that stays within a few pixels is a blur of those few
/// pixels. Infinite when a probe passes behind a camera.
pub fn blur_length_px(c2w_init: &Se3, traj: &Trajectory, k: &Intrinsics, depths: [f32; 2]) -> f64 {
    let w2c: Vec<Se3> = exposure_times(PATH_SAMPLES)
        .iter()
        .map(|&u| (*c2w_init * traj.eval(u)).inverse())
        .collect();
    let mid = *c2w_init * traj.eval(0.5);
    let (w, h) = (k.width as f64, k.height as f64);
    let mut widest = 0.0f64;
    let mut seen: Vec<(f64, f64)> = Vec::with_capacity(PATH_SAMPLES);
    for fy in [1.0 / 6.0, 0.5, 5.0 / 6.0] {
        for fx in [1.0 / 6.0, 0.5, 5.0 / 6.0] {
            let ray = Vector3::new((fx * w - k.cx) / k.fx, (fy * h - k.cy) / k.fy, 1.0);
            for z in depths {
                let world = mid.act(&(ray * z as f64));
                seen.clear();
                for c in &w2c {
                    let p = c.act(&world);
                    if p.z.is_nan() || p.z <= 0.0 {
                        return f64::INFINITY;
                    }
                    let xy = (k.fx * p.x / p.z + k.cx, k.fy * p.y / p.z + k.cy);
                    for &(x, y) in &seen {
                        widest = widest.max((xy.0 - x).hypot(xy.1 - y));
                    }
                    seen.push(xy);
                }
            }
        }
    }
    widest
}

/// Virtual views for a blur of `length_px` pixels with adjacent views at most `spacing_px`
/// apart: ⌈length / spacing⌉ + 1, at most `cap`, and 1 when the blur is under half the spacing
/// (the photo is sharp at this resolution). `spacing_px` = 0 or a non-finite length gives `cap`.
pub fn virtual_view_count(length_px: f64, spacing_px: f64, cap: usize) -> usize {
    if spacing_px.is_nan() || spacing_px <= 0.0 || !length_px.is_finite() {
        return cap;
    }
    if length_px < 0.5 * spacing_px {
        return 1.min(cap);
    }
    let n = (length_px / spacing_px).ceil() + 1.0;
    if n >= cap as f64 { cap } else { n as usize }
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
/// poses) and adds each knot's gradient to `knot_grads` (one [ρ; φ] per knot). Each view's
/// share of `d_blurred` is `view_weights[k]` ([`backward_view_weights`]), 1/n each when `None`
/// (the blur model's exact gradient).
pub fn backward_blurred<R: Rasterizer + ?Sized>(
    r: &mut R,
    g: &Gaussians,
    exposure: &Exposure,
    d_blurred: &[f32],
    view_weights: Option<&[f32]>,
    ws: &mut BlurWorkspace,
    knot_grads: &mut [[f64; 6]],
) -> Result<Gradients, TrainError> {
    let times = exposure.times;
    let inv_n = 1.0 / times.len() as f32;
    if let Some(w) = view_weights
        && w.len() != times.len()
    {
        return Err(TrainError::Input(format!(
            "{} view weights for {} virtual views",
            w.len(),
            times.len()
        )));
    }
    ws.d_rgb.clear();
    for k in 0..times.len() {
        match view_weights.map_or(inv_n, |w| w[k]) {
            // Exact zeros, so that the renderer skips this camera.
            0.0 => ws.d_rgb.resize(ws.d_rgb.len() + d_blurred.len(), 0.0),
            wk => ws.d_rgb.extend(d_blurred.iter().map(|d| d * wk)),
        }
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

/// Each virtual view's weight in a step's backward (`TrainConfig::backward_virtual_views`):
/// with `k` in 1..n, the n views split into k runs of consecutive views (run j is
/// `j·n/k .. (j+1)·n/k`), one view drawn uniformly from each and weighted by its run's length
/// over n, every other view 0; else `None` (every view at 1/n). A view of a run of length m is
/// drawn with probability 1/m at weight m/n, so its expected weight is 1/n, that of the full
/// backward. The draw depends only on `seed` and `step`, so a resumed run repeats it.
pub fn backward_view_weights(n: usize, k: usize, seed: u64, step: usize) -> Option<Vec<f32>> {
    use rand::{RngExt, SeedableRng};
    if k == 0 || k >= n {
        return None;
    }
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed ^ 0x6261_636b_7761_7264);
    rng.set_stream(step as u64);
    let mut w = vec![0.0f32; n];
    for j in 0..k {
        let (start, end) = (j * n / k, (j + 1) * n / k);
        w[rng.random_range(start..end)] = (end - start) as f32 / n as f32;
    }
    Some(w)
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn backward_view_weights_draw_one_view_per_run_with_expectation_one_over_n() {
        assert_eq!(backward_view_weights(15, 0, 1, 3), None);
        assert_eq!(backward_view_weights(15, 15, 1, 3), None);
        assert_eq!(backward_view_weights(4, 9, 1, 3), None);
        for (n, k) in [(15, 5), (15, 4), (7, 3), (2, 1), (9, 8)] {
            let runs: Vec<(usize, usize)> = (0..k).map(|j| (j * n / k, (j + 1) * n / k)).collect();
            let steps = 4000;
            let mut mean = vec![0.0f64; n];
            for step in 0..steps {
                let w = backward_view_weights(n, k, 11, step).unwrap();
                assert_eq!(w, backward_view_weights(n, k, 11, step).unwrap());
                for &(start, end) in &runs {
                    let drawn: Vec<usize> = (start..end).filter(|&i| w[i] != 0.0).collect();
                    assert_eq!(drawn.len(), 1, "n {n} k {k} run {start}..{end}: {w:?}");
                    assert_eq!(w[drawn[0]], (end - start) as f32 / n as f32);
                }
                let sum: f32 = w.iter().sum();
                assert!((sum - 1.0).abs() < 1e-6, "{w:?}");
                for (m, wi) in mean.iter_mut().zip(&w) {
                    *m += f64::from(*wi) / steps as f64;
                }
            }
            // Unbiased: every view's mean weight is 1/n (within the draws' sampling error).
            for (i, m) in mean.iter().enumerate() {
                assert!(
                    (m - 1.0 / n as f64).abs() < 0.15 / n as f64,
                    "n {n} k {k} view {i}: mean weight {m}"
                );
            }
        }
        // Another step or seed draws other views.
        let at = |seed, step| backward_view_weights(15, 5, seed, step).unwrap();
        assert!((1..20).any(|s| at(1, s) != at(1, 0)));
        assert!((1..20).any(|s| at(s, 0) != at(0, 0)));
    }
    use gems_math::TrajectoryKind;

    fn camera() -> Intrinsics {
        Intrinsics {
            fx: 300.0,
            fy: 300.0,
            cx: 200.0,
            cy: 135.0,
            width: 400,
            height: 270,
        }
    }

    /// A linear trajectory from Exp(ξ₀) to Exp(ξ₁).
    fn linear(start: [f64; 6], end: [f64; 6]) -> Trajectory {
        Trajectory::new(TrajectoryKind::Linear, vec![start, end]).unwrap()
    }

    #[test]
    fn exposure_times_are_linspace_or_the_midpoint() {
        assert_eq!(exposure_times(1), vec![0.5]);
        assert_eq!(exposure_times(3), vec![0.0, 0.5, 1.0]);
        let t = exposure_times(15);
        assert_eq!((t.len(), t[0], t[14]), (15, 0.0, 1.0));
    }

    #[test]
    fn view_count_spaces_adjacent_views_at_most_the_spacing_apart() {
        assert_eq!(virtual_view_count(0.0, 1.0, 15), 1);
        assert_eq!(virtual_view_count(0.49, 1.0, 15), 1);
        assert_eq!(virtual_view_count(0.5, 1.0, 15), 2);
        assert_eq!(virtual_view_count(1.0, 1.0, 15), 2);
        assert_eq!(virtual_view_count(4.2, 1.0, 15), 6);
        assert_eq!(virtual_view_count(4.2, 2.0, 15), 4);
        assert_eq!(virtual_view_count(13.9, 1.0, 15), 15);
        assert_eq!(virtual_view_count(300.0, 1.0, 15), 15);
        assert_eq!(virtual_view_count(f64::INFINITY, 1.0, 15), 15);
        assert_eq!(virtual_view_count(f64::NAN, 1.0, 15), 15);
        // Spacing 0 turns adaptation off; a cap of one is kept.
        assert_eq!(virtual_view_count(0.0, 0.0, 15), 15);
        assert_eq!(virtual_view_count(0.0, 1.0, 1), 1);
        assert_eq!(virtual_view_count(9.0, 1.0, 1), 1);
        // Property: with n views over L pixels the gap is at most the spacing, and with one
        // view fewer (from three up) it would not be.
        for i in 0..400 {
            let length = i as f64 * 0.037;
            let n = virtual_view_count(length, 1.0, 1000);
            assert!(n == 1 || length / (n - 1) as f64 <= 1.0, "{length} → {n}");
            assert!(n < 3 || length / (n - 2) as f64 > 1.0, "{length} → {n}");
        }
    }

    #[test]
    fn a_sideways_translation_blurs_near_content_by_focal_times_baseline_over_depth() {
        let k = camera();
        // The camera slides 0.2 along its x axis over the exposure, centred on c2w₀.
        let traj = linear(
            [-0.1, 0.0, 0.0, 0.0, 0.0, 0.0],
            [0.1, 0.0, 0.0, 0.0, 0.0, 0.0],
        );
        let c2w = Se3::exp(&gems_math::Vector6::new(0.3, -0.2, 0.1, 0.05, 0.1, -0.02));
        let length = blur_length_px(&c2w, &traj, &k, [2.0, 5.0]);
        assert!((length - 300.0 * 0.2 / 2.0).abs() < 1e-9, "{length}");
        // Only the far depth: less blur.
        let far = blur_length_px(&c2w, &traj, &k, [5.0, 5.0]);
        assert!((far - 300.0 * 0.2 / 5.0).abs() < 1e-9, "{far}");
        // A still camera draws no path.
        let still = linear([0.0; 6], [0.0; 6]);
        assert!(blur_length_px(&c2w, &still, &k, [2.0, 5.0]) < 1e-9);
    }

    #[test]
    fn a_pan_blurs_every_depth_by_about_focal_times_angle() {
        let k = camera();
        let b = 0.02;
        let traj = linear([0.0, 0.0, 0.0, 0.0, -b, 0.0], [0.0, 0.0, 0.0, 0.0, b, 0.0]);
        let c2w = Se3::identity();
        let near = blur_length_px(&c2w, &traj, &k, [1.0, 1.0]);
        let far = blur_length_px(&c2w, &traj, &k, [50.0, 50.0]);
        assert!((near - far).abs() < 1e-6, "{near} {far}");
        // The centre probe moves f·(tan b + tan b); the side probes up to (1 + (x/f)²) times that.
        let centre = 2.0 * 300.0 * b.tan();
        let side = 1.0 + (200.0 * 2.0 / 3.0 / 300.0f64).powi(2);
        assert!(
            near >= centre - 1e-9 && near <= centre * side * 1.01,
            "{near} {centre}"
        );
    }

    #[test]
    fn a_path_that_turns_back_blurs_by_its_spread_not_its_length() {
        let k = camera();
        // Quadratic Bézier with its middle knot sideways: the camera slides out to a/2 at u = ½
        // and back, drawing a path of length fx·a/z over a spread of fx·a/(2z).
        let a = 0.2;
        let traj = Trajectory::new(
            TrajectoryKind::Bezier,
            vec![[0.0; 6], [a, 0.0, 0.0, 0.0, 0.0, 0.0], [0.0; 6]],
        )
        .unwrap();
        let length = blur_length_px(&Se3::identity(), &traj, &k, [2.0, 4.0]);
        assert!((length - 300.0 * a / 2.0 / 2.0).abs() < 1e-9, "{length}");
    }

    #[test]
    fn a_probe_passing_behind_the_camera_asks_for_every_view() {
        let k = camera();
        // Forward by 3 over the exposure with content 1 in front of the mid pose.
        let traj = linear(
            [0.0, 0.0, -1.5, 0.0, 0.0, 0.0],
            [0.0, 0.0, 1.5, 0.0, 0.0, 0.0],
        );
        let length = blur_length_px(&Se3::identity(), &traj, &k, [1.0, 1.0]);
        assert_eq!(length, f64::INFINITY);
        assert_eq!(virtual_view_count(length, 1.0, 15), 15);
    }

    #[test]
    fn blur_depths_are_the_near_and_median_depths_of_the_points_in_view() {
        let k = camera();
        let c2w = Se3::exp(&gems_math::Vector6::new(1.0, 2.0, 3.0, 0.1, -0.2, 0.3));
        // Points on the optical axis at depths 1..=100, plus points behind and out of view.
        let mut means: Vec<[f32; 3]> = (1..=100)
            .map(|d| {
                let p = c2w.act(&Vector3::new(0.0, 0.0, d as f64));
                [p.x as f32, p.y as f32, p.z as f32]
            })
            .collect();
        for far_off in [
            Vector3::new(0.0, 0.0, -5.0),
            Vector3::new(100.0, 0.0, 1.0),
            Vector3::new(0.0, -100.0, 1.0),
        ] {
            let p = c2w.act(&far_off);
            means.push([p.x as f32, p.y as f32, p.z as f32]);
        }
        let [near, median] = blur_depths(&means, &c2w, &k).unwrap();
        assert!((near - 11.0).abs() < 0.01 && (median - 51.0).abs() < 0.01);
        assert_eq!(blur_depths(&means[..5], &c2w, &k), None);
    }
}

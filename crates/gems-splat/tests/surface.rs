//! Surface depth (`Renderer::surface_depth`): the fast path against the f64 reference, and
//! against the analytic depth of a slanted plane that expected depth misses.

mod common;

use common::*;
use gems_math::Intrinsics;
use gems_splat::{Camera, Gaussians, RenderSettings, Renderer, SH_COEFFS, reference};

#[test]
fn fast_surface_depth_matches_the_reference() {
    let (w, h) = (37, 29);
    for seed in [11, 12] {
        let (g, cams, bgs) = random_scene(seed, 300, 2, w, h, 1, (-3.0, -1.6));
        let s = RenderSettings::default();
        let mut r = Renderer::new();
        r.forward(&g, &cams, &bgs, &s).unwrap();
        let fast = r.surface_depth(&g, &cams).unwrap();
        let slow = reference::surface_depth(&g, &cams, &s).unwrap();
        assert_eq!(fast.len(), slow.len());
        let drawn = slow.iter().filter(|&&d| d > 0.0).count();
        assert!(drawn > fast.len() / 4, "{drawn} of {} pixels", fast.len());
        // The f32 and f64 transmittances may cross one half at different Gaussians where a
        // pixel sits on the threshold; everywhere else the two agree to f32 precision.
        let differing = fast
            .iter()
            .zip(&slow)
            .filter(|(f, s)| (f64::from(**f) - **s).abs() > 1e-5 * s.abs().max(1.0))
            .count();
        assert!(
            differing * 200 <= fast.len(),
            "seed {seed}: {differing} of {} pixels differ",
            fast.len()
        );
    }
}

#[test]
fn surface_depth_needs_its_forward() {
    let (g, cams, bgs) = random_scene(5, 20, 2, 16, 16, 0, (-3.0, -2.0));
    let r = Renderer::new();
    assert!(r.surface_depth(&g, &cams).is_err());
    let mut r = Renderer::new();
    r.forward(&g, &cams, &bgs, &RenderSettings::default())
        .unwrap();
    assert!(r.surface_depth(&g, &cams[..1]).is_err());
}

/// Flat, opaque Gaussians tiling the plane `z = 4 + 0.6·x` (a 31° slope), seen by a camera
/// at the origin looking down +z: the plane's depth at pixel `(u, v)` is
/// `4 / (1 − 0.6·(u − cx)/fx)`.
#[test]
fn surface_depth_follows_a_slanted_plane_that_expected_depth_misses() {
    let (w, h) = (64, 48);
    let k = Intrinsics {
        fx: 60.0,
        fy: 60.0,
        cx: 32.0,
        cy: 24.0,
        width: w,
        height: h,
    };
    let cam = Camera::new(&k, &gems_math::Se3::identity());
    let slope = 0.6f64;
    // The plane's normal (−slope, 0, 1) normalised; the quaternion turns +z onto it.
    let half = -(slope.atan()) / 2.0;
    let quat = [half.cos() as f32, 0.0, half.sin() as f32, 0.0];
    let mut g = Gaussians::with_degree(0);
    let spacing = 0.12f64;
    for i in -25..=25 {
        for j in -15..=15 {
            // Along the plane's in-plane axes, x' = (1, 0, slope)/|·| and y.
            let s = f64::from(i) * spacing;
            let norm = (1.0 + slope * slope).sqrt();
            let x = s / norm;
            let y = f64::from(j) * spacing;
            let z = 4.0 + slope * x;
            let mut sh = [[0.0f32; 3]; SH_COEFFS];
            sh[0] = [1.0; 3];
            g.push(
                [x as f32, y as f32, z as f32],
                quat,
                [
                    (spacing * 0.8).ln() as f32,
                    (spacing * 0.8).ln() as f32,
                    -9.0,
                ],
                4.0,
                sh,
            );
        }
    }
    let s = RenderSettings {
        compute_depth: true,
        ..RenderSettings::default()
    };
    let mut r = Renderer::new();
    let out = r.forward(&g, &[cam], &[[0.0; 3]], &s).unwrap();
    let surface = r.surface_depth(&g, &[cam]).unwrap();
    let expected_depth = out.depth.unwrap();
    let mut surface_err = Vec::new();
    let mut expected_err = Vec::new();
    for v in 0..h as usize {
        for u in 0..w as usize {
            let p = v * w as usize + u;
            if out.alpha[p] < 0.99 {
                continue;
            }
            let du = (u as f64 + 0.5 - k.cx) / k.fx;
            let truth = 4.0 / (1.0 - slope * du);
            surface_err.push((f64::from(surface[p]) - truth).abs() / truth);
            expected_err.push((f64::from(expected_depth[p]) - truth).abs() / truth);
        }
    }
    assert!(surface_err.len() > (w * h) as usize / 2);
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let (surface_median, expected_median) = (median(&mut surface_err), median(&mut expected_err));
    assert!(
        surface_median < 1e-5,
        "surface depth is {surface_median} off the plane"
    );
    assert!(
        expected_median > 20.0 * surface_median,
        "expected depth {expected_median}, surface {surface_median}"
    );
}

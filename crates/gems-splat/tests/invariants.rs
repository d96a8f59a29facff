//! Rendering invariants: empty scenes, hidden and transparent Gaussians, thread-count
//! independence, hostile inputs, input validation.

#![allow(clippy::needless_range_loop)]

mod common;

use common::*;
use gems_splat::{Gaussians, RenderSettings, Renderer, SH_COEFFS, SplatError, reference};
use proptest::prelude::*;

fn pool(threads: usize) -> rayon::ThreadPool {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap()
}

#[test]
fn zero_gaussians_render_the_background() {
    let (_, cams, bgs) = random_scene(1, 0, 2, 33, 20, 2, (-3.0, -2.0));
    let g = Gaussians::with_degree(2);
    let mut r = Renderer::new();
    let out = r
        .forward(&g, &cams, &bgs, &RenderSettings::default())
        .unwrap();
    for c in 0..2 {
        for p in 0..33 * 20 {
            let k = c * 33 * 20 + p;
            assert_eq!(out.alpha[k], 0.0);
            assert_eq!(&out.rgb[k * 3..k * 3 + 3], &bgs[c]);
        }
    }
    let d_rgb = vec![0.5f32; out.rgb.len()];
    let gr = r.backward(&g, &cams, &bgs, &d_rgb, None).unwrap();
    for c in 0..2 {
        for ch in 0..3 {
            assert!((gr.backgrounds[c][ch] - 0.5 * 660.0).abs() < 1e-3);
        }
    }
    assert!(
        gr.cam_rotation
            .iter()
            .flatten()
            .flatten()
            .all(|&v| v == 0.0)
    );
}

/// Renders `g` and `g` plus extra Gaussians; the images must be identical and the extras get
/// zero gradients.
fn assert_extras_change_nothing(extras: &Gaussians) {
    let (g, cams, bgs) = random_scene(3, 120, 2, 40, 30, 1, (-3.0, -1.5));
    let mut all = g.clone();
    for i in 0..extras.len() {
        all.push(
            extras.means[i],
            extras.quats[i],
            extras.log_scales[i],
            extras.opacity_logits[i],
            extras.sh[i],
        );
    }
    let s = RenderSettings::default();
    let mut r = Renderer::new();
    let base = r.forward(&g, &cams, &bgs, &s).unwrap();
    let d_rgb: Vec<f32> = random_weights(4, base.rgb.len())
        .iter()
        .map(|&v| v as f32)
        .collect();
    let gb = r.backward(&g, &cams, &bgs, &d_rgb, None).unwrap();
    let with = r.forward(&all, &cams, &bgs, &s).unwrap();
    let gw = r.backward(&all, &cams, &bgs, &d_rgb, None).unwrap();
    assert_eq!(base.rgb, with.rgb);
    assert_eq!(base.alpha, with.alpha);
    let n = g.len();
    assert_eq!(gb.means[..], gw.means[..n]);
    assert_eq!(gb.cam_rotation, gw.cam_rotation);
    for i in n..all.len() {
        assert!(
            gw.means[i]
                .iter()
                .chain(&gw.log_scales[i])
                .all(|&v| v == 0.0)
        );
        assert!(gw.quats[i].iter().all(|&v| v == 0.0));
        assert_eq!(gw.opacity_logits[i], 0.0);
    }
}

fn one(mean: [f32; 3], quat: [f32; 4], ls: [f32; 3], logit: f32, dc: f32) -> Gaussians {
    let mut g = Gaussians::with_degree(1);
    let mut sh = [[0.0; 3]; SH_COEFFS];
    sh[0] = [dc; 3];
    g.push(mean, quat, ls, logit, sh);
    g
}

#[test]
fn gaussian_behind_camera_changes_nothing() {
    // The cameras of random_scene sit at distance 4 from the origin looking at it; a point far
    // behind the first camera is behind every one of them.
    let (_, cams, _) = random_scene(3, 0, 2, 40, 30, 1, (-3.0, -1.5));
    let c = cams[0].center();
    let behind = [c[0] * 3.0, c[1] * 3.0, c[2] * 3.0];
    assert_extras_change_nothing(&one(behind, [1.0, 0.0, 0.0, 0.0], [0.5; 3], 5.0, 2.0));
}

#[test]
fn transparent_gaussian_changes_nothing() {
    assert_extras_change_nothing(&one([0.0; 3], [1.0, 0.2, 0.0, 0.0], [-1.0; 3], -12.0, 2.0));
}

#[test]
fn hostile_values_are_culled_not_propagated() {
    let nan = f32::NAN;
    let inf = f32::INFINITY;
    let mut extras = Gaussians::with_degree(1);
    for g in [
        one([nan, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0], [-1.0; 3], 2.0, 1.0),
        one([0.0, inf, 0.0], [1.0, 0.0, 0.0, 0.0], [-1.0; 3], 2.0, 1.0),
        one([0.0; 3], [0.0; 4], [-1.0; 3], 2.0, 1.0),
        one([0.0; 3], [nan, 0.0, 0.0, 0.0], [-1.0; 3], 2.0, 1.0),
        one([0.0; 3], [1.0, 0.0, 0.0, 0.0], [inf, 0.0, 0.0], 2.0, 1.0),
        one([0.0; 3], [1.0, 0.0, 0.0, 0.0], [200.0, 0.0, 0.0], 2.0, 1.0),
        one([0.0; 3], [1.0, 0.0, 0.0, 0.0], [-1.0; 3], nan, 1.0),
        one([0.0; 3], [1.0, 0.0, 0.0, 0.0], [-1.0; 3], 2.0, nan),
    ] {
        extras.push(
            g.means[0],
            g.quats[0],
            g.log_scales[0],
            g.opacity_logits[0],
            g.sh[0],
        );
    }
    assert_extras_change_nothing(&extras);
}

#[test]
fn results_do_not_depend_on_thread_count() {
    let (g, cams, bgs) = random_scene(9, 2000, 3, 96, 64, 3, (-3.5, -2.0));
    let s = RenderSettings {
        compute_depth: true,
        ..Default::default()
    };
    let d_rgb: Vec<f32> = random_weights(10, 3 * 96 * 64 * 3)
        .iter()
        .map(|&v| v as f32)
        .collect();
    let d_a: Vec<f32> = random_weights(11, 3 * 96 * 64)
        .iter()
        .map(|&v| v as f32)
        .collect();
    let run = |threads: usize| {
        pool(threads).install(|| {
            let mut r = Renderer::new();
            let out = r.forward(&g, &cams, &bgs, &s).unwrap();
            let gr = r.backward(&g, &cams, &bgs, &d_rgb, Some(&d_a)).unwrap();
            (out, gr)
        })
    };
    let (o1, g1) = run(1);
    let (o2, g2) = run(2);
    let (o3, g3) = run(3);
    assert_eq!(o1, o2);
    assert_eq!(o1, o3);
    assert_eq!(g1, g2);
    assert_eq!(g1, g3);
    assert!(
        o1.alpha.iter().any(|&a| a > 0.5),
        "the scene should cover the image"
    );
}

/// A camera given no upstream gradient is skipped by the backward (the trainer's stochastic
/// backward through a subset of virtual views saves its time that way): the batch's gradients
/// must equal those of the batch without it, and its own pose gradient must be zero.
#[test]
fn a_camera_without_upstream_gradient_adds_nothing() {
    let (w, h) = (64u32, 48u32);
    let (g, cams, bgs) = random_scene(21, 1500, 3, w, h, 3, (-3.5, -2.0));
    let s = RenderSettings::default();
    let px = (w * h) as usize;
    let d_rgb: Vec<f32> = random_weights(22, 3 * px * 3)
        .iter()
        .map(|&v| v as f32)
        .collect();
    // Camera 1's gradient zeroed in the batch of three ...
    let mut d_masked = d_rgb.clone();
    d_masked[px * 3..2 * px * 3].fill(0.0);
    let mut r = Renderer::new();
    r.forward(&g, &cams, &bgs, &s).unwrap();
    let masked = r.backward(&g, &cams, &bgs, &d_masked, None).unwrap();
    // ... against the batch of cameras 0 and 2 alone.
    let (cams2, bgs2) = (vec![cams[0], cams[2]], vec![bgs[0], bgs[2]]);
    let mut d_pair = d_rgb[..px * 3].to_vec();
    d_pair.extend_from_slice(&d_rgb[2 * px * 3..]);
    r.forward(&g, &cams2, &bgs2, &s).unwrap();
    let pair = r.backward(&g, &cams2, &bgs2, &d_pair, None).unwrap();

    let bits3 = |v: &[[f32; 3]]| v.iter().flatten().map(|x| x.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits3(&masked.means), bits3(&pair.means));
    assert_eq!(bits3(&masked.log_scales), bits3(&pair.log_scales));
    assert_eq!(masked.quats, pair.quats);
    assert_eq!(masked.opacity_logits, pair.opacity_logits);
    assert_eq!(masked.sh, pair.sh);
    assert_eq!(masked.cam_rotation[0], pair.cam_rotation[0]);
    assert_eq!(masked.cam_rotation[2], pair.cam_rotation[1]);
    assert_eq!(masked.cam_translation[2], pair.cam_translation[1]);
    assert_eq!(masked.cam_rotation[1], [[0.0; 3]; 3]);
    assert_eq!(masked.cam_translation[1], [0.0; 3]);
    assert_eq!(masked.backgrounds[1], [0.0; 3]);
    assert!(
        masked.means.iter().flatten().any(|&v| v != 0.0),
        "the other cameras should give gradients"
    );
}

#[test]
fn renderer_reuse_gives_identical_results() {
    let (g, cams, bgs) = random_scene(12, 300, 2, 50, 40, 2, (-3.0, -2.0));
    let (g2, cams2, bgs2) = random_scene(13, 500, 3, 37, 21, 3, (-3.0, -1.0));
    let s = RenderSettings::default();
    let mut r = Renderer::new();
    let a = r.forward(&g, &cams, &bgs, &s).unwrap();
    r.forward(&g2, &cams2, &bgs2, &s).unwrap();
    let b = r.forward(&g, &cams, &bgs, &s).unwrap();
    assert_eq!(a, b);
}

#[test]
fn bad_inputs_give_clear_errors() {
    let (g, cams, bgs) = random_scene(14, 10, 2, 20, 10, 1, (-3.0, -2.0));
    let s = RenderSettings::default();
    let mut r = Renderer::new();
    // Backward before any forward.
    let e = r
        .backward(&g, &cams, &bgs, &vec![0.0; 2 * 200 * 3], None)
        .unwrap_err();
    assert!(matches!(e, SplatError::NoForward(_)), "{e}");
    let mut bad = g.clone();
    bad.quats.pop();
    let e = r.forward(&bad, &cams, &bgs, &s).unwrap_err();
    assert!(e.to_string().contains("quats"), "{e}");
    let mut bad = g.clone();
    bad.sh_degree = 4;
    assert!(r.forward(&bad, &cams, &bgs, &s).is_err());
    let mut bad_cams = cams.clone();
    bad_cams[1].fx = f32::NAN;
    let e = r.forward(&g, &bad_cams, &bgs, &s).unwrap_err();
    assert!(
        matches!(e, SplatError::InvalidCamera { index: 1, .. }),
        "{e}"
    );
    let mut bad_cams = cams.clone();
    bad_cams[1].width = 21;
    assert!(matches!(
        r.forward(&g, &bad_cams, &bgs, &s),
        Err(SplatError::Shape(_))
    ));
    assert!(r.forward(&g, &cams, &bgs[..1], &s).is_err());
    assert!(r.forward(&g, &[], &[], &s).is_err());
    let mut bad_cams = cams.clone();
    bad_cams[0].rotation[0][0] = f32::INFINITY;
    assert!(r.forward(&g, &bad_cams, &bgs, &s).is_err());
    r.forward(&g, &cams, &bgs, &s).unwrap();
    let e = r.backward(&g, &cams, &bgs, &[0.0; 7], None).unwrap_err();
    assert!(e.to_string().contains("d_rgb"), "{e}");
    let e = r
        .backward(&g, &cams, &bgs, &vec![0.0; 1200], Some(&[0.0; 3]))
        .unwrap_err();
    assert!(e.to_string().contains("d_alpha"), "{e}");
    let e = r
        .backward(&g, &cams[..1], &bgs[..1], &vec![0.0; 600], None)
        .unwrap_err();
    assert!(matches!(e, SplatError::NoForward(_)), "{e}");
    assert!(reference::forward(&bad, &cams, &bgs, &s).is_err());
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 24, ..ProptestConfig::default() })]

    /// Any finite scene renders to finite images with alpha in [0, 1] and colour at least
    /// min(0, background), and finite gradients.
    #[test]
    fn outputs_are_finite_and_bounded(seed in 0u64..10_000, n in 0usize..80, lo in -6.0f32..-1.0) {
        let (g, cams, bgs) = random_scene(seed, n, 2, 29, 17, 3, (lo, lo + 1.5));
        let mut r = Renderer::new();
        let s = RenderSettings { antialiased: seed % 2 == 0, compute_depth: true, ..Default::default() };
        let out = r.forward(&g, &cams, &bgs, &s).unwrap();
        prop_assert!(out.alpha.iter().all(|a| (0.0..=1.0).contains(a)));
        prop_assert!(out.rgb.iter().all(|v| v.is_finite() && *v >= 0.0));
        prop_assert!(out.depth.as_ref().unwrap().iter().all(|v| v.is_finite() && *v >= 0.0));
        let d_rgb = vec![1.0f32; out.rgb.len()];
        let gr = r.backward(&g, &cams, &bgs, &d_rgb, None).unwrap();
        prop_assert!(gr.means.iter().flatten().all(|v| v.is_finite()));
        prop_assert!(gr.quats.iter().flatten().all(|v| v.is_finite()));
        prop_assert!(gr.cam_rotation.iter().flatten().flatten().all(|v| v.is_finite()));
    }
}

#[test]
fn look_at_centres_the_target_and_keeps_up_up() {
    let cam = gems_splat::Camera::look_at(
        &gems_math::Intrinsics {
            fx: 100.0,
            fy: 100.0,
            cx: 40.0,
            cy: 30.0,
            width: 80,
            height: 60,
        },
        [1.0, -2.0, -3.0],
        [0.2, 0.1, 0.3],
        [0.0, -1.0, 0.0],
    )
    .unwrap();
    let project = |p: [f32; 3]| {
        let r = cam.rotation;
        let pc: Vec<f32> = (0..3)
            .map(|i| r[i][0] * p[0] + r[i][1] * p[1] + r[i][2] * p[2] + cam.translation[i])
            .collect();
        (
            cam.fx * pc[0] / pc[2] + cam.cx,
            cam.fy * pc[1] / pc[2] + cam.cy,
            pc[2],
        )
    };
    let (u, v, z) = project([0.2, 0.1, 0.3]);
    assert!((u - 40.0).abs() < 1e-3 && (v - 30.0).abs() < 1e-3 && z > 0.0);
    // A point displaced along "up" appears higher (smaller v).
    let (_, v_up, _) = project([0.2, 0.0, 0.3]);
    assert!(v_up < v);
    let c = cam.center();
    assert!((c[0] - 1.0).abs() < 1e-5 && (c[1] + 2.0).abs() < 1e-5 && (c[2] + 3.0).abs() < 1e-5);
    assert!(
        gems_splat::Camera::look_at(
            &gems_math::Intrinsics {
                fx: 1.0,
                fy: 1.0,
                cx: 0.0,
                cy: 0.0,
                width: 4,
                height: 4,
            },
            [0.0; 3],
            [0.0; 3],
            [0.0, 1.0, 0.0]
        )
        .is_none()
    );
}

#[test]
fn png_matches_the_render() {
    let (g, cams, bgs) = random_scene(21, 200, 2, 31, 23, 2, (-3.0, -2.0));
    let mut r = Renderer::new();
    let out = r
        .forward(&g, &cams, &bgs, &RenderSettings::default())
        .unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("view.png");
    gems_splat::write_png(&path, &out, 1).unwrap();
    let img = image::open(&path).unwrap().to_rgb8();
    assert_eq!(img.dimensions(), (31, 23));
    for (x, y, p) in img.enumerate_pixels() {
        for ch in 0..3 {
            let k = ((23 + y as usize) * 31 + x as usize) * 3 + ch;
            let want = (out.rgb[k].clamp(0.0, 1.0) * 255.0).round() as u8;
            assert_eq!(p[ch], want);
        }
    }
    assert!(gems_splat::write_png(dir.path().join("x.png"), &out, 2).is_err());
}

//! Central finite differences on the f64 reference path for every parameter, the camera pose
//! included (rotation perturbed through the exponential map), in classic and antialiased mode;
//! and the fast path against the reference on random scenes.

#![allow(clippy::needless_range_loop)]

mod common;

use common::*;
use gems_splat::{Camera, Gaussians, RenderSettings, Renderer, reference};

/// Settings without the discontinuous cut-offs (α ≥ 1/255, T > 1e-4, α ≤ 0.999) so that the
/// loss is smooth and central differences converge; the gradient code paths are the same.
fn smooth(antialiased: bool) -> RenderSettings {
    RenderSettings {
        antialiased,
        alpha_min: 0.0,
        transmittance_min: 0.0,
        alpha_max: 1.0,
        ..Default::default()
    }
}

struct Loss {
    w_rgb: Vec<f64>,
    w_alpha: Vec<f64>,
    bgs: Vec<[f32; 3]>,
    s: RenderSettings,
}

impl Loss {
    fn eval(&self, g: &Gaussians, cams: &[Camera]) -> f64 {
        let out = reference::forward(g, cams, &self.bgs, &self.s).unwrap();
        dot(&out.rgb, &self.w_rgb) + dot(&out.alpha, &self.w_alpha)
    }
}

/// Central difference of the loss along a change of one f32 parameter. The step actually
/// taken (after rounding to f32) is used, so the quotient is exact to second order.
fn fd<F: Fn(&mut Gaussians, &mut Vec<Camera>, f32)>(
    loss: &Loss,
    g: &Gaussians,
    cams: &[Camera],
    get: f32,
    h: f32,
    set: F,
) -> f64 {
    let (mut gp, mut cp) = (g.clone(), cams.to_vec());
    let (mut gm, mut cm) = (g.clone(), cams.to_vec());
    let plus = get + h;
    let minus = get - h;
    set(&mut gp, &mut cp, plus);
    set(&mut gm, &mut cm, minus);
    (loss.eval(&gp, &cp) - loss.eval(&gm, &cm)) / (plus as f64 - minus as f64)
}

fn check(what: &str, fd: f64, an: f64, scale: f64) {
    let tol = 2e-3 * an.abs() + 1e-4 * scale;
    assert!(
        (fd - an).abs() <= tol,
        "{what}: finite difference {fd} vs analytic {an} (scale {scale})"
    );
}

fn rot_axis(k: usize, theta: f64) -> [[f64; 3]; 3] {
    let (s, c) = theta.sin_cos();
    match k {
        0 => [[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]],
        1 => [[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]],
        _ => [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]],
    }
}

fn run_fd(antialiased: bool, seed: u64) {
    let (w, h) = (24, 18);
    let (g, cams, bgs) = random_scene(seed, 7, 2, w, h, 3, (-2.2, -1.2));
    let npix = cams.len() * (w * h) as usize;
    let loss = Loss {
        w_rgb: random_weights(seed + 1, npix * 3),
        w_alpha: random_weights(seed + 2, npix),
        bgs,
        s: smooth(antialiased),
    };
    let gr = reference::backward(
        &g,
        &cams,
        &loss.bgs,
        &loss.s,
        &loss.w_rgb,
        Some(&loss.w_alpha),
    )
    .unwrap();
    assert!(
        gr.visible_count.iter().all(|&v| v > 0),
        "every Gaussian should be visible"
    );
    let scale_of = |v: &[f64]| v.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    let h_of = |x: f32| 1e-3 * x.abs().max(0.3);

    let s_means = scale_of(&flat3(&gr.means));
    let s_quats = scale_of(&flat4(&gr.quats));
    let s_ls = scale_of(&flat3(&gr.log_scales));
    let s_op = scale_of(&gr.opacity_logits);
    let s_sh = scale_of(&flat_sh(&gr.sh));
    for i in 0..g.len() {
        for k in 0..3 {
            let x = g.means[i][k];
            let d = fd(&loss, &g, &cams, x, h_of(x), |g, _, v| g.means[i][k] = v);
            check(&format!("mean[{i}][{k}]"), d, gr.means[i][k], s_means);
            let x = g.log_scales[i][k];
            let d = fd(&loss, &g, &cams, x, h_of(x), |g, _, v| {
                g.log_scales[i][k] = v;
            });
            check(
                &format!("log_scale[{i}][{k}]"),
                d,
                gr.log_scales[i][k],
                s_ls,
            );
        }
        for k in 0..4 {
            let x = g.quats[i][k];
            let d = fd(&loss, &g, &cams, x, h_of(x), |g, _, v| g.quats[i][k] = v);
            check(&format!("quat[{i}][{k}]"), d, gr.quats[i][k], s_quats);
        }
        let x = g.opacity_logits[i];
        let d = fd(&loss, &g, &cams, x, h_of(x), |g, _, v| {
            g.opacity_logits[i] = v;
        });
        check(&format!("opacity[{i}]"), d, gr.opacity_logits[i], s_op);
        for k in 0..16 {
            for ch in 0..3 {
                let x = g.sh[i][k][ch];
                let d = fd(&loss, &g, &cams, x, h_of(x), |g, _, v| g.sh[i][k][ch] = v);
                check(&format!("sh[{i}][{k}][{ch}]"), d, gr.sh[i][k][ch], s_sh);
            }
        }
    }
    // Backgrounds: the loss is linear in them.
    for c in 0..cams.len() {
        for ch in 0..3 {
            let mut lp = clone_loss(&loss);
            let mut lm = clone_loss(&loss);
            lp.bgs[c][ch] += 0.25;
            lm.bgs[c][ch] -= 0.25;
            let d = (lp.eval(&g, &cams) - lm.eval(&g, &cams)) / 0.5;
            check(
                &format!("background[{c}][{ch}]"),
                d,
                gr.backgrounds[c][ch],
                1.0,
            );
        }
    }
    // Pose: translation directly, rotation along exp(θ[e_k]×)·R; the predicted change uses the
    // f32-rounded perturbed matrices actually rendered.
    let s_t = scale_of(&flat3(&gr.cam_translation));
    for c in 0..cams.len() {
        for k in 0..3 {
            let x = cams[c].translation[k];
            let d = fd(&loss, &g, &cams, x, 1e-3, |_, cs, v| {
                cs[c].translation[k] = v;
            });
            check(
                &format!("cam t[{c}][{k}]"),
                d,
                gr.cam_translation[c][k],
                s_t,
            );
        }
        let s_f = scale_of(&gr.cam_focal.concat());
        for k in 0..2 {
            let x = if k == 0 { cams[c].fx } else { cams[c].fy };
            let d = fd(&loss, &g, &cams, x, h_of(x), |_, cs, v| {
                *(if k == 0 { &mut cs[c].fx } else { &mut cs[c].fy }) = v;
            });
            check(&format!("cam focal[{c}][{k}]"), d, gr.cam_focal[c][k], s_f);
        }
        let r0: [[f64; 3]; 3] = cams[c].rotation.map(|r| r.map(f64::from));
        let mut s_r = 0.0f64;
        let mut results = Vec::new();
        for k in 0..3 {
            // Small enough not to cross a box-culling edge; the linearisation uses the f32
            // matrices actually rendered, so rounding does not limit the step.
            let theta = 2e-4;
            let perturbed = |sign: f64| -> [[f32; 3]; 3] {
                let e = rot_axis(k, sign * theta);
                [0, 1, 2].map(|i| {
                    [0, 1, 2].map(|j| (0..3).map(|m| e[i][m] * r0[m][j]).sum::<f64>() as f32)
                })
            };
            let (rp, rm) = (perturbed(1.0), perturbed(-1.0));
            let mut cp = cams.clone();
            let mut cm = cams.clone();
            cp[c].rotation = rp;
            cm[c].rotation = rm;
            let measured = loss.eval(&g, &cp) - loss.eval(&g, &cm);
            let mut predicted = 0.0;
            for i in 0..3 {
                for j in 0..3 {
                    predicted += gr.cam_rotation[c][i][j] * (rp[i][j] as f64 - rm[i][j] as f64);
                }
            }
            s_r = s_r.max(predicted.abs() / (2.0 * theta));
            results.push((k, measured / (2.0 * theta), predicted / (2.0 * theta)));
        }
        for (k, m, p) in results {
            check(&format!("cam R[{c}] axis {k}"), m, p, s_r);
        }
    }
}

fn clone_loss(l: &Loss) -> Loss {
    Loss {
        w_rgb: l.w_rgb.clone(),
        w_alpha: l.w_alpha.clone(),
        bgs: l.bgs.clone(),
        s: l.s,
    }
}

#[test]
fn finite_differences_classic() {
    run_fd(false, 11);
}

#[test]
fn finite_differences_antialiased() {
    run_fd(true, 23);
}

#[test]
fn fast_matches_reference_on_random_scenes() {
    let mut r = Renderer::new();
    for (seed, antialiased, depth) in [(5u64, false, true), (6, true, false), (7, false, false)] {
        let (w, h) = (70, 45);
        let (g, cams, bgs) = random_scene(seed, 250, 3, w, h, 3, (-3.5, -1.8));
        let s = RenderSettings {
            antialiased,
            compute_depth: depth,
            ..Default::default()
        };
        let fast = r.forward(&g, &cams, &bgs, &s).unwrap();
        let refo = reference::forward(&g, &cams, &bgs, &s).unwrap();
        assert_eq!(fast.radii, refo.radii);
        let f64v = |v: &[f32]| v.iter().map(|&x| x as f64).collect::<Vec<_>>();
        assert_close("rgb", &f64v(&fast.rgb), &refo.rgb, 0.0, 1e-4);
        assert_close("alpha", &f64v(&fast.alpha), &refo.alpha, 0.0, 1e-4);
        if depth {
            assert_close(
                "depth",
                &f64v(fast.depth.as_ref().unwrap()),
                &refo.depth,
                1e-4,
                1e-4,
            );
        } else {
            assert!(fast.depth.is_none());
        }
        let npix = cams.len() * (w * h) as usize;
        let w_rgb = random_weights(seed + 10, npix * 3);
        let w_a = random_weights(seed + 11, npix);
        let gf = r
            .backward(&g, &cams, &bgs, &f32v(&w_rgb), Some(&f32v(&w_a)))
            .unwrap();
        let gr = reference::backward(&g, &cams, &bgs, &s, &w_rgb, Some(&w_a)).unwrap();
        assert_grad_close("means", &flat3(&gf.means), &flat3(&gr.means));
        assert_grad_close("quats", &flat4(&gf.quats), &flat4(&gr.quats));
        assert_grad_close("log_scales", &flat3(&gf.log_scales), &flat3(&gr.log_scales));
        assert_grad_close("opacity", &f64v(&gf.opacity_logits), &gr.opacity_logits);
        assert_grad_close("sh", &flat_sh(&gf.sh), &flat_sh(&gr.sh));
        assert_grad_close(
            "backgrounds",
            &flat3(&gf.backgrounds),
            &flat3(&gr.backgrounds),
        );
        let rf: Vec<f64> = gf
            .cam_rotation
            .iter()
            .flatten()
            .flatten()
            .map(|&v| v as f64)
            .collect();
        let rr: Vec<f64> = gr
            .cam_rotation
            .iter()
            .flatten()
            .flatten()
            .copied()
            .collect();
        assert_grad_close("cam R", &rf, &rr);
        assert_grad_close(
            "cam t",
            &flat3(&gf.cam_translation),
            &flat3(&gr.cam_translation),
        );
        let focal = |v: &[[f32; 2]]| v.iter().flatten().map(|&x| x as f64).collect::<Vec<_>>();
        assert_grad_close("cam focal", &focal(&gf.cam_focal), &gr.cam_focal.concat());
        assert_grad_close(
            "mean2d norm",
            &f64v(&gf.mean2d_grad_norm),
            &gr.mean2d_grad_norm,
        );
        assert_eq!(gf.visible_count, gr.visible_count);
        // Densification statistics: visible_count counts the cameras with a non-zero radius.
        let n = g.len();
        for i in 0..n {
            let vis = (0..cams.len())
                .filter(|&c| fast.radii[c * n + i][0] > 0)
                .count() as u32;
            assert_eq!(gf.visible_count[i], vis);
        }
    }
}

fn f32v(v: &[f64]) -> Vec<f32> {
    v.iter().map(|&x| x as f32).collect()
}

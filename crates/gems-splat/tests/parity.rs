//! Parity with gsplat 1.5.3 (f64 reference vectors in testdata/splat): forward outputs,
//! radii/culling and every gradient, for the fast renderer and the f64 reference.

#![allow(clippy::needless_range_loop)]

mod common;

use common::*;
use gems_splat::{RenderSettings, Renderer, reference};

const CASES: [&str; 4] = ["tiny", "basic", "dense", "culling"];

fn check_projection(case: &Case, out: &reference::ReferenceOutput) {
    let radii: Vec<f64> = out.radii.iter().flat_map(|r| r.map(f64::from)).collect();
    assert_close(
        &format!("{} radii", case.name),
        &radii,
        case.get("out_radii"),
        0.0,
        0.0,
    );
    // Compare screen-space quantities only where gsplat did not cull.
    let n = out.radii.len();
    let keep: Vec<bool> = (0..n).map(|k| case.get("out_radii")[2 * k] > 0.0).collect();
    let pick = |v: Vec<f64>, d: usize| -> Vec<f64> {
        v.chunks(d)
            .zip(&keep)
            .filter(|(_, k)| **k)
            .flat_map(|(c, _)| c.to_vec())
            .collect()
    };
    let m2d = pick(out.means2d.iter().flatten().copied().collect(), 2);
    let conics = pick(out.conics.iter().flatten().copied().collect(), 3);
    let depths = pick(out.depths.clone(), 1);
    let e_m2d = pick(case.get("out_means2d").to_vec(), 2);
    let e_conics = pick(case.get("out_conics").to_vec(), 3);
    let e_depths = pick(case.get("out_depths").to_vec(), 1);
    assert_close(&format!("{} means2d", case.name), &m2d, &e_m2d, 1e-4, 1e-6);
    assert_close(
        &format!("{} depths", case.name),
        &depths,
        &e_depths,
        1e-4,
        1e-6,
    );
    let cmax = e_conics.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    assert_close(
        &format!("{} conics", case.name),
        &conics,
        &e_conics,
        1e-4,
        1e-6 * cmax,
    );
}

#[test]
fn reference_matches_gsplat_forward_and_gradients() {
    for name in CASES {
        let case = Case::load(name);
        let (g, cams, bgs) = (case.gaussians(), case.cameras(), case.backgrounds());
        let s = RenderSettings::default();
        let out = reference::forward(&g, &cams, &bgs, &s).unwrap();
        check_projection(&case, &out);
        assert_close(
            &format!("{name} colors"),
            &out.rgb,
            case.get("out_colors"),
            0.0,
            1e-4,
        );
        assert_close(
            &format!("{name} alphas"),
            &out.alpha,
            case.get("out_alphas"),
            0.0,
            1e-4,
        );
        let gr = reference::backward(
            &g,
            &cams,
            &bgs,
            &s,
            case.get("loss_weight_colors"),
            Some(case.get("loss_weight_alphas")),
        )
        .unwrap();
        check_grads(&case, GradView::from_ref(&gr));
    }
}

#[test]
fn fast_renderer_matches_gsplat_forward_and_gradients() {
    let mut r = Renderer::new();
    for name in CASES {
        let case = Case::load(name);
        let (g, cams, bgs) = (case.gaussians(), case.cameras(), case.backgrounds());
        let s = RenderSettings::default();
        let out = r.forward(&g, &cams, &bgs, &s).unwrap();
        let radii: Vec<f64> = out.radii.iter().flat_map(|r| r.map(f64::from)).collect();
        assert_close(
            &format!("{name} radii"),
            &radii,
            case.get("out_radii"),
            0.0,
            0.0,
        );
        let rgb: Vec<f64> = out.rgb.iter().map(|&v| v as f64).collect();
        let alpha: Vec<f64> = out.alpha.iter().map(|&v| v as f64).collect();
        assert_close(
            &format!("{name} colors"),
            &rgb,
            case.get("out_colors"),
            0.0,
            1e-4,
        );
        assert_close(
            &format!("{name} alphas"),
            &alpha,
            case.get("out_alphas"),
            0.0,
            1e-4,
        );
        let d_rgb: Vec<f32> = case
            .get("loss_weight_colors")
            .iter()
            .map(|&v| v as f32)
            .collect();
        let d_a: Vec<f32> = case
            .get("loss_weight_alphas")
            .iter()
            .map(|&v| v as f32)
            .collect();
        let gr = r.backward(&g, &cams, &bgs, &d_rgb, Some(&d_a)).unwrap();
        check_grads(&case, GradView::from_fast(&gr));
    }
}

struct GradView {
    means: Vec<f64>,
    quats: Vec<f64>,
    log_scales: Vec<f64>,
    opacity_logits: Vec<f64>,
    sh: Vec<f64>,
    rot: Vec<f64>,
    trans: Vec<f64>,
}

impl GradView {
    fn from_ref(g: &reference::ReferenceGradients) -> Self {
        GradView {
            means: flat3(&g.means),
            quats: flat4(&g.quats),
            log_scales: flat3(&g.log_scales),
            opacity_logits: g.opacity_logits.clone(),
            sh: flat_sh(&g.sh),
            rot: g.cam_rotation.iter().flatten().flatten().copied().collect(),
            trans: flat3(&g.cam_translation),
        }
    }
    fn from_fast(g: &gems_splat::Gradients) -> Self {
        GradView {
            means: flat3(&g.means),
            quats: flat4(&g.quats),
            log_scales: flat3(&g.log_scales),
            opacity_logits: g.opacity_logits.iter().map(|&v| v as f64).collect(),
            sh: flat_sh(&g.sh),
            rot: g
                .cam_rotation
                .iter()
                .flatten()
                .flatten()
                .map(|&v| v as f64)
                .collect(),
            trans: flat3(&g.cam_translation),
        }
    }
}

fn check_grads(case: &Case, g: GradView) {
    let n = &case.name;
    assert_grad_close(&format!("{n} grad means"), &g.means, case.get("grad_means"));
    assert_grad_close(&format!("{n} grad quats"), &g.quats, case.get("grad_quats"));
    assert_grad_close(
        &format!("{n} grad log_scales"),
        &g.log_scales,
        case.get("grad_log_scales"),
    );
    assert_grad_close(
        &format!("{n} grad opacity"),
        &g.opacity_logits,
        case.get("grad_opacity_logits"),
    );
    assert_grad_close(&format!("{n} grad sh"), &g.sh, case.get("grad_sh_coeffs"));
    let (er, et) = split_viewmat_grad(case.get("grad_viewmats"));
    assert_grad_close(&format!("{n} grad R"), &g.rot, &er);
    assert_grad_close(&format!("{n} grad t"), &g.trans, &et);
}

//! A first training's Gaussians carried over into a second training of the same views whose
//! initial poses come from another model (the SfM on the first training's renders).
//!
//! Why: the run proper after `init.sfm_rerun_fraction` otherwise starts again from the second
//! model's sparse points, so the appearance the first pass learnt is thrown away, and its initial
//! points carry the tracks' errors (BENCHMARKS.md, "The held-out gap"). The first pass's
//! Gaussians are what rendered the images the second model was made from, so each one's
//! projections into the first pass's cameras are where the second model's cameras should see it:
//! triangulated with those cameras they give its place in the second model's frame, including
//! the part of the change between the two models that no single similarity captures.
//!
//! Per Gaussian, with the first pass's trained mid-exposure cameras and the second training's
//! initial cameras paired by view name:
//! 1. the similarity between the two camera sets ([`gems_math::camera_similarity`]) maps its mean,
//!    scales, rotation and SH bands into the new frame: the prediction X₀;
//! 2. its mean is then the MAP point under the reprojection error to its projections x_v in the
//!    old cameras (views where it projects inside the image, σ = 1 px) and a Gaussian prior
//!    around X₀ (σ = 5 % of X₀'s mean depth in the new cameras), which keeps points seen with
//!    little parallax, or in fewer than two views, at X₀ (Gauss–Newton, a few steps).

use gems_math::{Intrinsics, Matrix3, Se3, Sim3, Vector3, camera_similarity};
use gems_splat::Gaussians;

use crate::TrainError;
use crate::normalize::Normalization;
use crate::output::TrainOutput;
use crate::trainer::TrainView;

/// Reprojection σ of the old projections, in pixels.
const REPROJECTION_SIGMA_PX: f64 = 1.0;
/// Prior σ around the similarity's prediction, as a fraction of its mean depth in the cameras
/// that see it.
const PRIOR_SIGMA_DEPTH: f64 = 0.05;
/// Gauss–Newton steps (the problem is three-dimensional and starts near its optimum).
const GAUSS_NEWTON_STEPS: usize = 5;
/// Nearest depth (normalised units) at which a camera is taken to see a point.
const MIN_DEPTH: f64 = 1e-6;

/// One view in both trainings: the old camera (first training, trained mid-exposure pose) and
/// the new one (second training, initial pose), as world-to-camera transforms.
struct ViewPair {
    old_w2c: Se3,
    old_k: Intrinsics,
    new_w2c: Se3,
    new_k: Intrinsics,
}

/// Pixel of camera point `p` (OpenCV pinhole), `None` behind the camera.
fn pixel(k: &Intrinsics, p: &Vector3<f64>) -> Option<[f64; 2]> {
    (p.z > MIN_DEPTH).then(|| [k.fx * p.x / p.z + k.cx, k.fy * p.y / p.z + k.cy])
}

fn inside(k: &Intrinsics, [u, v]: [f64; 2]) -> bool {
    (0.0..f64::from(k.width)).contains(&u) && (0.0..f64::from(k.height)).contains(&v)
}

/// The `keep` most opaque of `first`'s Gaussians (all when it has no more), carried into the
/// frame of `views` (the second training's views, normalised frame, initial poses), as the
/// module documentation says. Views are paired by name; the first training's other views and
/// the second's views it did not train on are not used.
///
/// Errors when fewer than two views are shared or their centres coincide (no similarity).
pub fn carry_over_gaussians(
    first: &TrainOutput,
    views: &[TrainView],
    keep: usize,
) -> Result<Gaussians, TrainError> {
    let pairs: Vec<ViewPair> = first
        .views
        .iter()
        .filter_map(|old| {
            let new = views.iter().find(|v| v.name == old.name)?;
            Some(ViewPair {
                old_w2c: Se3::from(&old.mid_c2w).inverse(),
                old_k: old.intrinsics,
                new_w2c: new.c2w_init.inverse(),
                new_k: new.intrinsics,
            })
        })
        .collect();
    let cameras: Vec<(Se3, Se3)> = pairs
        .iter()
        .map(|p| (p.old_w2c.inverse(), p.new_w2c.inverse()))
        .collect();
    let sim = camera_similarity(&cameras).ok_or_else(|| {
        TrainError::Input(format!(
            "cannot carry the Gaussians over: {} views shared with the first training, at \
             least two with distinct centres needed",
            pairs.len()
        ))
    })?;
    let g = &first.gaussians;
    let mut order: Vec<usize> = (0..g.len()).collect();
    order.sort_by(|&a, &b| g.opacity_logits[b].total_cmp(&g.opacity_logits[a]));
    order.truncate(keep);
    order.sort_unstable();
    let kept = select(g, &order);
    let mut out = similarity_as_normalization(&sim).gaussians_to_input_frame(&kept);
    let mut shifts = Vec::with_capacity(out.len());
    for (mean, old) in out.means.iter_mut().zip(&kept.means) {
        let old = Vector3::new(f64::from(old[0]), f64::from(old[1]), f64::from(old[2]));
        let predicted = Vector3::new(f64::from(mean[0]), f64::from(mean[1]), f64::from(mean[2]));
        let x = triangulate(&pairs, &old, predicted);
        shifts.push((x - predicted).norm());
        *mean = [x.x as f32, x.y as f32, x.z as f32];
    }
    shifts.sort_by(f64::total_cmp);
    tracing::info!(
        gaussians = out.len(),
        of = g.len(),
        views = pairs.len(),
        similarity_scale = sim.scale,
        median_shift_from_similarity = shifts.get(shifts.len() / 2).copied().unwrap_or(0.0),
        "carried the first pass's Gaussians over"
    );
    Ok(out)
}

/// Gaussians `indices` of `g`, in that order.
fn select(g: &Gaussians, indices: &[usize]) -> Gaussians {
    Gaussians {
        means: indices.iter().map(|&i| g.means[i]).collect(),
        quats: indices.iter().map(|&i| g.quats[i]).collect(),
        log_scales: indices.iter().map(|&i| g.log_scales[i]).collect(),
        opacity_logits: indices.iter().map(|&i| g.opacity_logits[i]).collect(),
        sh: indices.iter().map(|&i| g.sh[i]).collect(),
        sh_degree: g.sh_degree,
    }
}

/// The [`Normalization`] whose inverse is `sim` (x ↦ Rᵀx/s + c with R = sim.rotᵀ, s = 1/scale,
/// c = sim.trans), so that [`Normalization::gaussians_to_input_frame`] applies `sim` to means,
/// scales, rotations and SH bands.
fn similarity_as_normalization(sim: &Sim3) -> Normalization {
    let r: Matrix3<f64> = sim.rot.transpose();
    Normalization {
        rotation: std::array::from_fn(|i| std::array::from_fn(|j| r[(i, j)])),
        center: sim.trans.into(),
        scale: 1.0 / sim.scale,
    }
}

/// The MAP position of a point at `old` in the old cameras, seen from the new ones, with the
/// prior around `predicted` (module documentation). Returns `predicted` when the point is seen
/// by no old camera, or when a step would put it behind a new camera that sees it.
fn triangulate(pairs: &[ViewPair], old: &Vector3<f64>, predicted: Vector3<f64>) -> Vector3<f64> {
    let seen: Vec<(&ViewPair, [f64; 2])> = pairs
        .iter()
        .filter_map(|p| {
            let x = pixel(&p.old_k, &p.old_w2c.act(old)).filter(|x| inside(&p.old_k, *x))?;
            (p.new_w2c.act(&predicted).z > MIN_DEPTH).then_some((p, x))
        })
        .collect();
    if seen.is_empty() {
        return predicted;
    }
    let depth = seen
        .iter()
        .map(|(p, _)| p.new_w2c.act(&predicted).z)
        .sum::<f64>()
        / seen.len() as f64;
    let w_prior = 1.0 / (PRIOR_SIGMA_DEPTH * depth).powi(2);
    let w_obs = 1.0 / REPROJECTION_SIGMA_PX.powi(2);
    let mut x = predicted;
    for _ in 0..GAUSS_NEWTON_STEPS {
        let mut h = Matrix3::identity() * w_prior;
        let mut b = (x - predicted) * w_prior;
        for (p, target) in &seen {
            let c = p.new_w2c.act(&x);
            if c.z <= MIN_DEPTH {
                return predicted;
            }
            let k = &p.new_k;
            let r = [
                k.fx * c.x / c.z + k.cx - target[0],
                k.fy * c.y / c.z + k.cy - target[1],
            ];
            // d(pixel)/d(camera point), then through the rotation to the world point.
            let du = Vector3::new(k.fx / c.z, 0.0, -k.fx * c.x / (c.z * c.z));
            let dv = Vector3::new(0.0, k.fy / c.z, -k.fy * c.y / (c.z * c.z));
            let rt = p.new_w2c.rot.transpose();
            let (ju, jv) = (rt * du, rt * dv);
            h += (ju * ju.transpose() + jv * jv.transpose()) * w_obs;
            b += (ju * r[0] + jv * r[1]) * w_obs;
        }
        let Some(step) = h.lu().solve(&(-b)) else {
            return predicted;
        };
        x += step;
    }
    if seen.iter().any(|(p, _)| p.new_w2c.act(&x).z <= MIN_DEPTH) {
        return predicted;
    }
    x
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::TrainConfig;
    use crate::output::ViewResult;
    use gems_math::{Pose, So3};

    const K: Intrinsics = Intrinsics {
        fx: 100.0,
        fy: 100.0,
        cx: 48.0,
        cy: 32.0,
        width: 96,
        height: 64,
    };

    /// Six cameras on an arc at z = −3 looking at the origin region (+z forward).
    fn cameras() -> Vec<Se3> {
        (0..6)
            .map(|i| {
                let a = (i as f64 - 2.5) * 0.12;
                let rot = *So3::exp(&Vector3::new(0.02 * i as f64, -a, 0.0)).matrix();
                Se3::new(rot, Vector3::new(3.0 * a.sin(), 0.1 * i as f64, -3.0))
            })
            .collect()
    }

    fn gaussians(means: &[[f32; 3]]) -> Gaussians {
        let n = means.len();
        Gaussians {
            means: means.to_vec(),
            quats: vec![[1.0, 0.0, 0.0, 0.0]; n],
            log_scales: vec![[-3.0; 3]; n],
            opacity_logits: (0..n).map(|i| i as f32 * 0.1).collect(),
            sh: vec![[[0.5; 3]; gems_splat::SH_COEFFS]; n],
            sh_degree: 0,
        }
    }

    fn first_output(c2w: &[Se3], g: Gaussians) -> TrainOutput {
        let views = c2w
            .iter()
            .enumerate()
            .map(|(i, c)| ViewResult {
                name: format!("{i}.png"),
                intrinsics: K,
                c2w_init: Pose::from(c),
                c2w_gt: None,
                c2w_gt_subframes: Vec::new(),
                knots: Vec::new(),
                virtual_c2w: Vec::new(),
                mid_c2w: Pose::from(c),
            })
            .collect();
        TrainOutput {
            config: TrainConfig::default(),
            normalization: Normalization::identity(),
            scene_scale: 1.0,
            init_label: "test".into(),
            gaussians: g,
            views,
            history: crate::trainer::History::default(),
            seconds: 0.0,
            steps: 0,
            pose_model: None,
        }
    }

    fn train_views(c2w: &[Se3]) -> Vec<TrainView> {
        c2w.iter()
            .enumerate()
            .map(|(i, c)| TrainView {
                name: format!("{i}.png"),
                image: vec![0.0; (K.width * K.height * 3) as usize],
                intrinsics: K,
                c2w_init: *c,
                c2w_gt: None,
                c2w_gt_subframes: Vec::new(),
            })
            .collect()
    }

    fn sim_apply(s: &Sim3, c: &Se3) -> Se3 {
        Se3::new(s.rot * c.rot, s.rot * c.trans * s.scale + s.trans)
    }

    fn point_grid() -> Vec<[f32; 3]> {
        let mut v = Vec::new();
        for i in 0..5 {
            for j in 0..4 {
                v.push([
                    -0.6 + 0.3 * i as f32,
                    -0.4 + 0.25 * j as f32,
                    0.5 * (i + j) as f32 % 1.5,
                ]);
            }
        }
        v
    }

    #[test]
    fn under_a_similarity_the_gaussians_follow_it_exactly() {
        let old = cameras();
        let s = Sim3 {
            scale: 1.7,
            rot: *So3::exp(&Vector3::new(0.3, -0.2, 0.5)).matrix(),
            trans: Vector3::new(0.4, -1.0, 2.0),
        };
        let new: Vec<Se3> = old.iter().map(|c| sim_apply(&s, c)).collect();
        let means = point_grid();
        let first = first_output(&old, gaussians(&means));
        let out = carry_over_gaussians(&first, &train_views(&new), usize::MAX).unwrap();
        assert_eq!(out.len(), means.len());
        for (m, o) in out.means.iter().zip(&means) {
            let want = s.act(&o.map(f64::from));
            for a in 0..3 {
                assert!(
                    (f64::from(m[a]) - want[a]).abs() < 1e-5,
                    "{m:?} vs {want:?}"
                );
            }
        }
        let ln = s.scale.ln() as f32;
        assert!(
            out.log_scales
                .iter()
                .all(|l| (l[0] - (-3.0 + ln)).abs() < 1e-5)
        );
        let q = gems_math::rotation_to_quat_wxyz(&s.rot);
        for qq in &out.quats {
            let dot: f64 = (0..4).map(|a| f64::from(qq[a]) * q[a]).sum();
            assert!(dot.abs() > 1.0 - 1e-6, "{qq:?} vs {q:?}");
        }
    }

    #[test]
    fn triangulation_finds_the_point_its_projections_say_against_a_wrong_prediction() {
        // The same cameras in both models: the projections fix each point, and a prediction
        // 0.15 off (4 % of the depth) is pulled most of the way back (the prior keeps a little).
        let cams = cameras();
        let pairs: Vec<ViewPair> = cams
            .iter()
            .map(|c| ViewPair {
                old_w2c: c.inverse(),
                old_k: K,
                new_w2c: c.inverse(),
                new_k: K,
            })
            .collect();
        for m in point_grid() {
            let truth = Vector3::from(m.map(f64::from));
            let predicted = truth + Vector3::new(0.05, -0.1, 0.1);
            let got = triangulate(&pairs, &truth, predicted);
            assert!(
                (got - truth).norm() < 0.2 * (predicted - truth).norm(),
                "{got:?} vs {truth:?} (prediction {predicted:?})"
            );
        }
        // Seen by no camera: the prediction stands.
        let behind = Vector3::new(0.0, 0.0, -10.0);
        let predicted = behind + Vector3::new(0.3, 0.0, 0.0);
        assert_eq!(triangulate(&pairs, &behind, predicted), predicted);
    }

    #[test]
    fn the_most_opaque_are_kept_in_their_order() {
        let old = cameras();
        let means = point_grid();
        let first = first_output(&old, gaussians(&means));
        let out = carry_over_gaussians(&first, &train_views(&old), 5).unwrap();
        // Opacity logits rise with the index: the last five, in order.
        assert_eq!(out.opacity_logits, first.gaussians.opacity_logits[15..]);
        for (m, o) in out.means.iter().zip(&means[15..]) {
            for a in 0..3 {
                assert!((m[a] - o[a]).abs() < 1e-4, "{m:?} vs {o:?}");
            }
        }
    }

    #[test]
    fn too_few_shared_views_is_an_error() {
        let old = cameras();
        let first = first_output(&old, gaussians(&point_grid()));
        let mut views = train_views(&old);
        for v in &mut views[1..] {
            v.name = format!("other-{}", v.name);
        }
        assert!(matches!(
            carry_over_gaussians(&first, &views, 10),
            Err(TrainError::Input(_))
        ));
    }
}

//! From a scene folder to a [`TrainInput`]: initial poses and points by initialisation mode,
//! blurry images, PRISM3D normalisation and initial Gaussians.
//!
//! Modes:
//! * `colmap` — poses and points of a COLMAP sparse model (the scene's `sparse/0`, or a path).
//! * `gt` — ground-truth mid-exposure poses.
//! * `gt-noisy` — ground truth perturbed by seeded noise (σ in normalised units; labelled so).
//! * SfM (`gems-init`) is run by the caller (`gems sfm` writes `sparse/0`, then `colmap` mode).
//!
//! Points: the chosen model's points (ground-truth modes use `gt/sparse/0` when the scene has
//! it, as `gems synth` writes); without points, random points inside the camera frustums.

use std::path::{Path, PathBuf};

use gems_data::{Scene, colmap::SparseModel, load_image};
use gems_math::{Intrinsics, Matrix3, Pose, Se3, Vector3, Vector6};
use gems_splat::Camera;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

use crate::TrainError;
use crate::config::TopUp;
use crate::config::TrainConfig;
use crate::init::{PointCloud, from_points, near_points, random_in_frustums};
use crate::normalize::Normalization;
use crate::trainer::{TrainInput, TrainView};

/// Where the initial poses (and points) come from.
#[derive(Clone, Debug, PartialEq)]
pub enum InitMode {
    /// A COLMAP model at this folder, or (`None`) the scene's own poses: its COLMAP model, else
    /// its poses file (`poses_bounds.npy`, `transforms.json`; points then start at random).
    Colmap(Option<PathBuf>),
    /// Ground-truth poses.
    Gt,
    /// Ground-truth poses with Gaussian noise (normalised units: translation σ, rotation σ rad).
    GtNoisy {
        translation_std: f64,
        rotation_std: f64,
    },
}

impl InitMode {
    /// Label recorded in the output and shown in the report.
    pub fn label(&self) -> String {
        match self {
            InitMode::Colmap(None) => "colmap (the scene's own model or poses)".into(),
            InitMode::Colmap(Some(p)) => format!("colmap ({})", p.display()),
            InitMode::Gt => "gt (ground-truth poses)".into(),
            InitMode::GtNoisy {
                translation_std,
                rotation_std,
            } => {
                format!(
                    "gt-noisy (ground truth + noise, sigma_t {translation_std}, sigma_r {rotation_std} rad)"
                )
            }
        }
    }
}

/// A training view as read from the scene, before normalisation.
struct RawView {
    name: String,
    image: Vec<f32>,
    intrinsics: Intrinsics,
    /// Initial camera-to-world pose.
    c2w: Se3,
    /// Ground-truth mid-exposure camera-to-world pose ([`gt_c2w`]).
    gt: Option<Se3>,
    /// Ground-truth camera-to-world poses of the sharp sub-frames, in time order.
    gt_subframes: Vec<Se3>,
}

fn c2w_of(p: &Pose) -> Se3 {
    Se3::from_arrays(&p.rotation, &p.translation).inverse()
}

/// The ground-truth camera-to-world pose a view is compared with: its explicit ground truth, or
/// else the middle of its ground-truth sub-frame poses (ExBluRF/E2NeRF-style
/// `poses_bounds_subframes.npy`), i.e. the mid-exposure pose. With an even number of sub-frames
/// it is halfway along the SE(3) geodesic between the two middle ones.
fn gt_c2w(gt_pose: Option<&Pose>, subframes: Option<&[Pose]>) -> Option<Se3> {
    if let Some(p) = gt_pose {
        return Some(c2w_of(p));
    }
    let subs = subframes.filter(|s| !s.is_empty())?;
    let n = subs.len();
    if n % 2 == 1 {
        return Some(c2w_of(&subs[n / 2]));
    }
    let (a, b) = (c2w_of(&subs[n / 2 - 1]), c2w_of(&subs[n / 2]));
    Some(a.compose(&Se3::exp(&(a.inverse().compose(&b).log() * 0.5))))
}

fn read_points(model: &SparseModel) -> (Vec<[f32; 3]>, Vec<[f32; 3]>) {
    let pts = model
        .points
        .iter()
        .map(|p| p.xyz.map(|v| v as f32))
        .collect();
    let cols = model
        .points
        .iter()
        .map(|p| p.rgb.map(|c| c as f32 / 255.0))
        .collect();
    (pts, cols)
}

fn load_model(dir: &Path) -> Result<SparseModel, TrainError> {
    gems_data::colmap::read_model(dir)
        .map_err(|e| TrainError::Input(format!("reading COLMAP model {}: {e}", dir.display())))
}

/// The 5th–95th percentile depth range (widened by 20 %) of `points` seen by `cams`, or `None`
/// when no point lies in front of a camera.
fn depth_range(points: &[[f32; 3]], cams: &[Camera]) -> Option<(f32, f32)> {
    let mut depths: Vec<f32> = cams
        .iter()
        .flat_map(|c| {
            points.iter().map(move |p| {
                let r = &c.rotation[2];
                r[0] * p[0] + r[1] * p[1] + r[2] * p[2] + c.translation[2]
            })
        })
        .filter(|z| z.is_finite() && *z > 0.0)
        .collect();
    if depths.is_empty() {
        return None;
    }
    depths.sort_by(f32::total_cmp);
    let at = |q: f64| depths[((depths.len() - 1) as f64 * q).round() as usize];
    let (near, far) = (0.8 * at(0.05), 1.2 * at(0.95));
    (far > near && near > 0.0).then_some((near, far))
}

/// Builds the training input of `scene` for `mode`, step by step: the sparse model the poses
/// (and points) come from, each view's image and initial pose, the PRISM3D normalisation, the
/// optional pose noise, the scene scale, then the initial Gaussians. The seeded generator is
/// drawn from in that order (noise, then points), so a seed gives one input.
pub fn prepare_input(
    scene: &Scene,
    mode: &InitMode,
    cfg: &TrainConfig,
) -> Result<TrainInput, TrainError> {
    let model = initial_model(scene, mode)?;
    let raw = read_views(scene, mode, model.as_ref())?;
    let poses: Vec<(Matrix3<f64>, Vector3<f64>)> =
        raw.iter().map(|r| (r.c2w.rot, r.c2w.trans)).collect();
    let norm = if cfg.normalize.enabled {
        Normalization::from_cameras(&poses, cfg.normalize.scale_factor)
    } else {
        Normalization::identity()
    };
    let mut rng = ChaCha8Rng::seed_from_u64(cfg.seed ^ 0x006e_6f69_7365);
    let views = normalised_views(raw, mode, &norm, &mut rng)?;
    let scene_scale = scene_scale(&views, cfg.normalize.scene_scale_margin);
    let cams: Vec<_> = views
        .iter()
        .map(|v| Camera::from_c2w(&v.intrinsics, &v.c2w_init))
        .collect();
    let (points, colors) =
        initial_points(model.as_ref(), &norm, &cams, cfg, scene_scale, &mut rng)?;
    let gaussians = from_points(&points, &colors, &cfg.init, cfg.sh_degree, &mut rng)?;
    Ok(TrainInput {
        views,
        gaussians,
        normalization: norm,
        scene_scale,
        init_label: mode.label(),
    })
}

/// The sparse model the run starts from: the given or the scene's COLMAP model, or for
/// ground-truth modes the scene's `gt/sparse/0` when it has one (for its points).
fn initial_model(scene: &Scene, mode: &InitMode) -> Result<Option<SparseModel>, TrainError> {
    Ok(match mode {
        InitMode::Colmap(Some(dir)) => {
            let mut model = load_model(dir)?;
            let names: Vec<String> = scene.views.iter().map(|v| v.name.clone()).collect();
            let matched = model.key_by_view_names(&names);
            tracing::info!(
                dir = %dir.display(),
                matched = matched.matched,
                views = matched.views,
                "COLMAP model's images matched {}",
                matched.rule.describe()
            );
            Some(model)
        }
        InitMode::Colmap(None) => match &scene.sfm {
            Some(model) => Some(model.clone()),
            None if scene.pose_source != gems_data::PoseSource::None => {
                tracing::info!(
                    "the scene has poses but no COLMAP model: its poses, and points at random"
                );
                None
            }
            None => {
                let why = match scene.sfm_match {
                    Some(m) => format!(
                        "its COLMAP model names none of its {} views (by file name, stem or \
                         sorted order)",
                        m.views
                    ),
                    None => "no COLMAP model and no poses".to_owned(),
                };
                return Err(TrainError::Input(format!(
                    "{}: {why} (run `gems sfm`, pass --colmap-model, or use --init sfm)",
                    scene.root.display()
                )));
            }
        },
        InitMode::Gt | InitMode::GtNoisy { .. } => {
            let gt_dir = scene.root.join("gt").join("sparse").join("0");
            if gt_dir.is_dir() {
                Some(load_model(&gt_dir)?)
            } else {
                None
            }
        }
    })
}

/// Each training view's image, intrinsics and initial pose (input frame) for `mode`. Views the
/// model did not register are named in a warning and left out; no view at all is an error.
fn read_views(
    scene: &Scene,
    mode: &InitMode,
    model: Option<&SparseModel>,
) -> Result<Vec<RawView>, TrainError> {
    let mut raw = Vec::new();
    // Views an SfM model did not register cannot be trained on; they are named, never dropped
    // silently (their SfM report lists them too).
    let mut unregistered = Vec::new();
    for v in scene.train_views() {
        let (pose, k) = match mode {
            InitMode::Colmap(Some(_)) => {
                let m = model.expect("colmap mode loads a model");
                let Some(img) = m.image_by_name(&v.name) else {
                    unregistered.push(v.name.clone());
                    continue;
                };
                let cam = m.camera(img.camera_id).ok_or_else(|| {
                    TrainError::Input(format!(
                        "COLMAP model: image {} refers to missing camera {}",
                        img.name, img.camera_id
                    ))
                })?;
                let k = cam.intrinsics().map_err(|e| {
                    TrainError::Input(format!("COLMAP model: camera {}: {e}", cam.id))
                })?;
                (img.pose(), Some(k.resized(v.width, v.height)))
            }
            InitMode::Colmap(None) => match v.pose {
                Some(p) => (p, v.intrinsics),
                None => {
                    unregistered.push(v.name.clone());
                    continue;
                }
            },
            InitMode::Gt | InitMode::GtNoisy { .. } => {
                let Some(p) = v.gt_pose else {
                    return Err(TrainError::Input(format!(
                        "view {} ({}) has no ground-truth pose for {}",
                        v.name,
                        v.image.display(),
                        mode.label()
                    )));
                };
                (p, v.intrinsics)
            }
        };
        let k = k.ok_or_else(|| {
            TrainError::Input(format!(
                "view {} ({}) has no intrinsics",
                v.name,
                v.image.display()
            ))
        })?;
        let img = load_image(&v.image).map_err(|e| TrainError::Input(e.to_string()))?;
        if (img.width, img.height) != (k.width, k.height) {
            return Err(TrainError::Input(format!(
                "{}: image is {}x{} but its intrinsics are for {}x{}",
                v.image.display(),
                img.width,
                img.height,
                k.width,
                k.height
            )));
        }
        raw.push(RawView {
            name: v.name.clone(),
            image: img.data,
            intrinsics: k,
            c2w: c2w_of(&pose),
            gt: gt_c2w(v.gt_pose.as_ref(), v.gt_subframe_poses.as_deref()),
            gt_subframes: v.gt_subframe_poses.iter().flatten().map(c2w_of).collect(),
        });
    }
    if !unregistered.is_empty() {
        tracing::warn!(
            "{} of {} training views have no pose in the {} and are not trained on: {}",
            unregistered.len(),
            unregistered.len() + raw.len(),
            mode.label(),
            unregistered.join(", ")
        );
    }
    if raw.is_empty() {
        return Err(TrainError::Input(format!(
            "{}: no training view has an initial pose ({})",
            scene.root.display(),
            mode.label()
        )));
    }

    Ok(raw)
}

/// The views in the normalised frame, with seeded SE(3) noise on the initial pose for
/// [`InitMode::GtNoisy`].
fn normalised_views(
    raw: Vec<RawView>,
    mode: &InitMode,
    norm: &Normalization,
    rng: &mut ChaCha8Rng,
) -> Result<Vec<TrainView>, TrainError> {
    let to_norm = |p: &Se3| {
        let (r, t) = norm.apply_c2w(&p.rot, &p.trans);
        Se3::new(r, t)
    };
    let mut views = Vec::with_capacity(raw.len());
    for RawView {
        name,
        image,
        intrinsics,
        c2w,
        gt,
        gt_subframes,
    } in raw
    {
        let mut c2w_init = to_norm(&c2w);
        if let InitMode::GtNoisy {
            translation_std,
            rotation_std,
        } = mode
        {
            let nt = Normal::new(0.0, *translation_std)
                .map_err(|e| TrainError::Config(e.to_string()))?;
            let nr =
                Normal::new(0.0, *rotation_std).map_err(|e| TrainError::Config(e.to_string()))?;
            let xi = Vector6::from_fn(|i, _| {
                if i < 3 {
                    nt.sample(rng)
                } else {
                    nr.sample(rng)
                }
            });
            c2w_init = c2w_init * Se3::exp(&xi);
        }
        views.push(TrainView {
            name,
            image,
            intrinsics,
            c2w_init,
            c2w_gt: gt.as_ref().map(to_norm),
            c2w_gt_subframes: gt_subframes.iter().map(to_norm).collect(),
        });
    }
    Ok(views)
}

/// The scene scale: `margin` × the largest distance of a camera centre from their mean.
fn scene_scale(views: &[TrainView], margin: f64) -> f32 {
    let centre = views
        .iter()
        .fold(Vector3::zeros(), |a, v| a + v.c2w_init.trans)
        / views.len() as f64;
    let max_dist = views
        .iter()
        .map(|v| (v.c2w_init.trans - centre).norm())
        .fold(0.0, f64::max);
    (margin * max_dist).max(1e-6) as f32
}

/// The initial point cloud (normalised frame) and colours: the model's points, topped up when
/// there are fewer than `init.min_points`, else random points in the camera frustums.
fn initial_points(
    model: Option<&SparseModel>,
    norm: &Normalization,
    cams: &[Camera],
    cfg: &TrainConfig,
    scene_scale: f32,
    rng: &mut ChaCha8Rng,
) -> Result<PointCloud, TrainError> {
    // MCMC never removes Gaussians, so an initial cloud above its cap would stay above it.
    let (min_points, random_points) = (
        cfg.init.min_points.min(cfg.mcmc.cap_max),
        cfg.init.random_points.min(cfg.mcmc.cap_max),
    );
    Ok(match model.map(read_points) {
        Some((p, c)) if p.len() >= 2 => {
            let mut p: Vec<[f32; 3]> = p
                .iter()
                .map(|x| {
                    let q = norm.apply_point(&Vector3::new(x[0] as f64, x[1] as f64, x[2] as f64));
                    [q.x as f32, q.y as f32, q.z as f32]
                })
                .collect();
            let mut c = c;
            if p.len() < min_points {
                let (near, far) = depth_range(&p, cams).unwrap_or((
                    cfg.init.random_near * scene_scale,
                    cfg.init.random_far * scene_scale,
                ));
                let extra = min_points - p.len();
                tracing::debug!(
                    sfm_points = p.len(),
                    extra,
                    near,
                    far,
                    top_up = ?cfg.init.top_up,
                    "sparse SfM cloud: adding points"
                );
                let (rp, rc) = match cfg.init.top_up {
                    TopUp::Frustums => random_in_frustums(cams, extra, near, far, rng)?,
                    TopUp::NearPoints => near_points(&p, &c, cfg.init.knn, extra, rng)?,
                };
                p.extend(rp);
                c.extend(rc);
            }
            (p, c)
        }
        _ => {
            let (near, far) = (
                cfg.init.random_near * scene_scale,
                cfg.init.random_far * scene_scale,
            );
            random_in_frustums(cams, random_points, near, far, rng)?
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pose_at(x: f64, yaw: f64) -> Pose {
        let c2w = Se3::exp(&Vector6::new(x, 0.0, 0.0, 0.0, yaw, 0.0));
        let w2c = c2w.inverse();
        let mut rotation = [[0.0; 3]; 3];
        for (i, row) in rotation.iter_mut().enumerate() {
            for (j, v) in row.iter_mut().enumerate() {
                *v = w2c.rot[(i, j)];
            }
        }
        Pose {
            rotation,
            translation: [w2c.trans[0], w2c.trans[1], w2c.trans[2]],
        }
    }

    #[test]
    fn ground_truth_is_the_explicit_pose_else_the_mid_subframe() {
        let explicit = pose_at(5.0, 0.0);
        let odd: Vec<Pose> = (0..5).map(|i| pose_at(0.1 * i as f64, 0.0)).collect();
        let even: Vec<Pose> = (0..4)
            .map(|i| pose_at(0.1 * i as f64, 0.02 * i as f64))
            .collect();
        let centre = |s: Se3| s.trans;
        assert!((centre(gt_c2w(Some(&explicit), Some(&odd)).unwrap())[0] - 5.0).abs() < 1e-12);
        assert!((centre(gt_c2w(None, Some(&odd)).unwrap())[0] - 0.2).abs() < 1e-12);
        // Even count: halfway between sub-frames 1 and 2 (x 0.15, yaw 0.03 on the geodesic).
        let mid = gt_c2w(None, Some(&even)).unwrap();
        let expect = Se3::exp(&Vector6::new(0.15, 0.0, 0.0, 0.0, 0.03, 0.0));
        assert!((mid.inverse().compose(&expect)).log().norm() < 1e-9);
        assert!(gt_c2w(None, Some(&[])).is_none() && gt_c2w(None, None).is_none());
    }
}

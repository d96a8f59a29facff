//! Tiny synthetic scenes for the training tests: a random textured Gaussian "wall" and a few
//! cameras looking at it, each with a known exposure trajectory.
#![allow(dead_code)]

use gems_math::Intrinsics;
use gems_math::{Se3, Vector3, Vector6};
use gems_splat::{Camera, Gaussians, Gradients, RenderSettings, reference};
use gems_train::Rasterizer;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// A wall of `n` coloured Gaussians at depth ≈ 2.5 in front of cameras near the origin.
pub fn wall(n: usize, seed: u64, extent: f32) -> Gaussians {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut g = Gaussians::with_degree(0);
    for _ in 0..n {
        let mean = [
            (rng.random::<f32>() - 0.5) * 2.0 * extent,
            (rng.random::<f32>() - 0.5) * 2.0 * extent * 0.8,
            2.5 + (rng.random::<f32>() - 0.5) * 0.3,
        ];
        let mut sh = [[0.0f32; 3]; 16];
        sh[0] = std::array::from_fn(|_| (rng.random::<f32>() - 0.5) / 0.2820948);
        let s = (0.04 + 0.05 * rng.random::<f32>()) * extent;
        let q: [f32; 4] = std::array::from_fn(|_| rng.random::<f32>() - 0.5);
        g.push(mean, q, [s.ln(), (s * 0.6).ln(), (s * 0.8).ln()], 2.0, sh);
    }
    g
}

pub fn intrinsics(w: u32, h: u32) -> Intrinsics {
    Intrinsics {
        fx: f64::from(w as f32 * 0.9),
        fy: f64::from(w as f32 * 0.9),
        cx: f64::from(w) / 2.0,
        cy: f64::from(h) / 2.0,
        width: w,
        height: h,
    }
}

/// A camera-to-world pose near the origin looking down +z (OpenCV), offset by `x`.
pub fn pose(x: f64, y: f64, yaw: f64) -> Se3 {
    Se3::exp(&Vector6::new(x, y, 0.0, 0.0, yaw, 0.0))
}

pub fn tangent(v: [f64; 6]) -> Vector6<f64> {
    Vector6::from(v)
}

pub fn center(p: &Se3) -> Vector3<f64> {
    p.trans
}

/// The f64 dense reference renderer behind the `Rasterizer` trait (results rounded to f32).
pub struct Reference(pub RenderSettings);

/// Settings without the hard 1/255 and 3.33σ cut-offs, so finite differences see a smooth loss.
pub fn smooth_settings() -> RenderSettings {
    RenderSettings {
        alpha_min: 0.0,
        radius_extent: 8.0,
        ..RenderSettings::default()
    }
}

impl Rasterizer for Reference {
    fn render(
        &mut self,
        g: &Gaussians,
        cams: &[Camera],
        bgs: &[[f32; 3]],
    ) -> Result<Vec<f32>, gems_train::TrainError> {
        Ok(reference::forward(g, cams, bgs, &self.0)?
            .rgb
            .iter()
            .map(|&v| v as f32)
            .collect())
    }

    fn gradients(
        &mut self,
        g: &Gaussians,
        cams: &[Camera],
        bgs: &[[f32; 3]],
        d_rgb: &[f32],
    ) -> Result<Gradients, gems_train::TrainError> {
        let d: Vec<f64> = d_rgb.iter().map(|&v| v as f64).collect();
        let r = reference::backward(g, cams, bgs, &self.0, &d, None)?;
        let f3 = |v: &[f64; 3]| v.map(|x| x as f32);
        Ok(Gradients {
            means: r.means.iter().map(f3).collect(),
            quats: r.quats.iter().map(|v| v.map(|x| x as f32)).collect(),
            log_scales: r.log_scales.iter().map(f3).collect(),
            opacity_logits: r.opacity_logits.iter().map(|&x| x as f32).collect(),
            sh: r
                .sh
                .iter()
                .map(|s| s.map(|c| c.map(|x| x as f32)))
                .collect(),
            backgrounds: r.backgrounds.iter().map(f3).collect(),
            cam_rotation: r
                .cam_rotation
                .iter()
                .map(|m| m.map(|row| row.map(|x| x as f32)))
                .collect(),
            cam_translation: r.cam_translation.iter().map(f3).collect(),
            cam_focal: r.cam_focal.iter().map(|f| f.map(|x| x as f32)).collect(),
            mean2d_grad_norm: r.mean2d_grad_norm.iter().map(|&x| x as f32).collect(),
            visible_count: r.visible_count.clone(),
        })
    }
}

/// A synthetic extreme-blur training set.
pub struct BlurScene {
    pub views: Vec<gems_train::TrainView>,
    /// Ground-truth sharp mid-exposure renders, `[H,W,3]` each.
    pub sharp: Vec<Vec<f32>>,
    pub gt_mid: Vec<Se3>,
    /// Exposure motion of each view: c2w(s) = mid·Exp(s·m), s ∈ [−½, ½].
    pub gt_motion: Vec<[f64; 6]>,
    pub gt: Gaussians,
}

/// `n_views` cameras on a grid looking at the wall; each blurry image is the mean of 21 sharp
/// renders along a known exposure motion (translation `motion` plus a yaw), and the initial
/// pose is the true mid-exposure pose perturbed by noise of scale `pose_noise`.
pub fn blur_scene(
    n_views: usize,
    w: u32,
    h: u32,
    motion: f64,
    pose_noise: f64,
    seed: u64,
) -> BlurScene {
    use gems_splat::Camera;
    let gt = wall(500, seed, 2.0);
    let k = intrinsics(w, h);
    let mut rng = ChaCha8Rng::seed_from_u64(seed + 1);
    let mut r = gems_splat::Renderer::new();
    let mut out = BlurScene {
        views: vec![],
        sharp: vec![],
        gt_mid: vec![],
        gt_motion: vec![],
        gt: gt.clone(),
    };
    let mut g = gt;
    g.sh_degree = 0;
    for v in 0..n_views {
        let mid = pose(
            (v % 3) as f64 * 0.25 - 0.25,
            (v / 3) as f64 * 0.2 - 0.1,
            0.05 * (v as f64 - 2.0),
        );
        let ang = rng.random::<f64>() * std::f64::consts::TAU;
        let m = tangent([
            motion * ang.cos(),
            motion * ang.sin(),
            0.0,
            0.0,
            0.3 * motion * ang.sin(),
            0.1 * motion,
        ]);
        let cams: Vec<Camera> = (0..21)
            .map(|i| Camera::from_c2w(&k, &(mid * Se3::exp(&(m * (i as f64 / 20.0 - 0.5))))))
            .collect();
        let rgb = r
            .forward(
                &g,
                &cams,
                &vec![[0.0; 3]; cams.len()],
                &RenderSettings::default(),
            )
            .unwrap()
            .rgb;
        let img = (w * h * 3) as usize;
        let mut blurry = vec![0.0f32; img];
        for c in rgb.chunks_exact(img) {
            for (b, x) in blurry.iter_mut().zip(c) {
                *b += x / 21.0;
            }
        }
        let sharp = r
            .forward(
                &g,
                &[Camera::from_c2w(&k, &mid)],
                &[[0.0; 3]],
                &RenderSettings::default(),
            )
            .unwrap()
            .rgb;
        let noise: [f64; 6] = std::array::from_fn(|i| {
            let s = if i < 3 { pose_noise } else { pose_noise * 0.5 };
            s * (rng.random::<f64>() * 2.0 - 1.0)
        });
        out.views.push(gems_train::TrainView {
            name: format!("view{v:02}"),
            image: blurry,
            intrinsics: k,
            c2w_init: mid * Se3::exp(&tangent(noise)),
            c2w_gt: Some(mid),
            c2w_gt_subframes: Vec::new(),
        });
        out.sharp.push(sharp);
        out.gt_mid.push(mid);
        out.gt_motion.push(m.into());
    }
    out
}

/// Initial Gaussians: the true means jittered, with their true colours and 3-NN scales (what an
/// SfM point cloud provides).
pub fn init_gaussians(scene: &BlurScene, jitter: f32, seed: u64) -> Gaussians {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let pts: Vec<[f32; 3]> = scene
        .gt
        .means
        .iter()
        .map(|m| std::array::from_fn(|i| m[i] + jitter * (rng.random::<f32>() * 2.0 - 1.0)))
        .collect();
    let cols: Vec<[f32; 3]> = scene
        .gt
        .sh
        .iter()
        .map(|s| s[0].map(|c| (c * 0.2820948 + 0.5).clamp(0.0, 1.0)))
        .collect();
    // The test cloud is sparse (one point per true Gaussian), so start from scales near the truth.
    let cfg = gems_train::InitConfig {
        scale_factor: 0.5,
        ..Default::default()
    };
    gems_train::from_points(&pts, &cols, &cfg, 3, &mut rng).unwrap()
}

/// Sets every Gaussian learning rate to 0 (the Gaussians stay as given).
pub fn freeze_gaussians(cfg: &mut gems_train::TrainConfig) {
    cfg.lr = gems_train::LearningRates {
        means: 0.0,
        log_scales: 0.0,
        quats: 0.0,
        opacities: 0.0,
        sh_dc: 0.0,
        sh_rest: 0.0,
        ..cfg.lr
    };
}

/// Focal factor by which [`short_focal_input`] understates the focal.
pub const SHORT_FOCAL: f64 = 0.94;

/// Sharp photos of a [`blur_scene`] (no motion, exact poses) with its true Gaussians, given to
/// the trainer with every focal [`SHORT_FOCAL`] times the one they were rendered at.
pub fn short_focal_input() -> gems_train::TrainInput {
    let scene = blur_scene(3, 32, 24, 0.0, 0.0, 1);
    let views = scene
        .views
        .iter()
        .map(|v| gems_train::TrainView {
            intrinsics: v.intrinsics.with_focal_scaled(SHORT_FOCAL),
            ..v.clone()
        })
        .collect();
    gems_train::TrainInput {
        views,
        gaussians: scene.gt,
        normalization: gems_train::Normalization::identity(),
        scene_scale: 1.0,
        init_label: "gt".into(),
    }
}

/// 100 steps that can change only the focal factor (`focal_lr`): Gaussians, poses, noise and
/// refinement off, one virtual view, black background, full size throughout.
pub fn focal_only_config(focal_lr: f32) -> gems_train::TrainConfig {
    let mut cfg = gems_train::TrainConfig {
        steps: 100,
        num_virtual_views: 1,
        random_background: false,
        seed: 3,
        ..gems_train::TrainConfig::default()
    };
    freeze_gaussians(&mut cfg);
    cfg.mcmc.noise_lr = 0.0;
    cfg.mcmc.refine_every = 1000;
    cfg.pose.lr = 0.0;
    cfg.pose.knot_init_std = 1e-9;
    cfg.pose.focal_lr = focal_lr;
    cfg.coarse_to_fine.levels = 0;
    cfg
}

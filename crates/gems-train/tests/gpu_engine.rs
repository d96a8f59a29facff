//! Training on the GPU engine (Mesa lavapipe on CI) against the CPU engine: the same short run
//! from the same initialisation ends at the same fit (within 0.3 dB), and checkpoint + resume
//! on the GPU continues bit-identically. Fails (never skips) without a GPU adapter.

mod common;

use gems_gpu::DeviceChoice;
use gems_train::TrainConfig;
use gems_train::engine::Engine;
use gems_train::io::{load_checkpoint, save_checkpoint};
use gems_train::normalize::Normalization;
use gems_train::trainer::{TrainInput, Trainer, psnr};

fn config() -> TrainConfig {
    let mut c = TrainConfig {
        steps: 60,
        num_virtual_views: 4,
        seed: 3,
        ..TrainConfig::default()
    };
    c.pose.accumulate_steps = 5;
    c.mcmc.cap_max = 600;
    c.mcmc.refine_every = 20;
    c.mcmc.refine_start_fraction = 0.1;
    c
}

fn trainer(cfg: &TrainConfig, engine: Engine) -> Trainer {
    let scene = common::blur_scene(3, 32, 24, 0.2, 0.02, 1);
    let input = TrainInput {
        views: scene.views.clone(),
        gaussians: common::init_gaussians(&scene, 0.02, 3),
        normalization: Normalization::identity(),
        scene_scale: 1.0,
        init_label: "gt-noisy".into(),
    };
    let mut t = Trainer::new(cfg.clone(), input).unwrap();
    t.set_engine(engine);
    t
}

fn gpu() -> Engine {
    let e = Engine::select(DeviceChoice::Gpu).expect(
        "no GPU adapter: install mesa-vulkan-drivers and libvulkan1, run with WGPU_BACKEND=vulkan",
    );
    assert!(matches!(e, Engine::Gpu(_)));
    eprintln!("{}", e.describe());
    e
}

/// Mean PSNR of each view's synthesised blurry image (rendered on the CPU) against its input.
fn fit_psnr(t: &mut Trainer) -> f32 {
    t.set_engine(Engine::cpu());
    let n = t.views.len();
    let mut sum = 0.0;
    for v in 0..n {
        let k = t.views[v].intrinsics;
        let poses = t.virtual_poses(v);
        let mut blurred = vec![0.0f32; t.views[v].image.len()];
        for p in &poses {
            let img = t.render_view(p, &k).unwrap();
            for (b, x) in blurred.iter_mut().zip(img) {
                *b += x / poses.len() as f32;
            }
        }
        sum += psnr(&blurred, &t.views[v].image);
    }
    sum / n as f32
}

#[test]
fn gpu_training_ends_within_0_3_db_of_cpu_training() {
    let cfg = config();
    let mut cpu = trainer(&cfg, Engine::cpu());
    let start = fit_psnr(&mut trainer(&cfg, Engine::cpu()));
    cpu.run(|_, _| Ok(())).unwrap();
    let mut gpu_run = trainer(&cfg, gpu());
    gpu_run.run(|_, _| Ok(())).unwrap();
    assert_eq!(gpu_run.state.step, cfg.steps);
    let (pc, pg) = (fit_psnr(&mut cpu), fit_psnr(&mut gpu_run));
    eprintln!("fit PSNR: start {start:.2} dB, CPU {pc:.2} dB, GPU {pg:.2} dB");
    assert!(
        pc > start + 1.0,
        "training did not improve the fit: {start} → {pc}"
    );
    assert!((pc - pg).abs() <= 0.3, "CPU {pc} dB vs GPU {pg} dB");
}

#[test]
fn gpu_resume_is_bit_identical() {
    let mut cfg = config();
    cfg.steps = 16;
    let mut a = trainer(&cfg, gpu());
    a.run(|_, _| Ok(())).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let mut b = trainer(&cfg, gpu());
    for _ in 0..7 {
        b.step().unwrap();
    }
    save_checkpoint(dir.path(), &b).unwrap();
    let views = b.views.clone();
    drop(b);
    let (cfg2, state) = load_checkpoint(dir.path()).unwrap();
    let mut c = Trainer::from_state(
        cfg2,
        views,
        Normalization::identity(),
        1.0,
        "gt-noisy".into(),
        state,
    )
    .unwrap();
    c.set_engine(gpu());
    c.run(|_, _| Ok(())).unwrap();
    assert_eq!(a.state.gaussians, c.state.gaussians);
    assert_eq!(a.state.knots, c.state.knots);
    assert_eq!(a.state.adam, c.state.adam);
}

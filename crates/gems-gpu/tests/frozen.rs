//! `FrozenScene` on the GPU (Gaussians resident, single-camera renders and pose gradients)
//! against the CPU engine's `forward`/`backward`, which the CPU `FrozenScene` runs.

#[path = "../../gems-splat/tests/common/mod.rs"]
mod common;

use common::*;
use gems_gpu::{DeviceChoice, Engine};
use gems_splat::{RenderSettings, Renderer};

#[test]
fn resident_renders_and_pose_gradients_match_the_cpu_engine() {
    let mut gpu = Engine::select(DeviceChoice::Gpu)
        .expect("no GPU adapter: install mesa-vulkan-drivers and run with WGPU_BACKEND=vulkan");
    let (g, cams, bgs) = random_scene(31, 400, 3, 64, 48, 3, (-3.2, -1.8));
    let s = RenderSettings::default();
    let mut frozen = gpu.freeze(&g).unwrap();
    let mut cpu = Renderer::new();
    // Several cameras and backgrounds through one frozen scene, each view's render followed
    // by its pose gradient, as the refinement alternates them.
    for (c, (cam, bg)) in cams.iter().zip(&bgs).enumerate() {
        let rgb = frozen.render(cam, *bg, &s).unwrap();
        let out = cpu.forward(&g, &[*cam], &[*bg], &s).unwrap();
        let f64v = |v: &[f32]| v.iter().map(|&x| f64::from(x)).collect::<Vec<_>>();
        assert_close(
            &format!("camera {c} rgb"),
            &f64v(&rgb),
            &f64v(&out.rgb),
            0.0,
            1e-4,
        );
        let d_rgb: Vec<f32> = random_weights(40 + c as u64, rgb.len())
            .into_iter()
            .map(|v| v as f32)
            .collect();
        let (d_r, d_t) = frozen.pose_gradient(cam, *bg, &d_rgb).unwrap();
        let want = cpu.backward(&g, &[*cam], &[*bg], &d_rgb, None).unwrap();
        assert_grad_close(
            &format!("camera {c} dL/dR"),
            &flat3(&d_r),
            &flat3(&want.cam_rotation[0]),
        );
        assert_grad_close(
            &format!("camera {c} dL/dt"),
            &flat3(&[d_t]),
            &flat3(&want.cam_translation),
        );
        assert!(
            d_t.iter().any(|&v| v != 0.0),
            "camera {c}: no pose gradient"
        );
    }
    // A dL/dRGB of the wrong size is an error, not a panic.
    let err = frozen
        .pose_gradient(&cams[0], bgs[0], &[0.0; 5])
        .unwrap_err();
    assert!(err.to_string().contains("dL/dRGB"), "{err}");
}

#[test]
fn an_empty_scene_renders_the_background_and_no_pose_gradient() {
    let mut gpu = Engine::select(DeviceChoice::Gpu)
        .expect("no GPU adapter: install mesa-vulkan-drivers and run with WGPU_BACKEND=vulkan");
    let (g, cams, _) = random_scene(32, 0, 1, 40, 30, 3, (-3.2, -1.8));
    let mut frozen = gpu.freeze(&g).unwrap();
    let rgb = frozen
        .render(&cams[0], [0.25, 0.5, 0.75], &RenderSettings::default())
        .unwrap();
    assert_eq!(rgb.len(), 40 * 30 * 3);
    assert!(rgb.chunks_exact(3).all(|p| p == [0.25, 0.5, 0.75]));
    let (d_r, d_t) = frozen
        .pose_gradient(&cams[0], [0.25, 0.5, 0.75], &vec![1.0; rgb.len()])
        .unwrap();
    assert_eq!((d_r, d_t), ([[0.0; 3]; 3], [0.0; 3]));
}

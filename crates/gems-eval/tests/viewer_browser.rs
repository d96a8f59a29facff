//! The WebGL2 viewer in a real browser: headless Chromium (SwiftShader WebGL) opens
//! `viewer.html#camera=<name>` in a window of the image's size; its screenshot must match gems'
//! own render of that camera (PSNR ≥ 25 dB), and another camera must give another image.
//!
//! Needs Debian's `chromium` (or `GEMS_CHROMIUM=<binary>`); without it the test fails.

use std::path::{Path, PathBuf};

use gems_eval::viewer::{CameraKind, ViewerCamera, ViewerScene, viewer_page};
use gems_splat::{Camera, Gaussians, RenderSettings, Renderer};

/// Screenshot of `viewer.html#camera=<name>` in a `w`×`h` window; fails without Chromium.
fn screenshot(page: &Path, name: &str, w: u32, h: u32, dir: &Path) -> gems_data::ImageRgb {
    use gems_eval::browser;
    assert!(
        browser::find_chromium().is_some(),
        "headless Chromium is needed for the viewer test: install Debian's `chromium` package \
         (apt-get install chromium) or set GEMS_CHROMIUM to a Chromium/Chrome binary"
    );
    let png = dir.join(format!("shot_{name}.png"));
    let url =
        browser::file_url(page, &format!("camera={}", browser::encode_component(name))).unwrap();
    browser::screenshot(&url, w, h, &png, dir).unwrap();
    let img = gems_data::load_image(&png).expect("reading the screenshot");
    assert_eq!((img.width, img.height), (w, h), "screenshot size");
    img
}

/// Deterministic pseudo-random numbers in [0, 1) (SplitMix64).
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> f32 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 40) as f32 / (1u64 << 24) as f32
    }
}

/// A few hundred anisotropic, view-dependent Gaussians in a box in front of the origin.
fn scene() -> Gaussians {
    let mut rng = Rng(7);
    let mut g = Gaussians::with_degree(1);
    for _ in 0..400 {
        let mean = [
            (rng.next() - 0.5) * 3.0,
            (rng.next() - 0.5) * 2.2,
            4.0 + rng.next() * 3.0,
        ];
        let quat = [
            rng.next() - 0.5,
            rng.next() - 0.5,
            rng.next() - 0.5,
            rng.next() - 0.5,
        ];
        let log_scale = [
            -3.0 + rng.next() * 1.5,
            -3.0 + rng.next() * 1.5,
            -3.5 + rng.next(),
        ];
        let mut sh = [[0.0f32; 3]; 16];
        sh[0] = [0; 3].map(|_: i32| (rng.next() - 0.5) * 3.0);
        for coeffs in &mut sh[1..4] {
            *coeffs = [0; 3].map(|_: i32| (rng.next() - 0.5) * 0.6);
        }
        g.push(mean, quat, log_scale, (rng.next() - 0.3) * 6.0, sh);
    }
    g
}

/// 640×480: headless Chromium does not make windows narrower than 500 pixels.
fn camera(pos: [f32; 3], target: [f32; 3]) -> Camera {
    Camera::look_at(
        &gems_math::Intrinsics {
            fx: 680.0,
            fy: 660.0,
            cx: 324.0,
            cy: 234.0,
            width: 640,
            height: 480,
        },
        pos,
        target,
        [0.0, -1.0, 0.0],
    )
    .expect("camera")
}

#[test]
fn viewer_matches_gems_render_in_chromium() {
    let tmp = tempfile::tempdir().unwrap();
    // GEMS_VIEWER_TEST_KEEP=<dir> keeps the page, screenshots and renders there for inspection.
    let keep = std::env::var_os("GEMS_VIEWER_TEST_KEEP").map(PathBuf::from);
    let dir = keep.as_deref().unwrap_or(tmp.path());
    let g = scene();
    let cams = [
        ("front", camera([0.0, 0.0, 0.0], [0.0, 0.0, 5.0])),
        ("side", camera([1.5, -0.8, 0.5], [0.0, 0.0, 5.5])),
    ];
    let view_scene = ViewerScene {
        gaussians: g.clone(),
        cameras: cams
            .iter()
            .map(|(name, c)| ViewerCamera {
                name: name.to_string(),
                kind: CameraKind::Train,
                camera: *c,
                trajectory: vec![c.center(), c.center().map(|v| v + 0.1)],
                images: Vec::new(),
            })
            .collect(),
        image_files: Vec::new(),
    };
    let page = dir.join("viewer.html");
    std::fs::write(&page, viewer_page(&view_scene, "test")).unwrap();
    let mut renderer = Renderer::new();
    let mut shots = Vec::new();
    for (name, cam) in &cams {
        let out = renderer
            .forward(&g, &[*cam], &[[0.0; 3]], &RenderSettings::default())
            .unwrap();
        let want: Vec<f32> = out.rgb.iter().map(|v| v.clamp(0.0, 1.0)).collect();
        let shot = screenshot(&page, name, cam.width, cam.height, dir);
        let (h, w) = (cam.height as usize, cam.width as usize);
        let p = gems_metrics::psnr(&shot.data, &want, h, w).unwrap();
        let covered = out.alpha.iter().filter(|&&a| a > 0.5).count() as f64 / (h * w) as f64;
        eprintln!(
            "{name}: PSNR {p:.2} dB vs gems render ({:.0}% covered)",
            covered * 100.0
        );
        gems_data::save_png(
            &dir.join(format!("gems_{name}.png")),
            &gems_data::ImageRgb {
                width: cam.width,
                height: cam.height,
                data: want,
            },
        )
        .unwrap();
        // The scene must actually be in view, or a blank page would pass.
        assert!(
            covered > 0.2,
            "{name}: the test scene covers only {covered}"
        );
        assert!(
            p >= 25.0,
            "{name}: viewer vs gems render PSNR {p:.2} dB < 25 dB"
        );
        shots.push(shot);
    }
    // Moving the camera changes the image.
    let (h, w) = (cams[0].1.height as usize, cams[0].1.width as usize);
    let between = gems_metrics::psnr(&shots[0].data, &shots[1].data, h, w).unwrap();
    assert!(
        between < 20.0,
        "two cameras gave nearly the same image ({between:.2} dB)"
    );
}

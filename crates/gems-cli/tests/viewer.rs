//! A trained scene's interactive view and exports, end to end: `gems train` writes `viewer.html`
//! and embeds the view in `report.html`; headless Chromium's screenshot of
//! `viewer.html#camera=<view>` matches gems' render of that view's mid-exposure camera
//! (PSNR ≥ 25 dB) and another view gives another image; `gems export` writes PLY and `.splat`.
//!
//! Needs Debian's `chromium` (or `GEMS_CHROMIUM=<binary>`); without it the test fails.

use std::path::Path;
use std::process::{Command, Output};

use gems_eval::browser;
use gems_splat::{RenderSettings, Renderer};

fn gems(args: &[&str]) -> Output {
    let out = Command::new(env!("CARGO_BIN_EXE_gems"))
        .args(args)
        .env("RUST_LOG", "warn")
        .output()
        .expect("the gems binary runs");
    assert!(
        out.status.success(),
        "gems {args:?} failed:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

#[test]
fn trained_scene_viewer_and_exports() {
    assert!(
        browser::find_chromium().is_some(),
        "headless Chromium is needed for the viewer test: install Debian's `chromium` package \
         (apt-get install chromium) or set GEMS_CHROMIUM to a Chromium/Chrome binary"
    );
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let scene = dir.join("scene");
    let out = dir.join("run");
    let s = |p: &Path| p.to_str().unwrap().to_owned();
    gems(&["synth", "--preset", "tiny", "-o", &s(&scene)]);
    gems(&[
        "train",
        &s(&scene),
        "-o",
        &s(&out),
        "--init",
        "gt",
        "--steps",
        "60",
    ]);

    let report = std::fs::read_to_string(out.join("report.html")).unwrap();
    assert!(report.contains("id=\"gems-viewer\"") && report.contains("Gaussians shown"));
    let page = out.join("viewer.html");
    assert!(page.is_file());

    let trained = gems_train::TrainOutput::load(&out).unwrap();
    // Headless Chromium windows are at least 500 px wide: a window k times the image, where the
    // viewer scales the camera's intrinsics by k, compared with gems' render of that camera.
    let mut renderer = Renderer::new();
    let mut shots = Vec::new();
    for v in trained.views.iter().take(2) {
        let mut cam = gems_splat::Camera::from_c2w(&v.intrinsics, &(&v.mid_c2w).into());
        let k = 500u32.div_ceil(cam.width).max(1);
        for f in [&mut cam.fx, &mut cam.fy, &mut cam.cx, &mut cam.cy] {
            *f *= k as f32;
        }
        cam.width *= k;
        cam.height *= k;
        let want = renderer
            .forward(
                &trained.gaussians,
                &[cam],
                &[[0.0; 3]],
                &RenderSettings::default(),
            )
            .unwrap();
        let want: Vec<f32> = want.rgb.iter().map(|x| x.clamp(0.0, 1.0)).collect();
        let url = browser::file_url(
            &page,
            &format!("camera={}", browser::encode_component(&v.name)),
        )
        .unwrap();
        let png = dir.join(format!("shot{}.png", shots.len()));
        browser::screenshot(&url, cam.width, cam.height, &png, dir).unwrap();
        let shot = gems_data::load_image(&png).unwrap();
        assert_eq!((shot.width, shot.height), (cam.width, cam.height));
        let (h, w) = (cam.height as usize, cam.width as usize);
        let p = gems_metrics::psnr(&shot.data, &want, h, w).unwrap();
        eprintln!("{}: viewer vs gems render {p:.2} dB", v.name);
        assert!(p >= 25.0, "{}: PSNR {p:.2} dB < 25 dB", v.name);
        shots.push((shot.data, h, w));
    }
    let between = gems_metrics::psnr(&shots[0].0, &shots[1].0, shots[0].1, shots[0].2).unwrap();
    assert!(
        between < 30.0,
        "two views gave the same image ({between:.2} dB)"
    );

    // Exports: PLY round-trips the Gaussians, `.splat` is 32 bytes per Gaussian.
    let n = trained.gaussians.len();
    gems(&[
        "export",
        &s(&out),
        "--format",
        "ply",
        "-o",
        &s(&dir.join("g.ply")),
    ]);
    assert_eq!(
        gems_splat::ply::read_ply(dir.join("g.ply")).unwrap().len(),
        n
    );
    gems(&[
        "export",
        &s(&out),
        "--format",
        "splat",
        "-o",
        &s(&dir.join("g.splat")),
    ]);
    assert_eq!(
        std::fs::metadata(dir.join("g.splat")).unwrap().len(),
        32 * n as u64
    );
}

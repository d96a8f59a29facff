//! What the `gems` binary's integration tests share: running the binary, and the scenes they
//! run it on (generated, or the real layouts rebuilt from generated ones).
#![allow(dead_code)] // each test file uses its own part of this module

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

pub fn gems(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_gems"))
        .args(args)
        .env("RUST_LOG", "warn")
        .output()
        .expect("the gems binary runs")
}

pub fn ok(out: &Output) {
    assert!(
        out.status.success(),
        "gems failed:\nstdout: {}\nstderr: {}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}

pub fn tiny_scene(dir: &Path) -> PathBuf {
    let scene = dir.join("scene");
    ok(&gems(&[
        "synth",
        "--preset",
        "tiny",
        "-o",
        scene.to_str().unwrap(),
    ]));
    scene
}

/// Every file and folder under `root` with its content hash (FNV-1a), to prove a command left a
/// scene exactly as it was.
pub fn snapshot(root: &Path) -> std::collections::BTreeMap<PathBuf, u64> {
    let mut out = std::collections::BTreeMap::new();
    let mut stack = vec![root.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p.clone());
                out.insert(p, 0);
            } else {
                let h = std::fs::read(&p)
                    .unwrap()
                    .iter()
                    .fold(0xcbf2_9ce4_8422_2325u64, |h, &b| {
                        (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3)
                    });
                out.insert(p, h);
            }
        }
    }
    out
}

/// Makes every file and folder under `root` read-only (a no-op for root, which is why the
/// snapshot comparison is the real proof).
pub fn read_only(root: &Path) {
    use std::os::unix::fs::PermissionsExt;
    for (p, _) in snapshot(root) {
        let mode = if p.is_dir() { 0o555 } else { 0o444 };
        std::fs::set_permissions(&p, std::fs::Permissions::from_mode(mode)).unwrap();
    }
    std::fs::set_permissions(root, std::fs::Permissions::from_mode(0o555)).unwrap();
}

pub fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

pub fn stdout(out: &Output) -> String {
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// A Deblur-NeRF real scene as redistributed, made from a generated one at 4× the training size:
/// JPG `images/`, PNG `images_4/` with the same stems, `poses_bounds.npy`, `sparse/0` (naming the
/// PNGs, as `Dojizz/NGP-Deblur-NeRF:blurball/sparse/0` does) and `hold=7`.
pub fn deblur_nerf_real(dir: &Path) -> PathBuf {
    let synth = dir.join("synth");
    ok(&gems(&[
        "synth",
        "--preset",
        "tiny",
        "--width",
        "192",
        "--height",
        "128",
        "--no-events",
        "-o",
        s(&synth),
    ]));
    let real = dir.join("blurball");
    for e in std::fs::read_dir(synth.join("images")).unwrap() {
        let p = e.unwrap().path();
        let stem = p.file_stem().unwrap().to_str().unwrap().to_owned();
        let img = gems_data::load_image(&p).unwrap();
        gems_data::image::save_image_auto(&real.join(format!("images/{stem}.jpg")), &img).unwrap();
        let small = gems_data::image::downscale_area(&img, 48, 32);
        gems_data::save_png(&real.join(format!("images_4/{stem}.png")), &small).unwrap();
    }
    std::fs::copy(
        synth.join("poses_bounds.npy"),
        real.join("poses_bounds.npy"),
    )
    .unwrap();
    let model = gems_data::colmap::read_model(&synth.join("gt/sparse/0")).unwrap();
    assert!(model.images.iter().all(|im| im.name.ends_with(".png")));
    gems_data::colmap::write_model(
        &real.join("sparse/0"),
        &model,
        gems_data::colmap::ModelFormat::Binary,
    )
    .unwrap();
    gems_data::write_hold_marker(&real, 7).unwrap();
    real
}

/// A short MP4 of a generated scene's blurry frames, made with ffmpeg (which `.ci/run`
/// installs).
pub fn clip_of(scene: &Path, out: &Path) {
    let status = Command::new("ffmpeg")
        .args(["-v", "error", "-y", "-framerate", "8", "-i"])
        .arg(scene.join("images/%03d.png"))
        .args(["-c:v", "libx264", "-pix_fmt", "yuv420p"])
        .arg(out)
        .status()
        .expect("ffmpeg is installed (.ci/run installs it)");
    assert!(status.success());
}

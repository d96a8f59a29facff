//! Every command in the README's `sh` blocks, run as written, in order, in one working folder
//! that holds what the README names: `my_photos/` (a folder of blurry photos), `clip.mp4` (a
//! video of them, made with ffmpeg), `blurball/` (a Deblur-NeRF real scene rebuilt from a
//! generated one) and `configs/` (the repository's). Training is cut to a few steps and the
//! fly-through to a few frames, appended to the command; nothing else is changed. The test
//! command itself (`scripts/test`) is what CI runs (`.ci/run`), so it is checked to be that.

mod common;

use common::{clip_of, deblur_nerf_real, ok, read_only, s, snapshot, tiny_scene};
use std::path::{Path, PathBuf};
use std::process::Command;

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// The commands of the README's `sh` blocks, comments stripped.
fn readme_commands() -> Vec<String> {
    let readme = std::fs::read_to_string(repo().join("README.md")).unwrap();
    let mut commands = Vec::new();
    let mut in_sh = false;
    for line in readme.lines() {
        if line.starts_with("```") {
            in_sh = !in_sh && line.trim_start_matches('`') == "sh";
            continue;
        }
        if in_sh {
            let command = line.split(" #").next().unwrap_or("").trim();
            if !command.is_empty() && !command.starts_with('#') {
                commands.push(command.to_owned());
            }
        }
    }
    commands
}

/// `command`'s words with a short schedule appended where it trains or renders a path.
fn quick(command: &str) -> Vec<String> {
    let mut words: Vec<String> = command.split_whitespace().map(str::to_owned).collect();
    let sub = words.get(1).cloned().unwrap_or_default();
    if ["train", "bench-real", "bench-quality", "demo"].contains(&sub.as_str()) {
        words.extend(["--steps".into(), "5".into()]);
    }
    if sub == "render" && words.iter().any(|w| w == "--path") {
        words.extend(["--frames".into(), "4".into()]);
    }
    words
}

#[test]
fn every_readme_command_runs() {
    let commands = readme_commands();
    assert_eq!(
        commands[..2],
        ["cargo run --release -- demo", "scripts/test"],
        "the two commands on a fresh clone come first"
    );
    let ci = std::fs::read_to_string(repo().join(".ci/run")).unwrap();
    assert!(
        ci.lines().any(|l| l.trim() == "scripts/test"),
        ".ci/run runs the README's test command"
    );

    let dir = tempfile::tempdir().unwrap();
    let work = dir.path().join("work");
    std::fs::create_dir_all(&work).unwrap();
    let generated = dir.path().join("generated");
    let scene = tiny_scene(&generated);
    let photos = work.join("my_photos");
    std::fs::create_dir_all(&photos).unwrap();
    for e in std::fs::read_dir(scene.join("images")).unwrap() {
        let p = e.unwrap().path();
        std::fs::copy(&p, photos.join(p.file_name().unwrap())).unwrap();
    }
    clip_of(&scene, &work.join("clip.mp4"));
    let blurball = deblur_nerf_real(&generated);
    copy_dir(&blurball, &work.join("blurball"));
    copy_dir(&repo().join("configs"), &work.join("configs"));
    let inputs = ["my_photos", "blurball"].map(|d| work.join(d));
    for d in &inputs {
        read_only(d);
    }
    let before: Vec<_> = inputs.iter().map(|d| snapshot(d)).collect();

    for command in &commands[2..] {
        let words = quick(command);
        assert_eq!(
            words[0], "gems",
            "a README command that is not gems: {command}"
        );
        let out = Command::new(env!("CARGO_BIN_EXE_gems"))
            .args(&words[1..])
            .current_dir(&work)
            .env("RUST_LOG", "warn")
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "README command `{}` failed:\n{}",
            words.join(" "),
            String::from_utf8_lossy(&out.stderr)
        );
    }
    // The first command, as `cargo run` would run it.
    ok(&Command::new(env!("CARGO_BIN_EXE_gems"))
        .args(quick("gems demo").iter().skip(1))
        .current_dir(&work)
        .env("RUST_LOG", "warn")
        .output()
        .unwrap());
    assert!(work.join("gems-demo/train/report.html").is_file());

    // What the README says comes out, does.
    for file in [
        "runs/photos/report.html",
        "runs/photos/point_cloud.ply",
        "runs/photos/metrics.json",
        "runs/photos/gems.log",
        "runs/photos/export_colmap/sparse/0/images.bin",
        "runs/photos/export_nerfstudio/transforms.json",
        "runs/clip/orbit.mp4",
        "runs/blurball/report.html",
    ] {
        assert!(work.join(file).is_file(), "{file} missing");
    }
    assert!(work.join("runs/photos/bursts").is_dir());
    for (d, b) in inputs.iter().zip(&before) {
        assert_eq!(&snapshot(d), b, "a README command wrote into {}", s(d));
    }
}

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap() {
        let p = e.unwrap().path();
        let dst = to.join(p.file_name().unwrap());
        if p.is_dir() {
            copy_dir(&p, &dst);
        } else {
            std::fs::copy(&p, &dst).unwrap();
        }
    }
}

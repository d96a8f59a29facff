//! The `gems` binary end to end on a tiny generated scene: training from a COLMAP run as a
//! subprocess (`--init colmap-cli`, with and without events), the report's EDI column, and one
//! clear error (no panic) for bad input.
//!
//! COLMAP itself is not installed in CI, so `--colmap-binary` points at a small shell script that
//! behaves like COLMAP's command line: it accepts the three steps and its `mapper` writes a model
//! (the scene's ground-truth model, copied) into `--output_path/0`. Everything on the gems side —
//! the subprocess calls, the import of the largest model, training and evaluation from it — is
//! the real code path.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn gems(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_gems"))
        .args(args)
        .env("RUST_LOG", "warn")
        .output()
        .expect("the gems binary runs")
}

fn ok(out: &Output) {
    assert!(
        out.status.success(),
        "gems failed:\nstdout: {}\nstderr: {}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}

/// `gems train <scene> -o <out> <extra…>`.
fn train(scene: &Path, out: &Path, extra: &[&str]) -> Output {
    let mut args = vec![
        "train",
        scene.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    gems(&args)
}

fn tiny_scene(dir: &Path) -> PathBuf {
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

/// A stand-in for the `colmap` executable whose mapper "reconstructs" `model`.
fn fake_colmap(dir: &Path, model: &Path) -> PathBuf {
    use std::os::unix::fs::PermissionsExt;
    let path = dir.join("fake-colmap");
    let script = format!(
        "#!/bin/sh\nstep=\"$1\"\nshift\nout=\"\"\nwhile [ $# -gt 0 ]; do\n  if [ \"$1\" = --output_path ]; then out=\"$2\"; fi\n  shift\ndone\ncase \"$step\" in\n  feature_extractor|exhaustive_matcher) exit 0 ;;\n  mapper) mkdir -p \"$out/0\" && cp '{}'/* \"$out/0/\" ;;\n  *) echo \"unknown command $step\" >&2; exit 1 ;;\nesac\n",
        model.display()
    );
    std::fs::write(&path, script).unwrap();
    std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o755)).unwrap();
    path
}

#[test]
fn train_from_colmap_cli_with_and_without_events() {
    let dir = tempfile::tempdir().unwrap();
    let scene = tiny_scene(dir.path());
    let colmap = fake_colmap(dir.path(), &scene.join("gt/sparse/0"));

    let out = dir.path().join("run");
    ok(&train(
        &scene,
        &out,
        &[
            "--init",
            "colmap-cli",
            "--colmap-binary",
            colmap.to_str().unwrap(),
            "--steps",
            "30",
        ],
    ));
    assert!(out.join("colmap/sparse/0/images.bin").is_file());
    let metrics: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("metrics.json")).unwrap()).unwrap();
    assert!(metrics["deblur"]["psnr"].as_f64().unwrap() > 10.0);
    let html = std::fs::read_to_string(out.join("report.html")).unwrap();
    assert!(!html.contains("EDI from events"));

    // --resume reuses the imported model: COLMAP is not run again (here it could not be).
    ok(&train(
        &scene,
        &out,
        &[
            "--init",
            "colmap-cli",
            "--colmap-binary",
            "/nonexistent/colmap",
            "--steps",
            "30",
            "--resume",
        ],
    ));

    // With events: EDI images feed COLMAP, the report shows them in their own column.
    let out = dir.path().join("run_events");
    ok(&train(
        &scene,
        &out,
        &[
            "--init",
            "colmap-cli",
            "--colmap-binary",
            colmap.to_str().unwrap(),
            "--events",
            "--steps",
            "30",
        ],
    ));
    let n_edi = std::fs::read_dir(out.join("edi/images")).unwrap().count();
    assert_eq!(
        n_edi,
        std::fs::read_dir(scene.join("images")).unwrap().count()
    );
    let html = std::fs::read_to_string(out.join("report.html")).unwrap();
    assert!(html.contains("EDI from events") && html.contains("EDI PSNR"));
    let grid = gems_data::load_image(&out.join("report/grid.png")).unwrap();
    let w = gems_data::load_image(
        &scene.join("images").join(
            std::fs::read_dir(scene.join("images"))
                .unwrap()
                .next()
                .unwrap()
                .unwrap()
                .file_name(),
        ),
    )
    .unwrap()
    .width;
    assert_eq!(grid.width, 4 * w + 12, "four columns with events");
}

#[test]
fn bad_input_gives_one_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("no-such-scene");
    let out = train(&missing, &dir.path().join("run"), &["--steps", "5"]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("no-such-scene") && !err.contains("panicked"),
        "{err}"
    );

    // A COLMAP that is not installed: the error names the executable.
    let scene = tiny_scene(dir.path());
    let out = train(
        &scene,
        &dir.path().join("run2"),
        &[
            "--init",
            "colmap-cli",
            "--colmap-binary",
            "/nonexistent/colmap",
            "--steps",
            "5",
        ],
    );
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("/nonexistent/colmap") && !err.contains("panicked"),
        "{err}"
    );

    // --events needs an initialiser that reads the deblurred images.
    let out = train(
        &scene,
        &dir.path().join("run3"),
        &["--init", "gt", "--events"],
    );
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("--events") && !err.contains("panicked"),
        "{err}"
    );
}

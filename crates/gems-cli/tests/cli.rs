//! The `gems` binary end to end on a tiny generated scene: training from a COLMAP run as a
//! subprocess (`--init colmap-cli`, with and without events), the report's EDI column, and one
//! clear error (no panic) for bad input.
//!
//! COLMAP itself is not installed in CI, so `--colmap-binary` points at a small shell script that
//! behaves like COLMAP's command line: it accepts the three steps and its `mapper` writes a model
//! (the scene's ground-truth model, copied) into `--output_path/0`. Everything on the gems side —
//! the subprocess calls, the import of the largest model, training and evaluation from it — is
//! the real code path.

mod common;

use common::{clip_of, deblur_nerf_real, gems, ok, read_only, s, snapshot, stdout, tiny_scene};
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// The command failed with one clear error that mentions `needle`, not a panic.
fn fails_clearly(out: &Output, needle: &str) {
    assert!(
        !out.status.success(),
        "expected a failure mentioning {needle}"
    );
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains(needle) && !err.contains("panicked"), "{err}");
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
    fails_clearly(&out, "no-such-scene");

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
    fails_clearly(&out, "/nonexistent/colmap");

    // --events needs an initialiser that reads the deblurred images.
    let out = train(
        &scene,
        &dir.path().join("run3"),
        &["--init", "gt", "--events"],
    );
    fails_clearly(&out, "--events");
}

#[test]
fn sfm_tracking_density_flags_reach_the_sfm() {
    let dir = tempfile::tempdir().unwrap();
    let scene = tiny_scene(dir.path());
    let points = |extra: &[&str], name: &str| {
        let out = dir.path().join(name);
        let run = gems(&[&["sfm", s(&scene), "-o", s(&out)], extra].concat());
        ok(&run);
        // "registered 8/8 views, 123 points, …"
        let text = stdout(&run);
        let field = text
            .split(", ")
            .find(|f| f.ends_with(" points"))
            .unwrap_or_else(|| panic!("no point count in {text}"));
        field.trim_end_matches(" points").parse::<usize>().unwrap()
    };
    let default = points(&[], "default");
    let dense = points(
        &["--grid-spacing", "0.02", "--max-query-points", "5000"],
        "dense",
    );
    assert!(
        dense > default,
        "{dense} points densely, {default} by default"
    );

    let bad = gems(&[
        "sfm",
        s(&scene),
        "-o",
        s(&dir.path().join("bad")),
        "--grid-spacing",
        "0.9",
    ]);
    fails_clearly(&bad, "grid_spacing");

    // A focal under a prior is refined away from the given one; a held one is kept.
    let focal = |extra: &[&str], name: &str| {
        let out = dir.path().join(name);
        ok(&gems(&[&["sfm", s(&scene), "-o", s(&out)], extra].concat()));
        sfm_report(&out)["focal"].as_f64().unwrap()
    };
    assert_eq!(focal(&["--focal", "80"], "held"), 80.0);
    let refined = focal(&["--focal", "80", "--focal-prior", "0.05"], "prior");
    assert!(
        refined != 80.0 && (refined / 80.0 - 1.0).abs() < 0.5,
        "{refined}"
    );
    let bad = gems(&[
        "sfm",
        s(&scene),
        "-o",
        s(&dir.path().join("bad-prior")),
        "--focal-prior=-0.1",
    ]);
    fails_clearly(&bad, "focal_prior");

    // Coarse to fine off keeps the working level's model; capture order on is reported.
    let report = |extra: &[&str], name: &str| {
        let out = dir.path().join(name);
        ok(&gems(&[&["sfm", s(&scene), "-o", s(&out)], extra].concat()));
        sfm_report(&out)
    };
    let coarse = report(&["--refine-max-blur", "0"], "coarse");
    assert_eq!(coarse["final_size"], coarse["working_size"]);
    assert_eq!(coarse["capture_order"], false);
    let ordered = report(&["--capture-order", "ordered"], "ordered");
    assert_eq!(ordered["capture_order"], true);
}

#[test]
fn deblur_nerf_real_trains_read_only_with_colmap_at_downscale_4() {
    let dir = tempfile::tempdir().unwrap();
    let real = deblur_nerf_real(dir.path());
    read_only(&real);
    let before = snapshot(&real);
    let out = dir.path().join("run");

    let info = gems(&["info", s(&real)]);
    ok(&info);
    let text = stdout(&info);
    assert!(
        text.contains("Deblur-NeRF / LLFF") && text.contains("sparse/0: COLMAP model"),
        "{text}"
    );
    assert!(
        text.contains("views posed by it, images matched by file stem"),
        "{text}"
    );
    assert!(
        text.contains("poses_bounds.npy: read and checked"),
        "{text}"
    );
    let info = gems(&["info", s(&real), "--downscale", "4", "--check"]);
    ok(&info);
    let text = stdout(&info);
    assert!(
        text.contains("resolution 48x32 (downscale 4)") && text.contains("check      ok"),
        "{text}"
    );

    ok(&train(
        &real,
        &out,
        &[
            "--init",
            "colmap",
            "--downscale",
            "4",
            "--steps",
            "10",
            "--no-eval",
        ],
    ));
    assert!(out.join("point_cloud.ply").is_file());
    let trained = gems_train::TrainOutput::load(&out).unwrap();
    let k = &trained.views[0].intrinsics;
    assert_eq!((k.width, k.height), (48, 32), "trained on images_4/");
    assert_eq!(trained.views[0].name, "001.jpg");
    assert!(
        !out.join("cache").exists(),
        "the scene's own images_4/ is used, no copy is made"
    );
    ok(&gems(&[
        "eval",
        s(&out),
        "--scene",
        s(&real),
        "--refine-steps",
        "2",
    ]));
    assert!(out.join("metrics.json").is_file());
    ok(&gems(&[
        "render",
        s(&out.join("point_cloud.ply")),
        "-o",
        s(&out.join("view.png")),
        "--colmap",
        s(&real.join("sparse/0")),
        "--image",
        "001.png",
    ]));
    ok(&gems(&["sfm", s(&real), "-o", s(&dir.path().join("sfm"))]));
    // No events: one clear error, still nothing written into the scene.
    let e = gems(&["edi", s(&real), "-o", s(&dir.path().join("edi"))]);
    assert!(!e.status.success());
    assert_eq!(snapshot(&real), before, "a command wrote into the scene");
}

#[test]
fn every_layout_every_command_leaves_the_scene_untouched() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let gems_scene = tiny_scene(d);

    // E2NeRF/BeNeRF-style: LLFF poses, events and exposure windows in seconds (text).
    let e2 = d.join("e2nerf");
    std::fs::create_dir_all(e2.join("events")).unwrap();
    for e in std::fs::read_dir(gems_scene.join("images")).unwrap() {
        let p = e.unwrap().path();
        std::fs::create_dir_all(e2.join("images")).unwrap();
        std::fs::copy(&p, e2.join("images").join(p.file_name().unwrap())).unwrap();
    }
    std::fs::copy(
        gems_scene.join("poses_bounds.npy"),
        e2.join("poses_bounds.npy"),
    )
    .unwrap();
    let ev = gems_events::read_events(
        &gems_scene.join("events.npz"),
        &gems_events::ReadOptions::default(),
    )
    .unwrap();
    gems_events::write_events_text(&e2.join("events/events.txt"), &ev).unwrap();
    for name in ["exposure_start_ts.txt", "exposure_end_ts.txt"] {
        let us = std::fs::read_to_string(gems_scene.join(name)).unwrap();
        let secs: String = us
            .lines()
            .map(|l| format!("{:.6}\n", l.trim().parse::<f64>().unwrap() * 1e-6))
            .collect();
        std::fs::write(e2.join("events").join(name), secs).unwrap();
    }

    // A plain folder of video frames.
    let frames = d.join("frames");
    std::fs::create_dir_all(&frames).unwrap();
    for (i, e) in std::fs::read_dir(gems_scene.join("images"))
        .unwrap()
        .enumerate()
    {
        std::fs::copy(e.unwrap().path(), frames.join(format!("{:04}.png", i + 1))).unwrap();
    }

    // nerfstudio: transforms.json with the ground-truth poses.
    let ns = d.join("nerfstudio");
    let gt = gems_data::open_scene(&gems_scene, &gems_data::OpenOptions::default()).unwrap();
    let mut t = gems_data::nerfstudio::Transforms::default();
    for v in &gt.views {
        std::fs::create_dir_all(ns.join("images")).unwrap();
        std::fs::copy(&v.image, ns.join("images").join(&v.name)).unwrap();
        t.frames.push(gems_data::nerfstudio::Frame {
            file_path: format!("images/{}", v.name),
            pose: v.gt_pose.unwrap(),
            subframe_poses: Vec::new(),
            camera: gems_data::nerfstudio::CameraSpec::Pinhole(v.intrinsics.unwrap()),
            split: None,
        });
    }
    gems_data::nerfstudio::write_transforms(&ns.join("transforms.json"), &t).unwrap();

    // ExBluRF: LLFF poses with ground-truth sub-frames, no manifest.
    let copy = |from: &Path, to: &Path, keep: &dyn Fn(usize) -> bool| {
        std::fs::create_dir_all(to).unwrap();
        let mut files: Vec<PathBuf> = std::fs::read_dir(from)
            .unwrap()
            .map(|e| e.unwrap().path())
            .collect();
        files.sort();
        for (_, f) in files.iter().enumerate().filter(|(i, _)| keep(*i)) {
            std::fs::copy(f, to.join(f.file_name().unwrap())).unwrap();
        }
    };
    let ex = d.join("exblurf");
    copy(&gems_scene.join("images"), &ex.join("images"), &|_| true);
    for f in ["poses_bounds.npy", "poses_bounds_subframes.npy"] {
        std::fs::copy(gems_scene.join(f), ex.join(f)).unwrap();
    }
    // BAD-Gaussians: images_test/ for the training views only, sparse/0, hold=4.
    let bad = d.join("bad");
    copy(&gems_scene.join("images"), &bad.join("images"), &|_| true);
    copy(
        &gems_scene.join("images_test"),
        &bad.join("images_test"),
        &|i| i % 4 != 0,
    );
    copy(
        &gems_scene.join("gt/sparse/0"),
        &bad.join("sparse/0"),
        &|_| true,
    );
    gems_data::write_hold_marker(&bad, 4).unwrap();
    // EBAD-NeRF: pose_bounds.npy, sharp images apart in images_gt_blur/ and images_gt_novel/.
    let ebad = d.join("ebad");
    copy(&gems_scene.join("images"), &ebad.join("images"), &|_| true);
    copy(
        &gems_scene.join("images_test"),
        &ebad.join("images_gt_blur"),
        &|i| i % 4 != 0,
    );
    copy(
        &gems_scene.join("images_test"),
        &ebad.join("images_gt_novel"),
        &|i| i % 4 == 0,
    );
    std::fs::copy(
        gems_scene.join("poses_bounds.npy"),
        ebad.join("pose_bounds.npy"),
    )
    .unwrap();
    gems_data::write_hold_marker(&ebad, 4).unwrap();

    // E2NeRF synthetic: transform_{train,test}.json (no file_path; lists of matrices along each
    // exposure), train/r_<2i>.png blurry with the odd frames missing, test/r_<i>.png sharp.
    let e2s = d.join("e2nerf_synthetic");
    let mut train_t = gems_data::nerfstudio::Transforms::default();
    let mut test_t = gems_data::nerfstudio::Transforms::default();
    for v in &gt.views {
        let subs = v.gt_subframe_poses.clone().unwrap();
        let frame = |pose, subframe_poses| gems_data::nerfstudio::Frame {
            file_path: String::new(),
            pose,
            subframe_poses,
            camera: gems_data::nerfstudio::CameraSpec::Pinhole(v.intrinsics.unwrap()),
            split: None,
        };
        if v.split == gems_data::Split::Train {
            let i = 2 * train_t.frames.len();
            std::fs::create_dir_all(e2s.join("train")).unwrap();
            std::fs::copy(&v.image, e2s.join(format!("train/r_{i}.png"))).unwrap();
            train_t
                .frames
                .push(frame(subs[subs.len() / 2], subs.clone()));
            train_t.frames.push(frame(subs[subs.len() / 2], subs));
        } else {
            let i = test_t.frames.len();
            std::fs::create_dir_all(e2s.join("test")).unwrap();
            std::fs::copy(
                v.sharp_gt.as_ref().unwrap(),
                e2s.join(format!("test/r_{i}.png")),
            )
            .unwrap();
            test_t
                .frames
                .push(frame(v.gt_pose.unwrap(), vec![v.gt_pose.unwrap(); 3]));
        }
    }
    for (name, t) in [
        ("transform_train.json", &train_t),
        ("transform_test.json", &test_t),
    ] {
        let text = gems_data::nerfstudio::transforms_to_json(t).replace("\"file_path\": \"\",", "");
        assert!(!text.contains("file_path"));
        std::fs::write(e2s.join(name), text).unwrap();
    }

    let scenes = [&gems_scene, &e2, &frames, &ns, &ex, &bad, &ebad, &e2s];
    for sc in scenes {
        read_only(sc);
    }
    let before: Vec<_> = scenes.iter().map(|sc| snapshot(sc)).collect();
    let o = |name: &str| d.join("out").join(name);

    for sc in scenes {
        ok(&gems(&["info", s(sc)]));
        ok(&gems(&["info", s(sc), "--check"]));
    }
    let text = stdout(&gems(&["info", s(&e2)]));
    assert!(
        text.contains("E2NeRF") && text.contains("exposure windows (times in s)"),
        "{text}"
    );
    // EDI on both event scenes (the seconds case included).
    ok(&gems(&["edi", s(&gems_scene), "-o", s(&o("edi_gems"))]));
    ok(&gems(&["edi", s(&e2), "-o", s(&o("edi_e2"))]));
    // SfM and a short training on the photos folder (built-in SfM), the generated scene (ground
    // truth, at half size: copies go to the output's cache) and nerfstudio.
    ok(&gems(&["sfm", s(&frames), "-o", s(&o("sfm_frames"))]));
    ok(&train(
        &frames,
        &o("train_frames"),
        &["--steps", "5", "--no-eval"],
    ));
    ok(&train(
        &gems_scene,
        &o("train_gems"),
        &["--init", "gt", "--steps", "5", "--downscale", "2"],
    ));
    assert!(o("train_gems").join("cache").is_dir());
    ok(&gems(&[
        "eval",
        s(&o("train_gems")),
        "--scene",
        s(&gems_scene),
        "--refine-steps",
        "2",
    ]));
    ok(&gems(&[
        "render",
        s(&o("train_gems").join("point_cloud.ply")),
        "-o",
        s(&o("view.png")),
        "--colmap",
        s(&gems_scene.join("gt/sparse/0")),
        "--image",
        "001.png",
    ]));
    ok(&gems(&["sfm", s(&ns), "-o", s(&o("sfm_ns"))]));
    ok(&gems(&["sfm", s(&ex), "-o", s(&o("sfm_ex"))]));
    ok(&train(
        &bad,
        &o("train_bad"),
        &[
            "--init",
            "colmap",
            "--steps",
            "5",
            "--downscale",
            "2",
            "--no-eval",
        ],
    ));
    ok(&train(
        &e2s,
        &o("train_e2s"),
        &["--init", "gt", "--steps", "5", "--no-eval"],
    ));
    ok(&gems(&[
        "eval",
        s(&o("train_e2s")),
        "--scene",
        s(&e2s),
        "--refine-steps",
        "2",
    ]));
    let metrics = std::fs::read_to_string(o("train_e2s").join("metrics.json")).unwrap();
    assert!(
        metrics.contains("\"nvs\": {") && metrics.contains("\"ape\": {"),
        "{metrics}"
    );
    for (sc, want) in [
        (&e2s, "E2NeRF synthetic"),
        (&ex, "ExBluRF"),
        (&bad, "BAD-Gaussians / PRISM3D"),
        (&ebad, "EBAD-NeRF"),
    ] {
        let text = stdout(&gems(&["info", s(sc)]));
        assert!(text.contains(want), "{text}");
    }
    let text = stdout(&gems(&["info", s(&ebad)]));
    assert!(text.contains("6 deblur-eval, 2 novel-view eval"), "{text}");
    for (sc, b) in scenes.iter().zip(&before) {
        assert_eq!(&snapshot(sc), b, "a command wrote into {}", sc.display());
    }
}

#[test]
fn info_check_reports_each_problem_and_train_refuses_first() {
    let dir = tempfile::tempdir().unwrap();
    let scene = tiny_scene(dir.path());
    // A corrupt PNG whose header still reads: only decoding finds it.
    let p = scene.join("images/003.png");
    let bytes = std::fs::read(&p).unwrap();
    std::fs::write(&p, &bytes[..bytes.len() / 2]).unwrap();
    ok(&gems(&["info", s(&scene)]));
    let out = gems(&["info", s(&scene), "--check"]);
    assert!(!out.status.success());
    let text = stdout(&out);
    let lines: Vec<&str> = text.lines().filter(|l| l.starts_with("problem")).collect();
    assert_eq!(lines.len(), 1, "{text}");
    assert!(lines[0].contains("003.png"), "{text}");
    // Training validates the same way before any work (no SfM, nothing trained).
    let run = dir.path().join("run");
    let out = train(&scene, &run, &["--init", "gt", "--steps", "5"]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("003.png") && err.contains("problem"), "{err}");
    assert!(!run.join("config.toml").exists());
    // No colour codes when stderr is not a terminal (a log file, a pipe).
    let logged = Command::new(env!("CARGO_BIN_EXE_gems"))
        .args(["info", s(&scene)])
        .env("RUST_LOG", "debug")
        .output()
        .unwrap();
    let log = String::from_utf8_lossy(&logged.stderr);
    assert!(
        log.contains("opened scene") && !log.contains('\u{1b}'),
        "{log}"
    );
    // Each cause once: an image whose header cannot be read fails the open with an error whose
    // message already holds its source.
    std::fs::write(scene.join("images/000.png"), b"\x89PNG\r\n\x1a\nbroken").unwrap();
    let cause = std::error::Error::source(
        &gems_data::load_image(&scene.join("images/000.png")).unwrap_err(),
    )
    .unwrap()
    .to_string();
    let out = gems(&["info", s(&scene)]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    let line = err.lines().find(|l| l.starts_with("error:")).unwrap();
    assert!(line.contains("000.png"), "{line}");
    assert_eq!(
        line.matches(cause.as_str()).count(),
        1,
        "a cause is repeated: {line}"
    );
}

/// The `sfm_report.json` that `gems sfm -o out` wrote.
fn sfm_report(out: &Path) -> serde_json::Value {
    serde_json::from_slice(&std::fs::read(out.join("sfm_report.json")).unwrap()).unwrap()
}

#[test]
fn exif_focal_is_used_and_reported() {
    let dir = tempfile::tempdir().unwrap();
    let scene = tiny_scene(dir.path());
    let photos = dir.path().join("photos");
    std::fs::create_dir_all(&photos).unwrap();
    // A phone's EXIF: only the 35 mm equivalent focal, 30 mm → 30 / 36 · 96 px = 80 px.
    let field = exif::Field {
        tag: exif::Tag::FocalLengthIn35mmFilm,
        ifd_num: exif::In::PRIMARY,
        value: exif::Value::Short(vec![30]),
    };
    let mut writer = exif::experimental::Writer::new();
    writer.push_field(&field);
    let mut tiff = std::io::Cursor::new(Vec::new());
    writer.write(&mut tiff, false).unwrap();
    let tiff = tiff.into_inner();
    let mut app1 = vec![0xFF, 0xE1];
    app1.extend_from_slice(&u16::try_from(8 + tiff.len()).unwrap().to_be_bytes());
    app1.extend_from_slice(b"Exif\0\0");
    app1.extend_from_slice(&tiff);
    for e in std::fs::read_dir(scene.join("images")).unwrap() {
        let p = e.unwrap().path();
        let img = gems_data::load_image(&p).unwrap();
        let jpg = photos.join(p.with_extension("jpg").file_name().unwrap());
        gems_data::image::save_image_auto(&jpg, &img).unwrap();
        let bytes = std::fs::read(&jpg).unwrap();
        let mut out = bytes[..2].to_vec();
        out.extend_from_slice(&app1);
        out.extend_from_slice(&bytes[2..]);
        std::fs::write(&jpg, out).unwrap();
    }
    let text = stdout(&gems(&["info", s(&photos)]));
    assert!(
        text.contains("focal 80.0 px for the SfM from EXIF FocalLengthIn35mmFilm 30 mm"),
        "{text}"
    );
    let out = gems(&["sfm", s(&photos), "-o", s(&dir.path().join("sfm"))]);
    ok(&out);
    assert!(
        stdout(&out).contains("focal 80.0 px from EXIF"),
        "{}",
        stdout(&out)
    );
    let report = sfm_report(&dir.path().join("sfm"));
    // Refined under the EXIF prior (2 %): moved, but not far.
    let refined = report["focal"].as_f64().unwrap();
    assert!(
        refined != 80.0 && (refined / 80.0 - 1.0).abs() < 0.1,
        "{report}"
    );
    // --focal-prior 0 holds it.
    let out = gems(&[
        "sfm",
        s(&photos),
        "-o",
        s(&dir.path().join("sfm-held")),
        "--focal-prior",
        "0",
    ]);
    ok(&out);
    let report = sfm_report(&dir.path().join("sfm-held"));
    assert_eq!(report["focal"].as_f64(), Some(80.0), "{report}");
    // --focal overrides it.
    let out = gems(&[
        "sfm",
        s(&photos),
        "-o",
        s(&dir.path().join("sfm2")),
        "--focal",
        "83.0",
    ]);
    ok(&out);
    assert!(!stdout(&out).contains("from EXIF"));
}

/// `--device gpu` end to end on whatever adapter there is (Mesa lavapipe on CI): train,
/// evaluate and render print the adapter and succeed; without an adapter it is one clear
/// error. (The full `gems demo --device gpu` also completes on lavapipe, in minutes: too slow
/// for this suite, so its stages are exercised here at a reduced size.)
#[test]
fn device_gpu_trains_evaluates_and_renders() {
    let dir = tempfile::tempdir().unwrap();
    let scene = tiny_scene(dir.path());
    let run = dir.path().join("run");
    let out = train(
        &scene,
        &run,
        &[
            "--init",
            "gt",
            "--steps",
            "10",
            "--no-eval",
            "--device",
            "gpu",
        ],
    );
    ok(&out);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("device: GPU "), "{stdout}");
    let out = gems(&[
        "eval",
        run.to_str().unwrap(),
        "--scene",
        scene.to_str().unwrap(),
        "--refine-steps",
        "5",
        "--device",
        "gpu",
    ]);
    ok(&out);
    assert!(run.join("metrics.json").is_file());
    let ply = run.join("point_cloud.ply");
    let png = dir.path().join("view.png");
    let render = |backend: &str| {
        Command::new(env!("CARGO_BIN_EXE_gems"))
            .args([
                "render",
                ply.to_str().unwrap(),
                "-o",
                png.to_str().unwrap(),
                "--width",
                "64",
                "--height",
                "48",
                "--cam-pos",
                "0,0,-3",
                "--look-at",
                "0,0,0",
                "--device",
                "gpu",
            ])
            .env("RUST_LOG", "warn")
            .env("WGPU_BACKEND", backend)
            .output()
            .unwrap()
    };
    ok(&render("vulkan"));
    assert!(png.is_file());
    // No backend with an adapter (DX12 is not built on Linux): one clear error.
    if cfg!(target_os = "linux") {
        let out = render("dx12");
        fails_clearly(&out, "--device: no GPU adapter is available");
    }
}

/// `gems bench-quality -o <out>` on the tiny preset's seed 3 for 3 steps, with `extra` arguments.
fn tiny_bench(out: &Path, extra: &[&str]) -> Output {
    let mut args = vec![
        "bench-quality",
        "-o",
        out.to_str().unwrap(),
        "--seeds",
        "3",
        "--preset",
        "tiny",
        "--steps",
        "3",
    ];
    args.extend_from_slice(extra);
    gems(&args)
}

/// `gems bench-quality` on one tiny scene with a few steps: the five rows per seed in both
/// outputs, and a ceiling scene whose images are the sharp frames, without the blurry
/// exposures' events.
#[test]
fn bench_quality_writes_the_five_rows() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("bench");
    ok(&tiny_bench(&out, &[]));
    let table = std::fs::read_to_string(out.join("quality.md")).unwrap();
    let rows: Vec<&str> = table.lines().filter(|l| l.starts_with("| 3 |")).collect();
    assert_eq!(rows.len(), 5, "{table}");
    for (row, name) in rows.iter().zip([
        "blurry input",
        "GeMS, built-in SfM",
        "GeMS, built-in SfM on the sharp frames",
        "GeMS, ground-truth poses",
        "sharp ceiling",
    ]) {
        assert!(row.contains(name) && row.contains(" dB"), "{row}");
    }
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("quality.json")).unwrap()).unwrap();
    let runs = json.as_array().unwrap();
    assert_eq!(runs.len(), 5);
    let (sfm, sharp_sfm, gt) = (1, 2, 3);
    // Started from the ground truth, three steps at the default knot lr (3e-3) move the poses by
    // a few 1e-3 in the normalised frame (×7 in this scene's units): far nearer than the SfM's.
    let ape = |r: usize| runs[r]["ape_rmse"].as_f64().unwrap();
    assert!(
        ape(gt) < 0.05 && ape(gt) < 0.5 * ape(sfm),
        "{} vs {}",
        runs[gt],
        runs[sfm]
    );
    // Each row also gives the APE of the poses it started from: zero from the ground truth,
    // positive from either SfM.
    let ape_init = |r: usize| runs[r]["ape_init_rmse"].as_f64().unwrap();
    assert!(ape_init(gt) < 1e-9 && ape_init(sfm) > 0.0, "{}", runs[sfm]);
    assert!(ape_init(sharp_sfm) > 0.0, "{}", runs[sharp_sfm]);
    // The sharp-frame row trained the blurry images from the model the SfM made of the sharp
    // frames.
    let m = gems_eval::read_metrics_json(&out.join("seed3/gems_sharp_sfm/metrics.json")).unwrap();
    let init = m.run.unwrap().init;
    assert!(
        init.starts_with("the built-in SfM's model") && init.contains("sharp_sfm"),
        "{init}"
    );
    // And the relative rotation error over every pair of views: zero from the ground truth,
    // positive from the SfM.
    let rot_init = |r: usize| runs[r]["rotation_error_init_deg"].as_f64().unwrap();
    assert!(rot_init(gt) < 1e-6 && rot_init(sfm) > 0.0, "{}", runs[sfm]);
    assert!(
        runs[gt]["rotation_error_deg"].as_f64().unwrap() < 1.0,
        "{}",
        runs[gt]
    );
    assert!(rows[gt].contains(" → "), "{}", rows[gt]);
    let sharp = out.join("seed3/sharp");
    let scene = out.join("seed3/scene");
    for e in std::fs::read_dir(scene.join("images_test")).unwrap() {
        let p = e.unwrap().path();
        let name = p.file_name().unwrap();
        assert_eq!(
            std::fs::read(&p).unwrap(),
            std::fs::read(sharp.join("images").join(name)).unwrap()
        );
    }
    assert!(!sharp.join("events.npz").exists() && sharp.join("gt/sparse/0").is_dir());
    // A second run into the same folder is refused.
    let again = gems(&["bench-quality", "-o", s(&out), "--preset", "tiny"]);
    assert!(!again.status.success());
}

/// `gems bench-quality --rows` trains only the rows asked for, in the table's order, and still
/// gives the blurry input when only the ground-truth run is blurry; an unknown row is one clear
/// error.
#[test]
fn bench_quality_runs_only_the_rows_asked_for() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("bench");
    ok(&tiny_bench(&out, &["--rows", "ceiling,gt"]));
    let table = std::fs::read_to_string(out.join("quality.md")).unwrap();
    let rows: Vec<&str> = table.lines().filter(|l| l.starts_with("| 3 |")).collect();
    assert_eq!(rows.len(), 3, "{table}");
    for (row, name) in
        rows.iter()
            .zip(["blurry input", "GeMS, ground-truth poses", "sharp ceiling"])
    {
        assert!(row.contains(name) && row.contains(" dB"), "{row}");
    }
    assert!(!out.join("seed3/gems_sfm").exists());
    assert!(out.join("seed3/ceiling/metrics.json").is_file());
    // The ceiling trains its sharp frames in one pass, whatever the blurry runs do.
    let saved = std::fs::read_to_string(out.join("seed3/ceiling/config.toml")).unwrap();
    assert!(saved.contains("sfm_rerun_fraction = 0.0"), "{saved}");
    assert!(saved.contains("num_virtual_views = 1"), "{saved}");
    let other = dir.path().join("other");
    let bad = gems(&["bench-quality", "-o", s(&other), "--rows", "sfm,sharp"]);
    fails_clearly(&bad, "invalid value 'sharp' for '--rows");
}

#[test]
fn bench_real_runs_the_rows_under_the_protocol_and_reads_finished_rows_back() {
    let dir = tempfile::tempdir().unwrap();
    let real = deblur_nerf_real(dir.path());
    read_only(&real);
    let before = snapshot(&real);
    let out = dir.path().join("bench");
    let args = [
        "bench-real",
        s(&real),
        "-o",
        s(&out),
        "--rows",
        "naive,dataset",
        "--steps",
        "10",
        "--device",
        "cpu",
    ];
    let run = gems(&args);
    ok(&run);
    assert_eq!(
        snapshot(&real),
        before,
        "the benchmark wrote into the scene"
    );
    // Fresh rows have nothing to resume, and are not warned that they have no checkpoint.
    let log = String::from_utf8_lossy(&run.stderr);
    assert!(!log.contains("no checkpoint"), "{log}");
    let table = std::fs::read_to_string(out.join("bench.md")).unwrap();
    assert!(
        table.contains("protocol deblur-nerf-real at ×4, 10 steps"),
        "{table}"
    );
    assert!(
        table.contains("naive 3DGS (n = 1, poses fixed), dataset's poses")
            && table.contains("gems, dataset's poses"),
        "{table}"
    );
    assert!(
        table.contains(
            "the dataset's poses (its COLMAP model), carried into the result's initial frame"
        ),
        "{table}"
    );
    let rows: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("bench.json")).unwrap()).unwrap();
    assert_eq!(rows.as_array().unwrap().len(), 2);
    for r in rows.as_array().unwrap() {
        assert!(r["at_dataset_pose"]["psnr"].as_f64().unwrap() > 5.0, "{r}");
        assert!(r["refined"]["psnr"].as_f64().is_some(), "{r}");
        assert!(r["peak_memory_gib"].as_f64().unwrap() > 0.0, "{r}");
        assert!(r["wall_seconds"].as_f64().unwrap() > 0.0, "{r}");
    }
    for (row, n) in [("naive", 1), ("dataset", 15)] {
        let m = gems_eval::read_metrics_json(&out.join(row).join("metrics.json")).unwrap();
        let what = m.run.unwrap();
        assert_eq!(what.protocol.as_deref(), Some("deblur-nerf-real"));
        assert_eq!((what.downscale, what.hold, what.steps), (4, Some(7), 10));
        assert_eq!(what.virtual_views, n);
        let cfg =
            gems_train::TrainConfig::from_toml_file(&out.join(row).join("config.toml")).unwrap();
        assert_eq!(cfg.pose.optimize, row == "dataset");
        assert!(
            what.init.starts_with("the dataset's COLMAP model"),
            "{}",
            what.init
        );
        assert!(what.init.contains("by file stem"), "{}", what.init);
    }
    // A second run reads the finished rows instead of training again.
    let again = gems(&args);
    ok(&again);
    assert_eq!(
        std::fs::read_to_string(out.join("bench.md")).unwrap(),
        table
    );
    // A bad device is one clear error before anything runs.
    let bad = gems(&["bench-real", s(&real), "-o", s(&out), "--device", "tpu"]);
    fails_clearly(&bad, "--device tpu");
}

#[test]
fn bursts_and_camera_exports_from_a_trained_folder() {
    let dir = tempfile::tempdir().unwrap();
    let scene = tiny_scene(dir.path());
    let out = dir.path().join("run");
    ok(&train(
        &scene,
        &out,
        &[
            "--init",
            "gt",
            "--steps",
            "10",
            "--no-eval",
            "--device",
            "cpu",
        ],
    ));
    let trained = gems_train::TrainOutput::load(&out).unwrap();
    let n = trained.config.num_virtual_views;
    ok(&gems(&["render", s(&out), "--bursts", "--device", "cpu"]));
    for v in &trained.views {
        let stem = Path::new(&v.name).file_stem().unwrap().to_str().unwrap();
        let frames = std::fs::read_dir(out.join("bursts").join(stem))
            .unwrap()
            .count();
        assert_eq!(frames, n, "{stem}");
        assert!(out.join("bursts").join(format!("{stem}.gif")).is_file());
    }
    ok(&gems(&["export", s(&out), "--format", "colmap"]));
    let model = gems_data::colmap::read_model(&out.join("export_colmap/sparse/0")).unwrap();
    assert_eq!(model.images.len(), trained.views.len());
    ok(&gems(&[
        "export",
        s(&out),
        "--format",
        "nerfstudio",
        "--device",
        "cpu",
    ]));
    let t = gems_data::nerfstudio::read_transforms(&out.join("export_nerfstudio/transforms.json"))
        .unwrap();
    assert_eq!(t.frames.len(), trained.views.len());
    // A folder without --bursts, or --bursts on a PLY: one clear error each.
    fails_clearly(&gems(&["render", s(&out), "-o", "x.png"]), "is a folder");
    fails_clearly(
        &gems(&["render", s(&out.join("point_cloud.ply")), "--bursts"]),
        "--bursts needs an output folder",
    );
}

#[test]
fn a_video_is_a_scene_of_ordered_frames_and_a_fly_through_is_a_video() {
    let dir = tempfile::tempdir().unwrap();
    let scene = tiny_scene(dir.path());
    let clips = dir.path().join("clips");
    std::fs::create_dir_all(&clips).unwrap();
    let clip = clips.join("clip.mp4");
    clip_of(&scene, &clip);
    read_only(&clips);
    let before = snapshot(&clips);

    let info = gems(&["info", s(&clip)]);
    ok(&info);
    assert!(stdout(&info).contains("8.00 fps"), "{}", stdout(&info));

    let out = dir.path().join("run");
    ok(&train(
        &clip,
        &out,
        &[
            "--fps", "6", "--init", "sfm", "--steps", "10", "--device", "cpu",
        ],
    ));
    let frames = out.join("frames");
    let list = gems_data::video::read_frame_list(&frames).unwrap();
    assert!(list.frames.len() >= 5, "{list:?}");
    assert!((list.rate - 6.0).abs() < 1e-9);
    for (k, f) in list.frames.iter().enumerate() {
        assert_eq!(f.name, format!("{k:04}.png"));
        assert!((f.time_s - k as f64 / 6.0).abs() < 1e-9);
    }
    let opened = gems_data::open_scene(&frames, &Default::default()).unwrap();
    assert_eq!(
        opened.frame_times.as_ref().unwrap().len(),
        list.frames.len()
    );
    assert!(out.join("metrics.json").is_file() || out.join("point_cloud.ply").is_file());
    assert_eq!(
        snapshot(&clips),
        before,
        "nothing is written beside the video"
    );

    // The result goes back out as a video along its path and around it.
    let video = dir.path().join("fly.mp4");
    ok(&gems(&[
        "render",
        s(&out),
        "--path",
        "orbit",
        "--frames",
        "8",
        "-o",
        s(&video),
        "--device",
        "cpu",
    ]));
    assert!(std::fs::metadata(&video).unwrap().len() > 0);
    let probed = gems_data::video::Ffmpeg::default().probe(&video).unwrap();
    let k = gems_train::TrainOutput::load(&out).unwrap().views[0].intrinsics;
    assert_eq!((probed.width, probed.height), (k.width, k.height));
    // Without ffmpeg the frames stay as PNG.
    let no_ffmpeg = gems(&[
        "render",
        s(&out),
        "--path",
        "train",
        "--frames",
        "4",
        "-o",
        s(&dir.path().join("t.mp4")),
        "--ffmpeg",
        "/nonexistent/ffmpeg",
        "--device",
        "cpu",
    ]);
    ok(&no_ffmpeg);
    assert!(dir.path().join("t.frames/0003.png").is_file());

    // Bad input: one clear error each.
    let bad = dir.path().join("bad.mp4");
    std::fs::write(&bad, b"not a video").unwrap();
    fails_clearly(&gems(&["info", s(&bad)]), "not a video ffprobe can read");
    fails_clearly(
        &train(&bad, &dir.path().join("r2"), &["--steps", "5"]),
        "not a video ffprobe can read",
    );
    fails_clearly(
        &train(
            &clip,
            &dir.path().join("r3"),
            &["--ffmpeg", "/nonexistent/ffmpeg"],
        ),
        "install ffmpeg",
    );
}

/// `gems <args>` as a person runs it: no `RUST_LOG`, and no desktop session (`XDG_RUNTIME_DIR`
/// unset, as on a server or in CI, where Mesa's device-select layer used to print two lines
/// starting "error:" while `--device auto` probed for a GPU).
fn gems_as_a_person(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_gems"))
        .args(args)
        .env_remove("RUST_LOG")
        .env_remove("XDG_RUNTIME_DIR")
        .env_remove("NODEVICE_SELECT")
        .output()
        .expect("the gems binary runs")
}

/// Whether `text` has a number with more than six digits after its decimal point.
fn has_long_float(text: &str) -> bool {
    let bytes = text.as_bytes();
    (1..bytes.len()).any(|i| {
        bytes[i] == b'.'
            && bytes[i - 1].is_ascii_digit()
            && bytes[i + 1..]
                .iter()
                .take_while(|b| b.is_ascii_digit())
                .count()
                > 6
    })
}

#[test]
fn the_console_is_short_and_readable_and_the_log_file_has_the_detail() {
    let dir = tempfile::tempdir().unwrap();
    let scene = tiny_scene(dir.path());
    let run = dir.path().join("run");
    let out = gems_as_a_person(&[
        "train",
        s(&scene),
        "-o",
        s(&run),
        "--steps",
        "30",
        "--no-eval",
    ]);
    ok(&out);
    let err = String::from_utf8_lossy(&out.stderr);
    // Nothing failed, so nothing says "error"; no timestamps, module paths or 17-digit floats.
    assert!(!err.to_lowercase().contains("error"), "{err}");
    assert!(
        !err.contains("gems_pipeline::") && !err.contains("Z  INFO"),
        "{err}"
    );
    assert!(!has_long_float(&err), "{err}");
    assert!(err.lines().count() <= 12, "a few lines per stage:\n{err}");
    // The built-in SfM is named as such, not as "colmap (…/sfm/sparse/0)".
    assert!(
        err.contains("init built-in SfM on the blurry photos"),
        "{err}"
    );

    // The log file keeps everything: timestamps, module paths, each step report at full
    // precision, from before the output folder was known too.
    let log = std::fs::read_to_string(run.join("gems.log")).unwrap();
    assert!(
        log.contains("==== gems ") && log.contains(" train "),
        "{log}"
    );
    assert!(
        log.contains("INFO gems_pipeline::init: structure from motion"),
        "{log}"
    );
    assert!(log.contains("DEBUG gems_gpu::context"), "{log}");
    assert!(
        log.contains("DEBUG gems_train::trainer: train step=30"),
        "{log}"
    );
    assert!(has_long_float(&log), "{log}");

    // -v puts the detail on the console too, and a second command appends to the log.
    let sfm = dir.path().join("sfm");
    let out = gems_as_a_person(&["sfm", s(&scene), "-o", s(&sfm), "-v"]);
    ok(&out);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("DEBUG gems_init::sfm"), "{err}");
    let out = gems_as_a_person(&["sfm", s(&scene), "-o", s(&sfm)]);
    ok(&out);
    let log = std::fs::read_to_string(sfm.join("gems.log")).unwrap();
    assert_eq!(log.matches("==== gems ").count(), 2, "{log}");

    // A failure is one line that says so, and the log file has it too.
    let out = gems_as_a_person(&[
        "train",
        s(&dir.path().join("no-such-scene")),
        "-o",
        s(&dir.path().join("failed")),
    ]);
    fails_clearly(&out, "no-such-scene");
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(
        err.lines().filter(|l| l.starts_with("error: ")).count(),
        1,
        "{err}"
    );
    let log = std::fs::read_to_string(dir.path().join("failed").join("gems.log")).unwrap();
    assert!(
        log.contains("ERROR gems: ") && log.contains("no-such-scene"),
        "{log}"
    );
}

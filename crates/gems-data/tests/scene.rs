//! Scene opening on hand-made folders of every layout: splits, ground truth, SfM attachment,
//! downscaled copies, events, and the errors of malformed folders.

use std::path::Path;

use gems_data::colmap::{self, Camera, CameraModel, Image, ModelFormat, SparseModel};
use gems_data::llff::{self, LlffRow};
use gems_data::nerfstudio::{self, CameraSpec, Frame, FrameSplit, Transforms};
use gems_data::*;
use gems_math::{Intrinsics, Pose};

fn write_img(path: &Path, w: u32, h: u32, seed: u32) {
    let mut img = ImageRgb::new(w, h);
    for (i, v) in img.data.iter_mut().enumerate() {
        *v = ((i as u32 * 37 + seed * 11) % 256) as f32 / 255.0;
    }
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    save_png(path, &img).unwrap();
}

fn pose(i: usize) -> Pose {
    let a = 0.1 * i as f64;
    Pose::from_quaternion(
        [(a / 2.0).cos(), 0.0, (a / 2.0).sin(), 0.0],
        [i as f64 * 0.1, 0.0, 1.0],
    )
}

fn names(n: usize) -> Vec<String> {
    (0..n).map(|i| format!("{i:03}.png")).collect()
}

/// A GeMS-layout scene as `gems synth` writes it: images/, images_test/ (one per image),
/// hold=<hold>, manifest with ground-truth poses, LLFF GT poses + sub-frames, and a COLMAP model
/// computed at twice the resolution.
fn make_gems(root: &Path, n: usize, hold: i64, w: u32, h: u32) {
    for (i, name) in names(n).iter().enumerate() {
        write_img(&root.join("images").join(name), w, h, i as u32);
        write_img(&root.join("images_test").join(name), w, h, 100 + i as u32);
    }
    write_hold_marker(root, hold).unwrap();
    write_manifest(root, &Manifest::ground_truth("test")).unwrap();
    let rows: Vec<LlffRow> = (0..n)
        .map(|i| LlffRow::from_pose(&pose(i), h as f64, w as f64, 20.0, 0.1, 10.0))
        .collect();
    llff::write_poses_bounds(&root.join("poses_bounds.npy"), &rows).unwrap();
    let sub: Vec<Vec<LlffRow>> = (0..n)
        .map(|i| {
            (0..5)
                .map(|s| LlffRow::from_pose(&pose(i + s), h as f64, w as f64, 20.0, 0.1, 10.0))
                .collect()
        })
        .collect();
    llff::write_subframes(&root.join("poses_bounds_subframes.npy"), &sub).unwrap();
    let model = SparseModel {
        cameras: vec![Camera {
            id: 1,
            model: CameraModel::Pinhole,
            width: 2 * w as u64,
            height: 2 * h as u64,
            params: vec![40.0, 42.0, w as f64, h as f64],
        }],
        // SfM estimates differ from ground truth: use pose(i + 1).
        images: names(n)
            .iter()
            .enumerate()
            .map(|(i, name)| Image::from_pose(i as u32 + 1, 1, name, &pose(i + 1)))
            .collect(),
        points: vec![],
    };
    colmap::write_model(&root.join("sparse/0"), &model, ModelFormat::Binary).unwrap();
}

fn close(a: &Pose, b: &Pose) -> bool {
    a.rotation
        .iter()
        .flatten()
        .zip(b.rotation.iter().flatten())
        .all(|(x, y)| (x - y).abs() < 1e-9)
        && a.translation
            .iter()
            .zip(&b.translation)
            .all(|(x, y)| (x - y).abs() < 1e-9)
}

#[test]
fn gems_layout_split_ground_truth_and_sfm() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path();
    make_gems(root, 10, 4, 8, 6);
    let s = open_scene(root, &OpenOptions::default()).unwrap();
    assert_eq!(s.layout, Layout::Gems);
    assert_eq!(s.hold, Some(4));
    assert_eq!(s.pose_source, PoseSource::Sfm);
    let nvs: Vec<&str> = s.nvs_eval_views().map(|v| v.name.as_str()).collect();
    assert_eq!(nvs, ["000.png", "004.png", "008.png"]);
    assert_eq!(s.train_views().count(), 7);
    assert_eq!(s.deblur_eval_views().count(), 7);
    let v = &s.views[5];
    assert_eq!(
        v.sharp_gt.as_deref(),
        Some(root.join("images_test/005.png").as_path())
    );
    assert!(
        close(v.pose.as_ref().unwrap(), &pose(6)),
        "SfM pose by name"
    );
    assert!(
        close(v.gt_pose.as_ref().unwrap(), &pose(5)),
        "GT pose from poses_bounds"
    );
    let sub = v.gt_subframe_poses.as_ref().unwrap();
    assert_eq!(sub.len(), 5);
    assert!(close(&sub[4], &pose(9)));
    // The model was computed at 16×12: intrinsics are rescaled to the 8×6 images.
    let k = v.intrinsics.unwrap();
    assert_eq!(
        (k.fx, k.fy, k.cx, k.cy, k.width, k.height),
        (20.0, 21.0, 4.0, 3.0, 8, 6)
    );

    let info = scene_info(&s, true).unwrap();
    let json = serde_json::to_value(&info).unwrap();
    for key in [
        "layout",
        "views",
        "train",
        "eval_deblur",
        "eval_nvs",
        "width",
        "height",
        "has_gt_poses",
        "has_sfm",
        "events",
    ] {
        assert!(json.get(key).is_some(), "missing key {key}");
    }
    assert_eq!(json["layout"], "gems");
    assert_eq!(json["views"], 10);
    assert_eq!(json["eval_nvs"], 3);
    assert_eq!(json["has_gt_poses"], true);
    assert_eq!(json["subframes_per_view"], 5);
    assert!(json["events"].is_null());
    let text = info.to_string();
    assert!(
        text.contains("10 (7 train, 7 deblur-eval, 3 novel-view eval"),
        "{text}"
    );
}

#[test]
fn prism3d_images_gt_gives_ground_truth_by_name() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path();
    make_gems(root, 4, 8, 8, 6);
    std::fs::remove_file(root.join(manifest::MANIFEST_FILE)).unwrap();
    // PRISM3D's GT list, in a different order and with different ids than the SfM model.
    let gt: Vec<Image> = [2usize, 0]
        .iter()
        .map(|&i| Image::from_pose(100 + i as u32, 1, &format!("{i:03}.png"), &pose(i + 7)))
        .collect();
    std::fs::write(
        root.join("sparse/0/images_gt.bin"),
        colmap::images_to_bin(&gt),
    )
    .unwrap();
    let s = open_scene(root, &OpenOptions::default()).unwrap();
    assert!(close(s.views[2].gt_pose.as_ref().unwrap(), &pose(9)));
    assert!(close(s.views[0].gt_pose.as_ref().unwrap(), &pose(7)));
    assert!(
        s.views[1].gt_pose.is_none(),
        "no manifest: poses_bounds.npy is not ground truth"
    );
    std::fs::write(root.join("sparse/0/images_gt.bin"), b"\x01").unwrap();
    let e = open_scene(root, &OpenOptions::default())
        .unwrap_err()
        .to_string();
    assert!(e.contains("images_gt.bin"), "{e}");
}

#[test]
fn distorted_cameras_are_undistorted_into_copies() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path();
    make_gems(root, 3, 8, 16, 12);
    let mut m = colmap::read_model(&root.join("sparse/0")).unwrap();
    m.cameras[0] = Camera {
        id: 1,
        model: CameraModel::SimpleRadial,
        width: 32,
        height: 24,
        params: vec![30.0, 16.0, 12.0, -0.2],
    };
    colmap::write_model(&root.join("sparse/0"), &m, ModelFormat::Binary).unwrap();
    // Copies go to the cache, never into the scene; without a cache that is an error.
    let e = open_scene_undistorted(root, &OpenOptions::default())
        .unwrap_err()
        .to_string();
    assert!(e.contains("cache"), "{e}");
    let cache_dir = tempfile::tempdir().unwrap();
    let cache = cache_folder(cache_dir.path(), root);
    let before = snapshot(root);
    // A pre-existing copy is kept as it is.
    write_img(&cache.join("images_undistorted/001.png"), 16, 12, 77);
    let kept = std::fs::read(cache.join("images_undistorted/001.png")).unwrap();
    let opts = OpenOptions {
        cache_dir: Some(cache_dir.path().to_path_buf()),
        ..OpenOptions::default()
    };
    let s = open_scene_undistorted(root, &opts).unwrap();
    assert_eq!(snapshot(root), before, "nothing written into the scene");
    assert_eq!(
        std::fs::read(cache.join("images_undistorted/001.png")).unwrap(),
        kept
    );
    let v = &s.views[2];
    assert_eq!(v.image, cache.join("images_undistorted/002.png"));
    assert_eq!(
        v.sharp_gt.as_deref(),
        Some(cache.join("images_test_undistorted/002.png").as_path())
    );
    let k = v.intrinsics.unwrap();
    assert_eq!(
        (k.fx, k.fy, k.cx, k.cy, k.width),
        (15.0, 15.0, 8.0, 6.0, 16)
    );
    // The copy is the undistortion of the original.
    let cam = &m.cameras[0];
    let map = undistort::UndistortMap::new(cam, 16, 12).unwrap();
    let want = map
        .apply(&load_image(&root.join("images/002.png")).unwrap())
        .unwrap();
    let got = load_image(&v.image).unwrap();
    for (a, b) in got.data.iter().zip(&want.data) {
        assert!((a - b).abs() <= 0.5 / 255.0 + 1e-6);
    }
    assert_ne!(got, load_image(&root.join("images/002.png")).unwrap());
}

#[test]
fn hold_option_and_no_hold() {
    let dir = tempfile::tempdir().unwrap();
    make_gems(dir.path(), 6, 4, 8, 6);
    let opts = OpenOptions {
        hold: Some(0),
        ..OpenOptions::default()
    };
    let s = open_scene(dir.path(), &opts).unwrap();
    assert_eq!(s.hold, None);
    assert_eq!(s.deblur_eval_views().count(), 6);
    assert_eq!(s.nvs_eval_views().count(), 0);
}

#[test]
fn bad_gaussians_style_sharp_per_training_view() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path();
    make_gems(root, 9, 4, 8, 6);
    // Keep only the 6 sharp images of training views (indices 1,2,3,5,6,7), renamed BAD-style.
    std::fs::remove_dir_all(root.join("images_test")).unwrap();
    for (k, i) in [1, 2, 3, 5, 6, 7].iter().enumerate() {
        write_img(
            &root.join(format!("images_test/img_test_{k:03}.png")),
            8,
            6,
            200 + *i,
        );
    }
    let s = open_scene(root, &OpenOptions::default()).unwrap();
    assert_eq!(s.deblur_eval_views().count(), 6);
    assert_eq!(s.nvs_eval_views().count(), 0);
    assert_eq!(
        s.views[5].sharp_gt.as_deref(),
        Some(root.join("images_test/img_test_003.png").as_path())
    );
    // A count matching neither rule is an error naming images_test.
    std::fs::remove_file(root.join("images_test/img_test_000.png")).unwrap();
    let e = open_scene(root, &OpenOptions::default())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("images_test") && e.contains("neither matches"),
        "{e}"
    );
}

/// Every file under `root` with its bytes (test scenes are small).
fn snapshot(root: &Path) -> std::collections::BTreeMap<std::path::PathBuf, Vec<u8>> {
    let mut out = std::collections::BTreeMap::new();
    let mut stack = vec![root.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p.clone());
                out.insert(p, Vec::new());
            } else {
                out.insert(p.clone(), std::fs::read(&p).unwrap());
            }
        }
    }
    out
}

#[test]
fn downscaled_copies_go_to_the_cache_never_into_the_scene() {
    let dir = tempfile::tempdir().unwrap();
    let root = &dir.path().join("scene");
    make_gems(root, 4, 8, 9, 6);
    let before = snapshot(root);
    // Without a cache a missing images_<f>/ is an error that says where copies would go.
    let opts = OpenOptions {
        downscale: 2,
        ..OpenOptions::default()
    };
    let e = open_scene(root, &opts).unwrap_err().to_string();
    assert!(e.contains("images_2") && e.contains("cache"), "{e}");
    let cache_dir = dir.path().join("cache");
    let opts = OpenOptions {
        downscale: 2,
        cache_dir: Some(cache_dir.clone()),
        ..OpenOptions::default()
    };
    let s = open_scene(root, &opts).unwrap();
    assert_eq!(snapshot(root), before, "nothing written into the scene");
    let cache = cache_folder(&cache_dir, root);
    assert!(cache.starts_with(&cache_dir));
    assert_eq!(
        (s.views[0].width, s.views[0].height),
        (4, 3),
        "floor(9/2) x 6/2"
    );
    assert!(s.views[0].image.starts_with(cache.join("images_2")));
    assert_eq!(s.views[0].name, "000.png");
    assert!(
        s.views[2]
            .sharp_gt
            .as_ref()
            .unwrap()
            .starts_with(cache.join("images_test_2"))
    );
    // Area filter: the copy equals the area-filtered full image (8-bit rounding aside).
    let full = load_image(&root.join("images/002.png")).unwrap();
    let small = load_image(&cache.join("images_2/002.png")).unwrap();
    let expect = image::downscale_area(&full, 4, 3);
    for (a, b) in small.data.iter().zip(&expect.data) {
        assert!((a - b).abs() <= 0.5 / 255.0 + 1e-6);
    }
    // Intrinsics: camera at 18×12 → 4×3 per axis.
    let k = s.views[0].intrinsics.unwrap();
    assert!((k.fx - 40.0 * 4.0 / 18.0).abs() < 1e-12 && (k.fy - 42.0 * 3.0 / 12.0).abs() < 1e-12);
    // A second open reuses the cached copies as they are.
    let t = std::fs::metadata(cache.join("images_2/002.png"))
        .unwrap()
        .modified()
        .unwrap();
    open_scene(root, &opts).unwrap();
    assert_eq!(
        std::fs::metadata(cache.join("images_2/002.png"))
            .unwrap()
            .modified()
            .unwrap(),
        t
    );
    // A cache inside the scene is refused.
    let inside = OpenOptions {
        downscale: 3,
        cache_dir: Some(root.join("cache")),
        ..OpenOptions::default()
    };
    let e = open_scene(root, &inside).unwrap_err().to_string();
    assert!(e.contains("inside the scene"), "{e}");
    assert_eq!(snapshot(root), before);
}

#[test]
fn an_existing_downscaled_folder_is_paired_by_stem_then_by_order() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path();
    make_gems(root, 4, 8, 8, 6);
    std::fs::remove_dir_all(root.join("images_test")).unwrap();
    // Same stems, another extension (Deblur-NeRF real: JPG images/, PNG images_4/): by stem,
    // whatever the order of the extensions.
    for (i, n) in names(4).iter().enumerate() {
        let stem = n.trim_end_matches(".png");
        let mut img = ImageRgb::new(4, 3);
        img.data.fill(i as f32 / 4.0);
        image::save_image_auto(&root.join(format!("images_2/{stem}.jpg")), &img).unwrap();
    }
    let opts = OpenOptions {
        downscale: 2,
        ..OpenOptions::default()
    };
    let s = open_scene(root, &opts).unwrap();
    assert_eq!(
        s.views[1].name, "001.png",
        "views keep the images/ name (SfM key)"
    );
    assert_eq!(s.views[1].image, root.join("images_2/001.jpg"));
    assert!(
        s.views[1].pose.is_some(),
        "the SfM model matches by the images/ name"
    );
    // Names differ completely but the count agrees: sorted order.
    std::fs::remove_dir_all(root.join("images_2")).unwrap();
    for (i, n) in ["a.png", "b.png", "c.png", "d.png"].iter().enumerate() {
        write_img(&root.join("images_2").join(n), 4, 3, i as u32);
    }
    let s = open_scene(root, &opts).unwrap();
    assert_eq!(s.views[2].name, "002.png");
    assert_eq!(s.views[2].image, root.join("images_2/c.png"));
    // A partial folder cannot be paired: one error, and the folder is left alone.
    std::fs::remove_file(root.join("images_2/d.png")).unwrap();
    let e = open_scene(root, &opts).unwrap_err().to_string();
    assert!(
        e.contains("images_2") && e.contains("holds 3 images") && e.contains('4'),
        "{e}"
    );
    assert_eq!(std::fs::read_dir(root.join("images_2")).unwrap().count(), 3);
}

#[test]
fn llff_layout_interleaves_sharp_test_views() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path();
    let n = 9;
    for (i, name) in names(n).iter().enumerate() {
        write_img(&root.join("images").join(name), 10, 8, i as u32);
    }
    let rows: Vec<LlffRow> = (0..n)
        .map(|i| LlffRow::from_pose(&pose(i), 16.0, 20.0, 30.0, 0.1, 5.0))
        .collect();
    llff::write_poses_bounds(&root.join("poses_bounds.npy"), &rows).unwrap();
    // ExBluRF sub-frames for the training views only.
    let sub: Vec<Vec<LlffRow>> = (0..6).map(|i| vec![rows[i]; 3]).collect();
    llff::write_subframes(&root.join("poses_bounds_subframes.npy"), &sub).unwrap();
    let opts = OpenOptions {
        hold: Some(3),
        ..OpenOptions::default()
    };
    let s = open_scene(root, &opts).unwrap();
    assert_eq!(s.layout, Layout::Llff);
    assert_eq!(s.pose_source, PoseSource::Llff);
    let nvs: Vec<usize> = s
        .views
        .iter()
        .enumerate()
        .filter(|(_, v)| v.split == Split::NovelView)
        .map(|(i, _)| i)
        .collect();
    assert_eq!(nvs, [0, 3, 6]);
    assert_eq!(s.views[3].sharp_gt.as_ref(), Some(&s.views[3].image));
    assert_eq!(s.deblur_eval_views().count(), 0);
    assert!(close(s.views[4].pose.as_ref().unwrap(), &pose(4)));
    let k = s.views[4].intrinsics.unwrap();
    assert_eq!(
        (k.fx, k.cx, k.cy, k.width),
        (15.0, 5.0, 4.0, 10),
        "hwf 16x20 f30 scaled to 10x8"
    );
    assert!(s.views[0].gt_subframe_poses.is_none());
    assert_eq!(s.views[1].gt_subframe_poses.as_ref().unwrap().len(), 3);
    // E2NeRF real scenes: 5 poses per image, the middle one is the view's pose.
    let five: Vec<LlffRow> = (0..n * 5)
        .map(|j| LlffRow::from_pose(&pose(j), 16.0, 20.0, 30.0, 0.1, 5.0))
        .collect();
    llff::write_poses_bounds(&root.join("poses_bounds.npy"), &five).unwrap();
    std::fs::remove_file(root.join("poses_bounds_subframes.npy")).unwrap();
    let s = open_scene(root, &opts).unwrap();
    assert!(close(s.views[4].pose.as_ref().unwrap(), &pose(4 * 5 + 2)));
    // Wrong number of poses names the file.
    llff::write_poses_bounds(&root.join("poses_bounds.npy"), &rows[..5]).unwrap();
    let e = open_scene(root, &opts).unwrap_err().to_string();
    assert!(
        e.contains("poses_bounds.npy") && e.contains("5 poses"),
        "{e}"
    );
}

#[test]
fn nerfstudio_round_trip_and_scene() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path();
    let k = Intrinsics {
        fx: 50.0,
        fy: 51.0,
        cx: 6.0,
        cy: 4.0,
        width: 12,
        height: 8,
    };
    let frames: Vec<Frame> = (0..4)
        .map(|i| Frame {
            file_path: format!("images/{i:03}.png"),
            pose: pose(i),
            subframe_poses: Vec::new(),
            camera: CameraSpec::Pinhole(k),
            split: Some(if i == 2 {
                FrameSplit::Eval
            } else {
                FrameSplit::Train
            }),
        })
        .collect();
    for f in &frames {
        write_img(&root.join(&f.file_path), 12, 8, 1);
    }
    let t = Transforms { frames };
    nerfstudio::write_transforms(&root.join("transforms.json"), &t).unwrap();
    let back = nerfstudio::read_transforms(&root.join("transforms.json")).unwrap();
    assert_eq!(back.frames.len(), 4);
    for (a, b) in back.frames.iter().zip(&t.frames) {
        assert_eq!(
            (a.file_path.as_str(), a.camera, a.split),
            (b.file_path.as_str(), b.camera, b.split)
        );
        assert!(close(&a.pose, &b.pose));
    }
    let s = open_scene(root, &OpenOptions::default()).unwrap();
    assert_eq!(s.layout, Layout::Nerfstudio);
    assert_eq!(s.views[2].split, Split::NovelView);
    assert_eq!(s.views[1].intrinsics, Some(k));
    assert!(close(s.views[3].pose.as_ref().unwrap(), &pose(3)));
}

/// OpenGL c2w convention on a hand-written matrix: identity in OpenGL (camera looking down −z,
/// y up) is an OpenCV camera rotated 180° about x.
#[test]
fn nerfstudio_opengl_convention() {
    let text = r#"{"camera_angle_x": 1.5707963267948966,
        "frames": [{"file_path": "./train/r_0", "transform_matrix": [[1,0,0,1],[0,1,0,2],[0,0,1,3],[0,0,0,1]]}]}"#;
    let t = nerfstudio::parse_transforms(text).unwrap();
    let p = t.frames[0].pose;
    assert_eq!(p.center(), [1.0, 2.0, 3.0]);
    // World point 1 unit in front (−z in OpenGL) must have camera z = +1 in OpenCV.
    let c = p.transform_point([1.0, 2.0, 2.0]);
    assert!(
        (c[2] - 1.0).abs() < 1e-12 && c[0].abs() < 1e-12 && c[1].abs() < 1e-12,
        "{c:?}"
    );
    // A world point above the camera (+y) is at negative OpenCV y (image up).
    assert!(p.transform_point([1.0, 3.0, 2.0])[1] < 0.0);
    let k = t.frames[0].camera.resolve(100, 80);
    assert!((k.fx - 50.0).abs() < 1e-9 && k.cx == 50.0 && k.cy == 40.0);
    // Blender paths omit ".png"; the scene resolves them.
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("transforms.json"), text).unwrap();
    write_img(&dir.path().join("train/r_0.png"), 10, 10, 0);
    let s = open_scene(dir.path(), &OpenOptions::default()).unwrap();
    assert!((s.views[0].intrinsics.unwrap().fx - 5.0).abs() < 1e-12);
    // Downscaled: into the cache when the scene has no train_2/ …
    let before = snapshot(dir.path());
    let cache = tempfile::tempdir().unwrap();
    let opts = OpenOptions {
        downscale: 2,
        cache_dir: Some(cache.path().to_path_buf()),
        ..OpenOptions::default()
    };
    let s = open_scene(dir.path(), &opts).unwrap();
    assert_eq!(snapshot(dir.path()), before);
    assert!(
        s.views[0].image.starts_with(cache.path()),
        "{:?}",
        s.views[0].image
    );
    assert_eq!((s.views[0].width, s.views[0].height), (5, 5));
    // … and its own train_2/ (matched by stem) when it has one.
    image::save_image_auto(&dir.path().join("train_2/r_0.jpg"), &ImageRgb::new(5, 5)).unwrap();
    let s = open_scene(dir.path(), &opts).unwrap();
    assert_eq!(s.views[0].image, dir.path().join("train_2/r_0.jpg"));
    assert_eq!(s.views[0].name, "r_0.png");
    assert!((s.views[0].intrinsics.unwrap().fx - 2.5).abs() < 1e-12);
}

#[test]
fn nerfstudio_errors_name_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("transforms.json");
    let cases = [
        (
            r#"{"fl_x": 1, "w": 2, "h": 2, "k1": 0.2, "frames": []}"#,
            "distortion",
        ),
        (
            r#"{"fl_x": 1, "w": 2, "h": 2, "frames": [{"file_path": "a.png", "transform_matrix": [[1,0,0,0],[0,1,0,0],[0,0,1,0]]}]}"#,
            "",
        ),
        (
            r#"{"frames": [{"file_path": "a.png", "transform_matrix": [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]}]}"#,
            "no intrinsics",
        ),
        (
            r#"{"fl_x": 1, "w": 2, "h": 2, "frames": [{"file_path": "a.png", "transform_matrix": [[2,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]}]}"#,
            "rigid",
        ),
        (
            r#"{"camera_model": "EQUIRECTANGULAR", "frames": []}"#,
            "EQUIRECTANGULAR",
        ),
        ("{not json", "invalid JSON"),
    ];
    for (text, needle) in cases {
        std::fs::write(&p, text).unwrap();
        let e = open_scene(dir.path(), &OpenOptions::default())
            .unwrap_err()
            .to_string();
        assert!(e.contains("transforms.json") || e.contains("a.png"), "{e}");
        assert!(e.contains(needle), "{e} should contain {needle}");
    }
}

#[test]
fn malformed_scenes_give_one_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path();
    // Not a scene.
    let e = open_scene(root, &OpenOptions::default())
        .unwrap_err()
        .to_string();
    assert!(e.contains("images"), "{e}");
    let e = open_scene(&root.join("nope"), &OpenOptions::default())
        .unwrap_err()
        .to_string();
    assert!(e.contains("nope"), "{e}");
    // Distorted camera.
    make_gems(root, 3, 8, 8, 6);
    let mut m = colmap::read_model(&root.join("sparse/0")).unwrap();
    m.cameras[0] = Camera {
        id: 1,
        model: CameraModel::Opencv,
        width: 8,
        height: 6,
        params: vec![4.0, 4.0, 4.0, 3.0, 0.1, 0.0, 0.0, 0.0],
    };
    colmap::write_model(&root.join("sparse/0"), &m, ModelFormat::Binary).unwrap();
    let e = open_scene(root, &OpenOptions::default())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("cameras.bin")
            && e.contains("distortion")
            && e.contains("open_scene_undistorted"),
        "{e}"
    );
    // A fisheye camera cannot be undistorted either.
    m.cameras[0].model = CameraModel::OpencvFisheye;
    colmap::write_model(&root.join("sparse/0"), &m, ModelFormat::Binary).unwrap();
    let e = open_scene_undistorted(root, &OpenOptions::default())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("cameras.bin") && e.contains("OPENCV_FISHEYE"),
        "{e}"
    );
    // Corrupt image.
    make_gems(root, 3, 8, 8, 6);
    std::fs::write(root.join("images/001.png"), b"garbage").unwrap();
    let e = open_scene(root, &OpenOptions::default())
        .unwrap_err()
        .to_string();
    assert!(e.contains("001.png"), "{e}");
    // Sharp image of the wrong size.
    make_gems(root, 3, 8, 8, 6);
    write_img(&root.join("images_test/002.png"), 7, 6, 0);
    let e = open_scene(root, &OpenOptions::default())
        .unwrap_err()
        .to_string();
    assert!(e.contains("002.png") && e.contains("7x6"), "{e}");
    // Sub-frame count mismatch.
    make_gems(root, 3, 8, 8, 6);
    llff::write_subframes(
        &root.join("poses_bounds_subframes.npy"),
        &[vec![LlffRow::from_pose(&pose(0), 6.0, 8.0, 1.0, 0.1, 1.0)]],
    )
    .unwrap();
    let e = open_scene(root, &OpenOptions::default())
        .unwrap_err()
        .to_string();
    assert!(e.contains("poses_bounds_subframes.npy"), "{e}");
}

#[test]
fn events_and_exposure_windows() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path();
    make_gems(root, 3, 8, 8, 6);
    let t: Vec<i64> = (0..100).map(|i| i * 10_000).collect();
    let ev = gems_events::EventStream::from_columns(
        8,
        6,
        t,
        (0..100).map(|i| (i % 8) as u16).collect(),
        (0..100).map(|i| (i % 6) as u16).collect(),
        (0..100).map(|i| if i % 2 == 0 { 1 } else { -1 }).collect(),
    )
    .unwrap();
    std::fs::create_dir_all(root.join("events")).unwrap();
    gems_events::write_events_npz(&root.join("events/events.npz"), &ev).unwrap();
    std::fs::write(
        root.join("events/exposure_start_ts.txt"),
        "0\n300000\n600000\n",
    )
    .unwrap();
    std::fs::write(
        root.join("events/exposure_end_ts.txt"),
        "99000\n450000\n990000\n",
    )
    .unwrap();
    let s = open_scene(root, &OpenOptions::default()).unwrap();
    assert_eq!(s.views[1].exposure.unwrap().start, 300_000);
    let info = scene_info(&s, true).unwrap();
    let e = info.events.as_ref().unwrap();
    assert_eq!(e.count, Some(100));
    assert_eq!(e.time_span_us, Some((0, 990_000)));
    let counts: Vec<Option<usize>> = e.windows.iter().map(|w| w.events).collect();
    assert_eq!(counts, [Some(10), Some(16), Some(40)]);
    let text = info.to_string();
    assert!(
        text.contains("100 events") && text.contains("exposures  3 windows"),
        "{text}"
    );
    // Without reading, the files are still reported.
    let quick = scene_info(&s, false).unwrap();
    assert_eq!(quick.events.unwrap().count, None);
    // Window count mismatch names the file.
    std::fs::write(root.join("events/exposure_start_ts.txt"), "0\n300000\n").unwrap();
    std::fs::write(root.join("events/exposure_end_ts.txt"), "99000\n450000\n").unwrap();
    let e = open_scene(root, &OpenOptions::default())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("exposure_start_ts.txt") && e.contains("2 exposure windows"),
        "{e}"
    );
}

#[test]
fn torch_bins_are_reported_with_conversion_hint() {
    let dir = tempfile::tempdir().unwrap();
    make_gems(dir.path(), 2, 8, 8, 6);
    std::fs::write(dir.path().join("events_bins_13.pt"), b"PK").unwrap();
    let s = open_scene(dir.path(), &OpenOptions::default()).unwrap();
    let info = scene_info(&s, true).unwrap();
    let e = info.events.unwrap();
    assert!(e.bin_counts.unwrap().ends_with("events_bins_13.pt"));
    assert!(e.notes[0].contains("numpy.save"), "{:?}", e.notes);
}

/// Writes float-second events (an `.npz` with float64 `t`, as tub-rip / v2e conversions do) over
/// 0..1 s, sensor 8×6.
fn write_float_second_events(path: &Path) {
    use npyz::WriterBuilder;
    let n = 200usize;
    let t: Vec<f64> = (0..n).map(|i| i as f64 * 0.005).collect();
    let x: Vec<u16> = (0..n).map(|i| (i % 8) as u16).collect();
    let y: Vec<u16> = (0..n).map(|i| (i % 6) as u16).collect();
    let p: Vec<i8> = (0..n).map(|i| if i % 2 == 0 { 1 } else { -1 }).collect();
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    let f = std::fs::File::create(path).unwrap();
    let mut npz = npyz::npz::NpzWriter::new(f);
    macro_rules! put {
        ($name:expr, $v:expr) => {{
            let mut w = npz
                .array($name, Default::default())
                .unwrap()
                .default_dtype()
                .shape(&[$v.len() as u64])
                .begin_nd()
                .unwrap();
            w.extend($v.iter().copied()).unwrap();
            w.finish().unwrap();
        }};
    }
    put!("t", t);
    put!("x", x);
    put!("y", y);
    put!("p", p);
}

#[test]
fn time_units_are_detected_across_a_scenes_files() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path();
    make_gems(root, 3, 8, 8, 6);
    write_float_second_events(&root.join("events.npz"));
    // The issue's scene: exposure files in seconds beside float-second events.
    std::fs::write(root.join("exposure_start_ts.txt"), "0.1\n0.4\n0.7\n").unwrap();
    std::fs::write(root.join("exposure_end_ts.txt"), "0.2\n0.5\n0.8\n").unwrap();
    let s = open_scene(root, &OpenOptions::default()).unwrap();
    let w = s.views[1].exposure.unwrap();
    assert_eq!((w.start, w.end), (400_000, 500_000));
    let info = scene_info(&s, true).unwrap();
    let counts: Vec<Option<usize>> = info
        .events
        .as_ref()
        .unwrap()
        .windows
        .iter()
        .map(|w| w.events)
        .collect();
    assert_eq!(
        counts,
        [Some(21), Some(21), Some(21)],
        "every window holds events"
    );
    assert!(check::check_scene(&s).is_empty());
    // The same windows in µs are read as µs.
    std::fs::write(
        root.join("exposure_start_ts.txt"),
        "100000\n400000\n700000\n",
    )
    .unwrap();
    std::fs::write(root.join("exposure_end_ts.txt"), "200000\n500000\n800000\n").unwrap();
    let s = open_scene(root, &OpenOptions::default()).unwrap();
    assert_eq!(s.views[1].exposure.unwrap().start, 400_000);
    // And in ms as ms (only that unit puts them inside the stream).
    std::fs::write(root.join("exposure_start_ts.txt"), "100\n400\n700\n").unwrap();
    std::fs::write(root.join("exposure_end_ts.txt"), "200\n500\n800\n").unwrap();
    let s = open_scene(root, &OpenOptions::default()).unwrap();
    assert_eq!(s.views[1].exposure.unwrap().start, 400_000);
    // Exposures alone whose values fit two units: one error naming the range and the option.
    std::fs::remove_file(root.join("events.npz")).unwrap();
    std::fs::write(root.join("exposure_start_ts.txt"), "0\n10\n20\n").unwrap();
    std::fs::write(root.join("exposure_end_ts.txt"), "5\n15\n25\n").unwrap();
    let e = open_scene(root, &OpenOptions::default())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("ambiguous") && e.contains("0 .. 25") && e.contains("--time-unit"),
        "{e}"
    );
    let opts = OpenOptions {
        time_unit: Some(gems_events::TimeUnit::Milliseconds),
        ..OpenOptions::default()
    };
    let s = open_scene(root, &opts).unwrap();
    assert_eq!(s.views[1].exposure.unwrap().end, 15_000);
}

//! The public deblurring datasets as distributed, rebuilt in miniature: layout and dataset
//! detection, `images_<f>/` beside `images/`, both pose sources, `gems info --check`'s validation,
//! and the EXIF focal. Every scene is opened without a cache and must come out unchanged.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use gems_data::colmap::{self, Camera, CameraModel, Image, ModelFormat, SparseModel};
use gems_data::llff::{self, LlffRow};
use gems_data::*;
use gems_math::Pose;

fn write_img(path: &Path, w: u32, h: u32, seed: u32) {
    let mut img = ImageRgb::new(w, h);
    for (i, v) in img.data.iter_mut().enumerate() {
        *v = ((i as u32 * 37 + seed * 11) % 256) as f32 / 255.0;
    }
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    image::save_image_auto(path, &img).unwrap();
}

fn pose(i: usize) -> Pose {
    let a = 0.1 * i as f64;
    Pose::from_quaternion(
        [(a / 2.0).cos(), 0.0, (a / 2.0).sin(), 0.0],
        [i as f64 * 0.1, 0.0, 1.0],
    )
}

fn snapshot(root: &Path) -> BTreeMap<PathBuf, Vec<u8>> {
    let mut out = BTreeMap::new();
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

fn rows(n: usize, w: u32, h: u32) -> Vec<LlffRow> {
    (0..n)
        .map(|i| LlffRow::from_pose(&pose(i), h as f64, w as f64, 30.0, 0.1, 10.0))
        .collect()
}

/// A Deblur-NeRF real scene as redistributed: JPG `images/` at full resolution, PNG `images_4/`
/// with the same stems, `poses_bounds.npy` (hwf at full resolution), `sparse/0` and `hold=7`.
fn make_deblur_nerf_real(root: &Path, n: usize) {
    let (w, h) = (32, 24);
    for i in 0..n {
        write_img(&root.join(format!("images/{i:03}.jpg")), w, h, i as u32);
        write_img(
            &root.join(format!("images_4/{i:03}.png")),
            w / 4,
            h / 4,
            i as u32,
        );
    }
    llff::write_poses_bounds(&root.join("poses_bounds.npy"), &rows(n, w, h)).unwrap();
    let model = SparseModel {
        cameras: vec![Camera {
            id: 1,
            model: CameraModel::Pinhole,
            width: w as u64,
            height: h as u64,
            params: vec![30.0, 30.0, 16.0, 12.0],
        }],
        images: (0..n)
            .map(|i| Image::from_pose(i as u32 + 1, 1, &format!("{i:03}.jpg"), &pose(i + 1)))
            .collect(),
        points: vec![],
    };
    colmap::write_model(&root.join("sparse/0"), &model, ModelFormat::Binary).unwrap();
    write_hold_marker(root, 7).unwrap();
}

#[test]
fn deblur_nerf_real_opens_at_its_evaluation_resolution_read_only() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path();
    make_deblur_nerf_real(root, 9);
    let before = snapshot(root);
    let opts = OpenOptions {
        downscale: 4,
        ..OpenOptions::default()
    };
    let s = open_scene(root, &opts).unwrap();
    assert_eq!(snapshot(root), before, "opening wrote into the scene");
    assert_eq!(s.layout, Layout::Llff);
    assert_eq!(s.dataset, "Deblur-NeRF / LLFF");
    assert_eq!(s.hold, Some(7));
    assert_eq!(s.views.len(), 9);
    let v = &s.views[1];
    assert_eq!(v.name, "001.jpg");
    assert_eq!(v.image, root.join("images_4/001.png"));
    assert_eq!((v.width, v.height), (8, 6));
    // The COLMAP model gives poses and intrinsics (rescaled to the ×4 images) …
    assert_eq!(s.pose_source, PoseSource::Sfm);
    assert_eq!(s.sfm_dir.as_deref(), Some(root.join("sparse/0").as_path()));
    let k = v.intrinsics.unwrap();
    assert!(
        (k.fx - 7.5).abs() < 1e-12 && (k.cx - 4.0).abs() < 1e-12,
        "{k:?}"
    );
    let p = v.pose.unwrap();
    assert!((p.translation[0] - pose(2).translation[0]).abs() < 1e-12);
    // … and the poses file is read, checked and said to be unused for poses.
    let uses: Vec<String> = s
        .uses
        .iter()
        .map(|u| format!("{}: {}", u.path.display(), u.role))
        .collect();
    assert!(
        uses.iter()
            .any(|u| u.contains("sparse/0") && u.contains("--init colmap")),
        "{uses:?}"
    );
    assert!(
        uses.iter()
            .any(|u| u.contains("poses_bounds.npy") && u.contains("9 rows for 9 images")),
        "{uses:?}"
    );
    // Deblur-NeRF interleaves the sharp test views: every 7th view.
    assert_eq!(s.views[7].split, Split::NovelView);
    assert_eq!(s.nvs_eval_views().count(), 2);
    let text = scene_info(&s, false).unwrap().to_string();
    assert!(
        text.contains("dataset    Deblur-NeRF / LLFF") && !text.contains("sfm        none"),
        "{text}"
    );
    assert!(check::check_scene(&s).is_empty());
    assert_eq!(snapshot(root), before);

    // A copy that ships only images_4/: its files are the views.
    let only = dir.path().join("only4");
    std::fs::create_dir_all(&only).unwrap();
    for f in ["images_4", "poses_bounds.npy", "hold=7"] {
        let from = root.join(f);
        if from.is_dir() {
            std::fs::create_dir_all(only.join(f)).unwrap();
            for e in std::fs::read_dir(&from).unwrap() {
                let p = e.unwrap().path();
                std::fs::copy(&p, only.join(f).join(p.file_name().unwrap())).unwrap();
            }
        } else {
            std::fs::copy(&from, only.join(f)).unwrap();
        }
    }
    let s = open_scene(&only, &opts).unwrap();
    assert_eq!(s.views.len(), 9);
    assert_eq!(s.views[2].image, only.join("images_4/002.png"));
    assert_eq!(s.pose_source, PoseSource::Llff);

    // The count is checked against the poses file.
    llff::write_poses_bounds(&root.join("poses_bounds.npy"), &rows(8, 32, 24)).unwrap();
    let e = open_scene(root, &opts).unwrap_err().to_string();
    assert!(
        e.contains("poses_bounds.npy") && e.contains("8 poses"),
        "{e}"
    );
}

#[test]
fn every_dataset_is_recognised() {
    let dir = tempfile::tempdir().unwrap();
    let (w, h) = (8u32, 6u32);

    // ExBluRF: LLFF with ground-truth sub-frame poses.
    let ex = dir.path().join("exblurf");
    for i in 0..6 {
        write_img(&ex.join(format!("images/{i:03}.png")), w, h, i);
    }
    llff::write_poses_bounds(&ex.join("poses_bounds.npy"), &rows(6, w, h)).unwrap();
    let sub: Vec<Vec<LlffRow>> = (0..6).map(|_| rows(3, w, h)).collect();
    llff::write_subframes(&ex.join("poses_bounds_subframes.npy"), &sub).unwrap();
    let s = open_scene(&ex, &OpenOptions::default()).unwrap();
    assert_eq!((s.layout, s.dataset.as_str()), (Layout::Llff, "ExBluRF"));
    assert_eq!(s.views[1].gt_subframe_poses.as_ref().unwrap().len(), 3);

    // EBAD-NeRF: pose_bounds.npy (sic), sharp images kept apart.
    let eb = dir.path().join("ebad");
    for i in 0..6u32 {
        write_img(&eb.join(format!("images/{i:03}.png")), w, h, i);
    }
    llff::write_poses_bounds(&eb.join("pose_bounds.npy"), &rows(6, w, h)).unwrap();
    write_hold_marker(&eb, 3).unwrap();
    for i in [1u32, 2, 4, 5] {
        write_img(&eb.join(format!("images_gt_blur/{i:03}.png")), w, h, 50 + i);
    }
    for i in [0u32, 3] {
        write_img(
            &eb.join(format!("images_gt_novel/{i:03}.png")),
            w,
            h,
            90 + i,
        );
    }
    let s = open_scene(&eb, &OpenOptions::default()).unwrap();
    assert_eq!((s.layout, s.dataset.as_str()), (Layout::Llff, "EBAD-NeRF"));
    assert_eq!(s.deblur_eval_views().count(), 4);
    assert_eq!(s.nvs_eval_views().count(), 2);
    assert_eq!(
        s.views[3].sharp_gt.as_deref(),
        Some(eb.join("images_gt_novel/003.png").as_path())
    );

    // E2NeRF real: 5 poses per image, events.
    let e2 = dir.path().join("e2nerf");
    for i in 0..4u32 {
        write_img(&e2.join(format!("images/{:03}.jpg", 5 * i)), w, h, i);
    }
    llff::write_poses_bounds(&e2.join("poses_bounds.npy"), &rows(20, w, h)).unwrap();
    std::fs::write(e2.join("events.pt"), b"PK").unwrap();
    let s = open_scene(&e2, &OpenOptions::default()).unwrap();
    assert_eq!(s.dataset, "E2NeRF (LLFF with events)");
    let mid = pose(7).translation[0]; // image 1: rows 5..10, middle row 7
    assert!((s.views[1].pose.unwrap().translation[0] - mid).abs() < 1e-12);

    // BAD-Gaussians / PRISM3D: images_test/.
    let bad = dir.path().join("bad");
    for i in 0..4u32 {
        write_img(&bad.join(format!("images/{i:03}.png")), w, h, i);
        write_img(&bad.join(format!("images_test/{i:03}.png")), w, h, 9 + i);
    }
    let s = open_scene(&bad, &OpenOptions::default()).unwrap();
    assert_eq!(
        (s.layout, s.dataset.as_str()),
        (Layout::Gems, "BAD-Gaussians / PRISM3D")
    );

    // A folder of phone photos or video frames.
    let photos = dir.path().join("frames");
    for i in 0..5u32 {
        write_img(&photos.join(format!("{:04}.png", i + 1)), w, h, i);
    }
    let before = snapshot(&photos);
    let s = open_scene(&photos, &OpenOptions::default()).unwrap();
    assert_eq!(
        (s.layout, s.dataset.as_str()),
        (Layout::Folder, "photos or video frames")
    );
    assert_eq!(s.train_views().count(), 5);
    assert!(s.views.iter().all(|v| v.pose.is_none()));
    let cache = dir.path().join("cache");
    let opts = OpenOptions {
        downscale: 2,
        cache_dir: Some(cache.clone()),
        ..OpenOptions::default()
    };
    let s = open_scene(&photos, &opts).unwrap();
    assert_eq!((s.views[0].width, s.views[0].height), (4, 3));
    assert!(s.views[0].image.starts_with(&cache));
    assert_eq!(snapshot(&photos), before);
}

#[test]
fn check_finds_every_problem_one_line_each() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path();
    make_deblur_nerf_real(root, 4);
    // A truncated JPEG: its header still reads (open succeeds), its pixels do not.
    let jpg = root.join("images/002.jpg");
    let bytes = std::fs::read(&jpg).unwrap();
    std::fs::write(&jpg, &bytes[..bytes.len() * 2 / 3]).unwrap();
    // Events every 10 ms for 1 s, one outside the 32×24 sensor, and a window without events.
    let n = 100;
    let ev = gems_events::EventStream::from_columns(
        40,
        24,
        (0..n).map(|i| i * 10_000).collect(),
        (0..n)
            .map(|i| if i == 50 { 39 } else { (i % 32) as u16 })
            .collect(),
        (0..n).map(|i| (i % 24) as u16).collect(),
        (0..n).map(|i| if i % 2 == 0 { 1 } else { -1 }).collect(),
    )
    .unwrap();
    gems_events::write_events_npz(&root.join("events.npz"), &ev).unwrap();
    std::fs::write(
        root.join("exposure_start_ts.txt"),
        "0\n100000\n200000\n905000\n",
    )
    .unwrap();
    std::fs::write(
        root.join("exposure_end_ts.txt"),
        "50000\n150000\n250000\n909000\n",
    )
    .unwrap();
    let s = open_scene(root, &OpenOptions::default()).unwrap();
    let problems: Vec<String> = check::check_scene(&s)
        .iter()
        .map(ToString::to_string)
        .collect();
    assert_eq!(problems.len(), 3, "{problems:#?}");
    assert!(
        problems[0].contains("002.jpg") && problems[0].contains("truncated"),
        "{problems:#?}"
    );
    assert!(problems[1].contains("events.npz") && problems[1].contains("x = 39"));
    assert!(problems[2].contains("003.jpg") && problems[2].contains("holds no events"));
}

/// A JPEG whose APP1 segment carries the EXIF `fields` (built with kamadak-exif's writer).
fn jpeg_with_exif(path: &Path, w: u32, h: u32, fields: &[::exif::Field]) {
    let mut writer = ::exif::experimental::Writer::new();
    for f in fields {
        writer.push_field(f);
    }
    let mut tiff = std::io::Cursor::new(Vec::new());
    writer.write(&mut tiff, false).unwrap();
    let tiff = tiff.into_inner();
    write_img(path, w, h, 3);
    let jpeg = std::fs::read(path).unwrap();
    assert_eq!(&jpeg[..2], &[0xFF, 0xD8]);
    let len = u16::try_from(2 + 6 + tiff.len()).unwrap();
    let mut out = jpeg[..2].to_vec();
    out.extend_from_slice(&[0xFF, 0xE1]);
    out.extend_from_slice(&len.to_be_bytes());
    out.extend_from_slice(b"Exif\0\0");
    out.extend_from_slice(&tiff);
    out.extend_from_slice(&jpeg[2..]);
    std::fs::write(path, out).unwrap();
}

fn field(tag: ::exif::Tag, value: ::exif::Value) -> ::exif::Field {
    ::exif::Field {
        tag,
        ifd_num: ::exif::In::PRIMARY,
        value,
    }
}

fn rational(num: u32, denom: u32) -> ::exif::Value {
    ::exif::Value::Rational(vec![::exif::Rational { num, denom }])
}

#[test]
fn exif_focal_in_pixels() {
    use ::exif::{Tag, Value};
    let dir = tempfile::tempdir().unwrap();
    // FocalLength 4.2 mm on a sensor sampled at 15 px/mm, image written at half the original
    // 128 px width: 4.2 · 15 / 2 = 31.5 px.
    let a = dir.path().join("photos/a.jpg");
    jpeg_with_exif(
        &a,
        64,
        48,
        &[
            field(Tag::FocalLength, rational(42, 10)),
            field(Tag::FocalPlaneXResolution, rational(15, 1)),
            field(Tag::FocalPlaneResolutionUnit, Value::Short(vec![4])),
            field(Tag::PixelXDimension, Value::Long(vec![128])),
            // Ignored when the physical tags are there.
            field(Tag::FocalLengthIn35mmFilm, Value::Short(vec![28])),
        ],
    );
    let f = exif::focal_from_exif(&a, 64, 48).unwrap();
    assert!((f.focal_px - 31.5).abs() < 1e-9, "{f:?}");
    assert!(f.source.contains("FocalPlaneXResolution"), "{f:?}");
    // Resolution per inch (the default unit): 4.2 mm · 254 px/inch / 25.4 = 42 px.
    jpeg_with_exif(
        &a,
        64,
        48,
        &[
            field(Tag::FocalLength, rational(42, 10)),
            field(Tag::FocalPlaneXResolution, rational(254, 1)),
        ],
    );
    let f = exif::focal_from_exif(&a, 64, 48).unwrap();
    assert!((f.focal_px - 42.0).abs() < 1e-9, "{f:?}");
    // A phone: only the 35 mm equivalent. 27 mm on a 36 mm frame, long side 64 px → 48 px.
    jpeg_with_exif(
        &a,
        64,
        48,
        &[
            field(Tag::FocalLength, rational(42, 10)),
            field(Tag::FocalLengthIn35mmFilm, Value::Short(vec![27])),
        ],
    );
    let f = exif::focal_from_exif(&a, 64, 48).unwrap();
    assert!((f.focal_px - 48.0).abs() < 1e-9, "{f:?}");
    assert!(f.source.contains("35mm"), "{f:?}");
    // The folder's focal is the first photo's; photos without EXIF give none.
    let g = exif::folder_focal(&dir.path().join("photos")).unwrap();
    assert_eq!(g.image, a);
    let plain = dir.path().join("plain/b.png");
    write_img(&plain, 8, 6, 1);
    assert!(exif::folder_focal(plain.parent().unwrap()).is_none());
    // `gems info` says where the focal came from.
    let s = open_scene(&dir.path().join("photos"), &OpenOptions::default()).unwrap();
    let text = scene_info(&s, false).unwrap().to_string();
    assert!(
        text.contains("focal 48.0 px for the SfM from EXIF FocalLengthIn35mmFilm 27 mm"),
        "{text}"
    );
}

/// E2NeRF's synthetic scenes (`iCVTEAM/E2NeRF:load_blender.py`): `transform_train.json` lists
/// every rendered frame but only the even ones ship an image in `train/`; each train frame holds
/// a list of matrices along the exposure and no `file_path`; sharp `test/` images are taken at
/// matrix 1. Views keep the file order (r_10 after r_8, not after r_0).
#[test]
fn e2nerf_synthetic_scene_opens_in_file_order_with_subframes() {
    use gems_data::nerfstudio::{CameraSpec, Frame, Transforms};
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().join("lego");
    let (w, h) = (10u32, 8u32);
    let sub = |i: usize| -> Vec<Pose> { (0..5).map(|j| pose(10 * i + j)).collect() };
    let frames = |n: usize, split: &str| -> Transforms {
        Transforms {
            frames: (0..n)
                .map(|i| Frame {
                    file_path: format!("./{split}/r_{i}"),
                    pose: sub(i)[2],
                    subframe_poses: sub(i),
                    camera: CameraSpec::FovX(0.69),
                    split: None,
                })
                .collect(),
        }
    };
    for i in (0..12).step_by(2) {
        write_img(&root.join(format!("train/r_{i}.png")), w, h, i);
    }
    for i in 0..3 {
        write_img(&root.join(format!("test/r_{i}.png")), w, h, 100 + i);
    }
    for (split, n) in [("train", 12), ("test", 3)] {
        let path = root.join(format!("transform_{split}.json"));
        nerfstudio::write_transforms(&path, &frames(n, split)).unwrap();
        // E2NeRF's files name no image: the loader makes `<split>/r_<i>.png` itself.
        let mut json: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
        for f in json["frames"].as_array_mut().unwrap() {
            f.as_object_mut().unwrap().remove("file_path");
        }
        std::fs::write(&path, json.to_string()).unwrap();
    }
    let before = snapshot(&root);
    let s = open_scene(&root, &OpenOptions::default()).unwrap();
    assert_eq!(
        (s.layout, s.dataset.as_str()),
        (Layout::Blender, "E2NeRF synthetic")
    );
    let names: Vec<&str> = s.views.iter().map(|v| v.name.as_str()).collect();
    assert_eq!(
        names,
        [
            "train_r_0.png",
            "train_r_2.png",
            "train_r_4.png",
            "train_r_6.png",
            "train_r_8.png",
            "train_r_10.png",
            "test_r_0.png",
            "test_r_1.png",
            "test_r_2.png"
        ]
    );
    let close = |a: &Pose, b: &Pose| {
        a.center()
            .iter()
            .zip(b.center())
            .all(|(x, y)| (x - y).abs() < 1e-9)
    };
    // Train view r_10: the middle of its five exposure matrices starts it; all five are its
    // ground-truth sub-frames.
    let v = &s.views[5];
    assert_eq!(v.split, Split::Train);
    assert!(close(v.pose.as_ref().unwrap(), &pose(102)));
    let subs = v.gt_subframe_poses.as_ref().unwrap();
    assert_eq!(subs.len(), 5);
    assert!(close(&subs[4], &pose(104)));
    assert!(v.sharp_gt.is_none());
    // Test view r_1: sharp, at matrix 1 of its list.
    let t = &s.views[7];
    assert_eq!(t.split, Split::NovelView);
    assert_eq!(
        t.sharp_gt.as_deref(),
        Some(root.join("test/r_1.png").as_path())
    );
    assert!(close(t.pose.as_ref().unwrap(), &pose(11)));
    assert!(t.gt_subframe_poses.is_none());
    let k = t.intrinsics.unwrap();
    assert!((k.fx - 0.5 * 10.0 / (0.5f64 * 0.69).tan()).abs() < 1e-9);
    assert!(
        s.uses
            .iter()
            .any(|u| u.role.contains("6 of 12 frames have an image")),
        "{:?}",
        s.uses
    );
    assert_eq!(s.nvs_eval_views().count(), 3);
    // Downscaled: copies of train/ and test/ go to the cache, never into the scene.
    let cache = dir.path().join("cache");
    let s2 = open_scene(
        &root,
        &OpenOptions {
            downscale: 2,
            cache_dir: Some(cache.clone()),
            ..OpenOptions::default()
        },
    )
    .unwrap();
    assert_eq!((s2.views[0].width, s2.views[0].height), (5, 4));
    assert!(s2.views.iter().all(|v| v.image.starts_with(&cache)));
    assert_eq!(s2.views[6].name, "test_r_0.png");
    assert_eq!(snapshot(&root), before);
}

/// The NeRF-synthetic layout itself: `transforms_{train,test}.json` with `file_path` and one
/// matrix per frame; a train frame whose image is missing is skipped, a split with none is an
/// error naming the folder.
#[test]
fn nerf_synthetic_scene_opens_and_a_split_without_images_is_an_error() {
    use gems_data::nerfstudio::{CameraSpec, Frame, Transforms};
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().join("chair");
    let t = |split: &str, n: usize| Transforms {
        frames: (0..n)
            .map(|i| Frame {
                file_path: format!("./{split}/r_{i}"),
                pose: pose(i),
                subframe_poses: Vec::new(),
                camera: CameraSpec::FovX(0.69),
                split: None,
            })
            .collect(),
    };
    for i in 0..3 {
        write_img(&root.join(format!("train/r_{i}.png")), 6, 4, i);
    }
    nerfstudio::write_transforms(&root.join("transforms_train.json"), &t("train", 4)).unwrap();
    nerfstudio::write_transforms(&root.join("transforms_test.json"), &t("test", 2)).unwrap();
    let e = open_scene(&root, &OpenOptions::default())
        .unwrap_err()
        .to_string();
    assert!(e.contains("test") && e.contains("2 frames"), "{e}");
    for i in 0..2 {
        write_img(&root.join(format!("test/r_{i}.png")), 6, 4, 9 + i);
    }
    let s = open_scene(&root, &OpenOptions::default()).unwrap();
    assert_eq!(
        (s.layout, s.dataset.as_str()),
        (Layout::Blender, "NeRF-Blender synthetic")
    );
    assert_eq!(
        (s.train_views().count(), s.nvs_eval_views().count()),
        (3, 2)
    );
    assert!(s.views[0].gt_subframe_poses.is_none());
    assert_eq!("blender".parse::<Layout>(), Ok(Layout::Blender));
}

/// The committed fixture `testdata/scenes/deblur_nerf_real_png_model/`: a Deblur-NeRF real scene
/// as redistributed (`Dojizz/NGP-Deblur-NeRF:blurball`), in miniature. JPG photos in `images/`,
/// PNG copies in `images_4/`, `poses_bounds.npy`, `hold=7`, and a `sparse/0` made on the PNG
/// copies: its images are named `000.png`…, in a frame other than the poses file's (scaled,
/// rotated, moved), and it leaves `004` unregistered, as COLMAP does with a photo too blurred.
fn fixture_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../testdata/scenes/deblur_nerf_real_png_model")
}

const FIXTURE_VIEWS: usize = 9;
const FIXTURE_UNREGISTERED: usize = 4;

/// The similarity from the fixture's poses-file frame to its model's frame.
fn fixture_similarity() -> gems_math::Sim3 {
    let r = Pose::from_quaternion([0.9, 0.1, -0.3, 0.2], [0.0; 3]);
    gems_math::Sim3 {
        scale: 2.5,
        rot: gems_math::Se3::from(&r).rot,
        trans: gems_math::Vector3::new(0.4, -1.0, 3.0),
    }
}

fn fixture_model_pose(i: usize) -> Pose {
    let c2w = gems_math::Se3::from(&pose(i)).inverse();
    Pose::from(&fixture_similarity().act_c2w(&c2w).inverse())
}

/// Writes the fixture: `GEMS_WRITE_FIXTURES=1 cargo test --release -p gems-data --test datasets
/// write_png_model_fixture`. Without the variable it checks that the committed files are the
/// ones this code writes (so the fixture and its description cannot drift apart).
#[test]
fn write_png_model_fixture() {
    let out = tempfile::tempdir().unwrap();
    let root = if std::env::var_os("GEMS_WRITE_FIXTURES").is_some() {
        fixture_root()
    } else {
        out.path().to_path_buf()
    };
    let (w, h) = (32, 24);
    for i in 0..FIXTURE_VIEWS {
        write_img(&root.join(format!("images/{i:03}.jpg")), w, h, i as u32);
        write_img(
            &root.join(format!("images_4/{i:03}.png")),
            w / 4,
            h / 4,
            i as u32,
        );
    }
    llff::write_poses_bounds(&root.join("poses_bounds.npy"), &rows(FIXTURE_VIEWS, w, h)).unwrap();
    let model = SparseModel {
        cameras: vec![Camera {
            id: 1,
            model: CameraModel::Pinhole,
            width: (w / 4) as u64,
            height: (h / 4) as u64,
            params: vec![7.5, 7.5, 4.0, 3.0],
        }],
        images: (0..FIXTURE_VIEWS)
            .filter(|&i| i != FIXTURE_UNREGISTERED)
            .map(|i| {
                Image::from_pose(
                    i as u32 + 1,
                    1,
                    &format!("{i:03}.png"),
                    &fixture_model_pose(i),
                )
            })
            .collect(),
        points: vec![],
    };
    colmap::write_model(&root.join("sparse/0"), &model, ModelFormat::Binary).unwrap();
    write_hold_marker(&root, 7).unwrap();
    if root != fixture_root() {
        // Compare the files that do not depend on an image encoder's version.
        for f in [
            "poses_bounds.npy",
            "sparse/0/images.bin",
            "sparse/0/cameras.bin",
            "hold=7",
        ] {
            assert_eq!(
                std::fs::read(root.join(f)).unwrap(),
                std::fs::read(fixture_root().join(f)).unwrap(),
                "{f} differs from the committed fixture"
            );
        }
    }
}

#[test]
fn a_png_named_model_poses_jpg_photos_and_the_poses_file_fills_what_it_misses() {
    let root = fixture_root();
    let before = snapshot(&root);
    let dir = tempfile::tempdir().unwrap();
    let opts = OpenOptions {
        downscale: 4,
        cache_dir: Some(dir.path().to_path_buf()),
        ..OpenOptions::default()
    };
    let s = open_scene(&root, &opts).unwrap();
    assert_eq!(snapshot(&root), before, "opening wrote into the scene");
    assert_eq!(s.views.len(), FIXTURE_VIEWS);
    assert_eq!(s.pose_source, PoseSource::Sfm);
    let m = s.sfm_match.unwrap();
    assert_eq!(m.rule, colmap::NameRule::Stem);
    assert_eq!((m.matched, m.views), (FIXTURE_VIEWS - 1, FIXTURE_VIEWS));
    // Every view has a pose in the model's frame: the registered ones the model's own, the one
    // it misses the poses file's carried by the similarity of the other eight.
    for (i, v) in s.views.iter().enumerate() {
        let got = v.pose.unwrap_or_else(|| panic!("{} has no pose", v.name));
        let want = fixture_model_pose(i);
        let d = gems_math::Se3::from(&got).inverse();
        let e = gems_math::Se3::from(&want).inverse();
        assert!(
            (d.trans - e.trans).norm() < 1e-9 && (d.rot - e.rot).norm() < 1e-9,
            "{}: {got:?} vs {want:?}",
            v.name
        );
        let k = v.intrinsics.unwrap();
        assert!((k.fx - 7.5).abs() < 1e-12, "{}: {k:?}", v.name);
    }
    // The model, keyed by the views' names, finds each registered view.
    let model = s.sfm.as_ref().unwrap();
    assert!(model.image_by_name("000.jpg").is_some());
    assert!(model.image_by_name("004.jpg").is_none());
    let uses: Vec<String> = s
        .uses
        .iter()
        .map(|u| format!("{}: {}", u.path.display(), u.role))
        .collect();
    assert!(
        uses.iter().any(|u| u.contains("sparse/0")
            && u.contains("8 of 9 views")
            && u.contains("by file stem")),
        "{uses:?}"
    );
    assert!(
        uses.iter().any(|u| u.contains("poses_bounds.npy")
            && u.contains("004.jpg")
            && u.contains("model's frame")),
        "{uses:?}"
    );
    assert!(!uses.iter().any(|u| u.contains("not used")), "{uses:?}");
    let text = scene_info(&s, false).unwrap().to_string();
    assert!(
        text.contains("8 of 9 views posed by it, images matched by file stem"),
        "{text}"
    );
}

#[test]
fn a_model_that_names_no_view_is_not_used_and_the_poses_file_poses_them() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().join("scene");
    make_deblur_nerf_real(&root, 9);
    // A model of two images no view is called.
    let mut model = colmap::read_model(&root.join("sparse/0")).unwrap();
    model.images.truncate(2);
    model.images[0].name = "x.png".into();
    model.images[1].name = "y.png".into();
    colmap::write_model(&root.join("sparse/0"), &model, ModelFormat::Binary).unwrap();
    let s = open_scene(&root, &OpenOptions::default()).unwrap();
    assert_eq!(s.pose_source, PoseSource::Llff);
    assert!(s.sfm.is_none());
    assert_eq!(s.sfm_match.unwrap().matched, 0);
    assert!(s.views.iter().all(|v| v.pose.is_some()));
    let roles: Vec<&str> = s.uses.iter().map(|u| u.role.as_str()).collect();
    assert!(
        roles
            .iter()
            .any(|r| r.starts_with("not used: none of its 2 images")),
        "{roles:?}"
    );
    assert!(
        roles.contains(&"starting poses and intrinsics"),
        "{roles:?}"
    );
}

//! COLMAP reader/writer tests: byte-exact binary round trip, text round trip, hand-made files,
//! malformed inputs and "arbitrary bytes never panic".

use gems_data::DataError;
use gems_data::colmap::*;
use proptest::prelude::*;

fn sample_model() -> SparseModel {
    SparseModel {
        cameras: vec![
            Camera {
                id: 3,
                model: CameraModel::Pinhole,
                width: 400,
                height: 270,
                params: vec![350.5, 351.25, 200.0, 135.0],
            },
            Camera {
                id: 0,
                model: CameraModel::Opencv,
                width: 800,
                height: 540,
                params: vec![700.0, 701.0, 400.0, 270.0, 0.01, -0.002, 1e-4, -2e-5],
            },
        ],
        images: vec![
            Image {
                id: 0,
                qvec: [0.9, 0.1, -0.2, 0.3],
                tvec: [1.0, -2.0, 0.1234567890123],
                camera_id: 3,
                name: "img 000.png".into(),
                points2d: vec![
                    Point2D {
                        x: 10.5,
                        y: 20.25,
                        point3d_id: 7,
                    },
                    Point2D {
                        x: 1.0 / 3.0,
                        y: 2.0,
                        point3d_id: INVALID_POINT3D_ID,
                    },
                ],
            },
            Image {
                id: 5,
                qvec: [1.0, 0.0, 0.0, 0.0],
                tvec: [0.0, 0.0, 0.0],
                camera_id: 0,
                name: "b.jpg".into(),
                points2d: vec![],
            },
        ],
        points: vec![
            Point3D {
                id: 7,
                xyz: [0.1, 0.2, 3.0],
                rgb: [255, 0, 17],
                error: 0.75,
                track: vec![(0, 0)],
            },
            Point3D {
                id: 9,
                xyz: [-1e-9, 2e10, 5.5],
                rgb: [1, 2, 3],
                error: -1.0,
                track: vec![],
            },
        ],
    }
}

#[test]
fn binary_round_trip_is_byte_exact() {
    let dir = tempfile::tempdir().unwrap();
    let m = sample_model();
    write_model(dir.path(), &m, ModelFormat::Binary).unwrap();
    let back = read_model(dir.path()).unwrap();
    assert_eq!(back, m);
    for f in ["cameras.bin", "images.bin", "points3D.bin"] {
        let a = std::fs::read(dir.path().join(f)).unwrap();
        let d2 = tempfile::tempdir().unwrap();
        write_model(d2.path(), &back, ModelFormat::Binary).unwrap();
        assert_eq!(a, std::fs::read(d2.path().join(f)).unwrap(), "{f}");
    }
}

#[test]
fn text_round_trip_preserves_values() {
    let dir = tempfile::tempdir().unwrap();
    let m = sample_model();
    write_model(dir.path(), &m, ModelFormat::Text).unwrap();
    assert_eq!(detect_format(dir.path()), Some(ModelFormat::Text));
    let back = read_model(dir.path()).unwrap();
    assert_eq!(back, m);
}

/// A binary file assembled field by field from the documented layout (not with our writer).
#[test]
fn hand_made_binary_cameras_parse() {
    let mut b = Vec::new();
    b.extend_from_slice(&1u64.to_le_bytes());
    b.extend_from_slice(&42u32.to_le_bytes());
    b.extend_from_slice(&0i32.to_le_bytes()); // SIMPLE_PINHOLE
    b.extend_from_slice(&640u64.to_le_bytes());
    b.extend_from_slice(&480u64.to_le_bytes());
    for p in [500.0f64, 320.0, 240.0] {
        b.extend_from_slice(&p.to_le_bytes());
    }
    let cams = parse_cameras_bin(&b).unwrap();
    assert_eq!(cams.len(), 1);
    assert_eq!(cams[0].id, 42);
    assert_eq!(cams[0].model, CameraModel::SimplePinhole);
    let k = cams[0].intrinsics().unwrap();
    assert_eq!(
        (k.fx, k.fy, k.cx, k.cy, k.width, k.height),
        (500.0, 500.0, 320.0, 240.0, 640, 480)
    );
}

#[test]
fn hand_made_text_model_parses() {
    let cams = parse_cameras_txt(
        "# Camera list with one line of data per camera:\n\
         #   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n\
         # Number of cameras: 2\n\
         1 SIMPLE_RADIAL 100 80 90 50 40 0\n\
         2 RADIAL 100 80 90 50 40 0.1 0\n",
    )
    .unwrap();
    assert_eq!(cams.len(), 2);
    assert_eq!(cams[0].intrinsics().unwrap().fx, 90.0);
    let err = cams[1].intrinsics().unwrap_err();
    assert!(err.contains("distortion"), "{err}");
    let imgs = parse_images_txt(
        "# header\n\
         1 1 0 0 0 0.5 0 0 1 my image.png\n\
         \n\
         2 0.7071067811865476 0 0.7071067811865476 0 1 2 3 1 b.png\n\
         1.5 2.5 -1 3 4 10\n",
    )
    .unwrap();
    assert_eq!(imgs.len(), 2);
    assert_eq!(imgs[0].name, "my image.png");
    assert!(imgs[0].points2d.is_empty());
    assert_eq!(imgs[1].points2d[0].point3d_id, INVALID_POINT3D_ID);
    assert_eq!(imgs[1].points2d[1].point3d_id, 10);
    // 90° about y: camera x axis (first row of R) maps world z to camera x.
    let p = imgs[1].pose();
    let cam = p.transform_point([0.0, 0.0, 1.0]);
    assert!(
        (cam[0] - 2.0).abs() < 1e-12
            && (cam[1] - 2.0).abs() < 1e-12
            && (cam[2] - 3.0).abs() < 1e-12
    );
    let pts = parse_points3d_txt("# c\n7 1 2 3 255 128 0 0.5 1 0 2 1\n").unwrap();
    assert_eq!(pts[0].track, vec![(1, 0), (2, 1)]);
    assert_eq!(pts[0].rgb, [255, 128, 0]);
}

fn write_files(dir: &std::path::Path, files: &[(&str, &[u8])]) {
    for (n, b) in files {
        std::fs::write(dir.join(n), b).unwrap();
    }
}

fn assert_names(err: DataError, file: &str, needle: &str) {
    let msg = err.to_string();
    assert!(msg.contains(file), "error {msg:?} should name {file}");
    assert!(
        msg.contains(needle),
        "error {msg:?} should mention {needle:?}"
    );
}

#[test]
fn truncated_binary_names_the_file() {
    let m = sample_model();
    let dir = tempfile::tempdir().unwrap();
    write_model(dir.path(), &m, ModelFormat::Binary).unwrap();
    let full = images_to_bin(&m.images);
    for cut in [0, 7, 8, 20, full.len() - 1] {
        std::fs::write(dir.path().join("images.bin"), &full[..cut]).unwrap();
        assert_names(
            read_model(dir.path()).unwrap_err(),
            "images.bin",
            "truncated",
        );
    }
}

#[test]
fn malformed_models_give_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let m = sample_model();
    write_model(dir.path(), &m, ModelFormat::Text).unwrap();
    // Unknown camera model.
    write_files(
        dir.path(),
        &[("cameras.txt", b"3 WEIRD 1 1 1\n0 PINHOLE 1 1 1 1 1 1\n")],
    );
    assert_names(
        read_model(dir.path()).unwrap_err(),
        "cameras.txt",
        "unknown camera model",
    );
    // Wrong parameter count.
    write_files(dir.path(), &[("cameras.txt", b"3 PINHOLE 1 1 1 1 1\n")]);
    assert_names(
        read_model(dir.path()).unwrap_err(),
        "cameras.txt",
        "needs 4 parameters",
    );
    // Image referring to a missing camera.
    write_files(
        dir.path(),
        &[("cameras.txt", b"3 PINHOLE 400 270 1 1 1 1\n")],
    );
    assert_names(
        read_model(dir.path()).unwrap_err(),
        "images.txt",
        "camera 0",
    );
    // NaN pose.
    write_files(
        dir.path(),
        &[
            ("cameras.txt", b"3 PINHOLE 400 270 1 1 1 1\n".as_slice()),
            ("images.txt", b"1 nan 0 0 0 0 0 0 3 a.png\n\n"),
            ("points3D.txt", b""),
        ],
    );
    assert_names(
        read_model(dir.path()).unwrap_err(),
        "images.txt",
        "invalid pose",
    );
    // Missing points2D line.
    write_files(dir.path(), &[("images.txt", b"1 1 0 0 0 0 0 0 3 a.png")]);
    assert_names(
        read_model(dir.path()).unwrap_err(),
        "images.txt",
        "POINTS2D",
    );
    // Track pointing at a non-existent image.
    write_files(
        dir.path(),
        &[
            ("images.txt", b"1 1 0 0 0 0 0 0 3 a.png\n\n".as_slice()),
            ("points3D.txt", b"1 0 0 0 1 1 1 0 99 0\n"),
        ],
    );
    assert_names(
        read_model(dir.path()).unwrap_err(),
        "points3D.txt",
        "image 99",
    );
    // Missing file.
    std::fs::remove_file(dir.path().join("points3D.txt")).unwrap();
    assert_names(
        read_model(dir.path()).unwrap_err(),
        "points3D.txt",
        "missing",
    );
    // Unknown binary model id.
    let d2 = tempfile::tempdir().unwrap();
    write_model(d2.path(), &m, ModelFormat::Binary).unwrap();
    let mut cams = cameras_to_bin(&m.cameras);
    cams[12..16].copy_from_slice(&77i32.to_le_bytes());
    std::fs::write(d2.path().join("cameras.bin"), cams).unwrap();
    assert_names(
        read_model(d2.path()).unwrap_err(),
        "cameras.bin",
        "unknown camera model id 77",
    );
}

#[test]
fn unsupported_models_are_explained() {
    let cam = Camera {
        id: 1,
        model: CameraModel::OpencvFisheye,
        width: 10,
        height: 10,
        params: vec![1.0; 8],
    };
    assert!(cam.intrinsics().unwrap_err().contains("OPENCV_FISHEYE"));
    let cam = Camera {
        model: CameraModel::Opencv,
        params: vec![5.0, 6.0, 5.0, 5.0, 0.0, 0.0, 0.0, 0.0],
        ..cam
    };
    let k = cam.intrinsics().unwrap();
    assert_eq!((k.fx, k.fy), (5.0, 6.0));
}

#[test]
fn model_names_and_ids_agree() {
    for id in 0..11 {
        let m = CameraModel::from_id(id).unwrap();
        assert_eq!(m.id(), id);
        assert_eq!(CameraModel::from_name(m.name()), Some(m));
    }
    assert_eq!(CameraModel::from_id(11), None);
    assert_eq!(CameraModel::from_id(-1), None);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]
    #[test]
    fn arbitrary_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..512)) {
        let _ = parse_cameras_bin(&bytes);
        let _ = parse_images_bin(&bytes);
        let _ = parse_points3d_bin(&bytes);
        let text = String::from_utf8_lossy(&bytes);
        let _ = parse_cameras_txt(&text);
        let _ = parse_images_txt(&text);
        let _ = parse_points3d_txt(&text);
    }

    /// Mutating valid files (bit flips, truncation) must also never panic.
    #[test]
    fn mutated_valid_files_never_panic(pos in 0usize..400, val in any::<u8>(), cut in 0usize..400) {
        let m = sample_model();
        for mut b in [cameras_to_bin(&m.cameras), images_to_bin(&m.images), points3d_to_bin(&m.points)] {
            let p = pos % b.len();
            b[p] = val;
            b.truncate(cut.max(1).min(b.len()));
            let _ = parse_cameras_bin(&b);
            let _ = parse_images_bin(&b);
            let _ = parse_points3d_bin(&b);
        }
    }
}

fn arb_camera() -> impl Strategy<Value = Camera> {
    (any::<u32>(), 0i32..11, 1u64..10_000, 1u64..10_000).prop_flat_map(|(id, m, w, h)| {
        let model = CameraModel::from_id(m).unwrap();
        proptest::collection::vec(-1e6f64..1e6, model.num_params()).prop_map(move |params| Camera {
            id,
            model,
            width: w,
            height: h,
            params,
        })
    })
}

fn arb_image() -> impl Strategy<Value = Image> {
    (
        any::<u32>(),
        proptest::array::uniform4(-1.0f64..1.0),
        proptest::array::uniform3(-1e3f64..1e3),
        any::<u32>(),
        "[a-zA-Z0-9_][a-zA-Z0-9_ ./-]{0,20}[a-zA-Z0-9_]",
        proptest::collection::vec(
            (
                -1e4f64..1e4,
                -1e4f64..1e4,
                prop_oneof![Just(INVALID_POINT3D_ID), 0u64..1_000_000],
            ),
            0..6,
        ),
    )
        .prop_map(|(id, qvec, tvec, camera_id, name, pts)| Image {
            id,
            qvec,
            tvec,
            camera_id,
            name,
            points2d: pts
                .into_iter()
                .map(|(x, y, point3d_id)| Point2D { x, y, point3d_id })
                .collect(),
        })
}

fn arb_point() -> impl Strategy<Value = Point3D> {
    (
        any::<u64>(),
        proptest::array::uniform3(-1e6f64..1e6),
        proptest::array::uniform3(any::<u8>()),
        -1.0f64..10.0,
        proptest::collection::vec((any::<u32>(), any::<u32>()), 0..5),
    )
        .prop_map(|(id, xyz, rgb, error, track)| Point3D {
            id,
            xyz,
            rgb,
            error,
            track,
        })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(128))]
    /// Any model survives binary serialisation exactly and text serialisation exactly (shortest
    /// round-trip float formatting), and the text form parses back to the binary form's model.
    #[test]
    fn arbitrary_models_round_trip(
        cameras in proptest::collection::vec(arb_camera(), 0..4),
        images in proptest::collection::vec(arb_image(), 0..4),
        points in proptest::collection::vec(arb_point(), 0..4),
    ) {
        let cb = cameras_to_bin(&cameras);
        prop_assert_eq!(&parse_cameras_bin(&cb).unwrap(), &cameras);
        let ib = images_to_bin(&images);
        prop_assert_eq!(&parse_images_bin(&ib).unwrap(), &images);
        let pb = points3d_to_bin(&points);
        prop_assert_eq!(&parse_points3d_bin(&pb).unwrap(), &points);
        prop_assert_eq!(&parse_cameras_txt(&cameras_to_txt(&cameras)).unwrap(), &cameras);
        prop_assert_eq!(&parse_images_txt(&images_to_txt(&images)).unwrap(), &images);
        prop_assert_eq!(&parse_points3d_txt(&points3d_to_txt(&points)).unwrap(), &points);
    }
}

fn named(names: &[&str]) -> SparseModel {
    SparseModel {
        cameras: vec![],
        images: names
            .iter()
            .enumerate()
            .map(|(i, n)| Image::from_pose(i as u32 + 1, 1, n, &gems_math::Pose::IDENTITY))
            .collect(),
        points: vec![],
    }
}

fn strings(names: &[&str]) -> Vec<String> {
    names.iter().map(|s| s.to_string()).collect()
}

#[test]
fn model_images_are_keyed_by_name_then_stem_then_sorted_order() {
    // Exact names: nothing renamed.
    let mut m = named(&["b.jpg", "a.jpg"]);
    let k = m.key_by_view_names(&strings(&["a.jpg", "b.jpg"]));
    assert_eq!((k.rule, k.matched, k.views), (NameRule::Exact, 2, 2));
    assert_eq!(m.images[0].name, "b.jpg");
    // Stems (a model made on the PNG copies of JPG photos), in any order.
    let mut m = named(&["001.png", "000.png", "002.png"]);
    let k = m.key_by_view_names(&strings(&["000.jpg", "001.jpg", "002.jpg"]));
    assert_eq!((k.rule, k.matched), (NameRule::Stem, 3));
    assert_eq!(m.images[0].name, "001.jpg");
    assert_eq!(m.image_by_name("000.jpg").unwrap().id, 2);
    // Other names, same count: sorted order.
    let mut m = named(&["frame_b.png", "frame_a.png"]);
    let k = m.key_by_view_names(&strings(&["IMG_1.JPG", "IMG_2.JPG"]));
    assert_eq!((k.rule, k.matched), (NameRule::SortedOrder, 2));
    assert_eq!(m.image_by_name("IMG_1.JPG").unwrap().id, 2);
    // Sorted order that contradicts a match by stem is not taken: the stem match stands alone.
    // (sorted, a.jpg would take b.png and b.jpg c.png).
    let mut m = named(&["c.png", "b.png"]);
    let k = m.key_by_view_names(&strings(&["a.jpg", "b.jpg"]));
    assert_eq!((k.rule, k.matched), (NameRule::Stem, 1));
    assert_eq!(m.image_by_name("b.jpg").unwrap().id, 2);
    assert!(m.image_by_name("a.jpg").is_none());
    // One that agrees with the stems it found is taken.
    let mut m = named(&["c.png", "a.png"]);
    let k = m.key_by_view_names(&strings(&["a.jpg", "b.jpg"]));
    assert_eq!((k.rule, k.matched), (NameRule::SortedOrder, 2));
    assert_eq!(m.image_by_name("b.jpg").unwrap().id, 1);
    // Fewer model images than views: the partial match by stem, the rest unposed.
    let mut m = named(&["000.png", "002.png"]);
    let k = m.key_by_view_names(&strings(&["000.jpg", "001.jpg", "002.jpg"]));
    assert_eq!((k.rule, k.matched, k.model_images), (NameRule::Stem, 2, 2));
    // Two images with one stem match neither view by stem.
    let mut m = named(&["a.png", "a.jpg", "z.png"]);
    let k = m.key_by_view_names(&strings(&["a.tif", "q.tif"]));
    assert_eq!(k.matched, 0);
    // Nothing in common, counts differ: no match, nothing renamed.
    let mut m = named(&["x.png"]);
    let k = m.key_by_view_names(&strings(&["a.jpg", "b.jpg"]));
    assert_eq!(k.matched, 0);
    assert_eq!(m.images[0].name, "x.png");
}

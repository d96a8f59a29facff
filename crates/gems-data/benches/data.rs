//! Benchmarks of the data layer: COLMAP binary parsing at SfM-model scale, area downscaling at
//! ExBluRF resolution, LLFF parsing, and opening a scene folder.

use std::sync::LazyLock;

use gems_data::colmap::{self, Image, Point2D, Point3D};
use gems_data::image::downscale_area;
use gems_data::llff::{self, LlffRow};
use gems_data::{ImageRgb, OpenOptions};
use gems_math::Pose;

fn main() {
    divan::main();
}

/// 200 images × 2000 keypoints and 100k points with 4-view tracks (a VGGSfM-sized model).
static MODEL: LazyLock<(Vec<u8>, Vec<u8>)> = LazyLock::new(|| {
    let images: Vec<Image> = (0..200u32)
        .map(|i| Image {
            id: i + 1,
            qvec: [1.0, 0.0, 0.0, 0.0],
            tvec: [i as f64, 0.0, 0.0],
            camera_id: 1,
            name: format!("{i:05}.png"),
            points2d: (0..2000u64)
                .map(|k| Point2D {
                    x: k as f64 * 0.5,
                    y: k as f64 * 0.25,
                    point3d_id: k * 50 + u64::from(i) % 50,
                })
                .collect(),
        })
        .collect();
    let points: Vec<Point3D> = (0..100_000u64)
        .map(|k| Point3D {
            id: k,
            xyz: [k as f64, 1.0, 2.0],
            rgb: [1, 2, 3],
            error: 0.5,
            track: (0..4)
                .map(|j| ((k % 200) as u32 + j, k as u32 % 2000))
                .collect(),
        })
        .collect();
    (
        colmap::images_to_bin(&images),
        colmap::points3d_to_bin(&points),
    )
});

#[divan::bench]
fn colmap_parse_images_bin_200x2000(b: divan::Bencher) {
    let bytes = &MODEL.0;
    b.counter(divan::counter::BytesCount::new(bytes.len()))
        .bench(|| colmap::parse_images_bin(divan::black_box(bytes)).unwrap());
}

#[divan::bench]
fn colmap_parse_points3d_bin_100k(b: divan::Bencher) {
    let bytes = &MODEL.1;
    b.counter(divan::counter::BytesCount::new(bytes.len()))
        .bench(|| colmap::parse_points3d_bin(divan::black_box(bytes)).unwrap());
}

#[divan::bench]
fn llff_parse_1000_rows(b: divan::Bencher) {
    let rows: Vec<LlffRow> = (0..1000)
        .map(|i| LlffRow::from_pose(&Pose::IDENTITY, 540.0, 800.0, 700.0, 0.1, i as f64))
        .collect();
    let bytes = llff::poses_bounds_to_bytes(&rows);
    b.bench(|| llff::parse_poses_bounds(divan::black_box(&bytes)).unwrap());
}

#[divan::bench(args = [2, 4])]
fn downscale_area_800x540(b: divan::Bencher, factor: u32) {
    let mut img = ImageRgb::new(800, 540);
    for (i, v) in img.data.iter_mut().enumerate() {
        *v = (i % 251) as f32 / 250.0;
    }
    b.bench(|| downscale_area(divan::black_box(&img), 800 / factor, 540 / factor));
}

/// Opening a 24-view GeMS-layout folder (headers only, no pixel decoding).
#[divan::bench(sample_count = 20)]
fn open_scene_24_views(b: divan::Bencher) {
    let dir = tempfile::tempdir().unwrap();
    let img = ImageRgb::new(400, 270);
    for i in 0..24 {
        gems_data::save_png(&dir.path().join(format!("images/{i:03}.png")), &img).unwrap();
        gems_data::save_png(&dir.path().join(format!("images_test/{i:03}.png")), &img).unwrap();
    }
    b.bench(|| gems_data::open_scene(dir.path(), &OpenOptions::default()).unwrap());
}

/// Undistorting an 800×540 OPENCV image: building the map (once per camera) and applying it.
#[divan::bench]
fn undistort_build_map_800x540(b: divan::Bencher) {
    let cam = opencv_camera();
    b.bench(|| gems_data::undistort::UndistortMap::new(divan::black_box(&cam), 800, 540).unwrap());
}

#[divan::bench]
fn undistort_apply_800x540(b: divan::Bencher) {
    let map = gems_data::undistort::UndistortMap::new(&opencv_camera(), 800, 540).unwrap();
    let img = ImageRgb::new(800, 540);
    b.bench(|| map.apply(divan::black_box(&img)).unwrap());
}

fn opencv_camera() -> colmap::Camera {
    colmap::Camera {
        id: 1,
        model: colmap::CameraModel::Opencv,
        width: 800,
        height: 540,
        params: vec![700.0, 700.0, 400.0, 270.0, -0.2, 0.05, 0.001, -0.001],
    }
}

//! COLMAP text parsers (cameras/images/points3D): never panic on any UTF-8 input.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(text) = std::str::from_utf8(data) {
        let _ = gems_data::colmap::parse_cameras_txt(text);
        let _ = gems_data::colmap::parse_images_txt(text);
        let _ = gems_data::colmap::parse_points3d_txt(text);
    }
});

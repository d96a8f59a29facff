//! `points3D.bin` parser: must return Ok or Err, never panic or over-allocate; a parsed model
//! re-serialises to the same bytes.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(points) = gems_data::colmap::parse_points3d_bin(data) {
        assert_eq!(gems_data::colmap::points3d_to_bin(&points), data);
    }
});

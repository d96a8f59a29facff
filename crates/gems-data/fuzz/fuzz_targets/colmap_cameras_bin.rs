//! `cameras.bin` parser: must return Ok or Err, never panic or over-allocate; a parsed model
//! re-serialises to the same bytes.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(cams) = gems_data::colmap::parse_cameras_bin(data) {
        assert_eq!(gems_data::colmap::cameras_to_bin(&cams), data);
    }
});

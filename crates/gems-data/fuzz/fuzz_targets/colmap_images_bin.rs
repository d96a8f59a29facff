//! `images.bin` parser: must return Ok or Err, never panic or over-allocate; a parsed model
//! re-serialises to the same bytes.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(images) = gems_data::colmap::parse_images_bin(data) {
        assert_eq!(gems_data::colmap::images_to_bin(&images), data);
    }
});

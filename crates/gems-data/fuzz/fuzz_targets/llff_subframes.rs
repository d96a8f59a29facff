//! `poses_bounds_subframes.npy` parser: never panics or over-allocates; all images have the
//! same number of sub-frames.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(sub) = gems_data::llff::parse_subframes(data) {
        if let Some(first) = sub.first() {
            assert!(sub.iter().all(|s| s.len() == first.len()));
        }
    }
});

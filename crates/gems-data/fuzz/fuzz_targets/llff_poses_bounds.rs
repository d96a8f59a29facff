//! `poses_bounds.npy` parser: never panics or over-allocates; accepted rows hold finite poses.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(rows) = gems_data::llff::parse_poses_bounds(data) {
        assert!(rows.iter().all(|r| r.pose().is_finite()));
    }
});

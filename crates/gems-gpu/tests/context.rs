//! Device selection. On CI the only adapter is Mesa lavapipe (software), which `auto` must not
//! take and `gpu` must.

use gems_gpu::{DeviceChoice, select};

#[test]
fn parses_device_choices() {
    assert_eq!("auto".parse::<DeviceChoice>(), Ok(DeviceChoice::Auto));
    assert_eq!("cpu".parse::<DeviceChoice>(), Ok(DeviceChoice::Cpu));
    assert_eq!("gpu".parse::<DeviceChoice>(), Ok(DeviceChoice::Gpu));
    assert!("cuda".parse::<DeviceChoice>().is_err());
}

#[test]
fn cpu_choice_opens_nothing() {
    assert!(select(DeviceChoice::Cpu).unwrap().is_none());
}

#[test]
fn gpu_choice_opens_an_adapter_and_auto_skips_software_ones() {
    let ctx = select(DeviceChoice::Gpu)
        .expect("--device gpu needs an adapter: install mesa-vulkan-drivers for lavapipe")
        .expect("gpu gives a context");
    eprintln!("adapter: {} (subgroups: {})", ctx.adapter, ctx.subgroups);
    // Mesa's lavapipe has had subgroup arithmetic (8 wide) since before Debian 12's 22.3: CI
    // must exercise the subgroup backward rasterizer, not only the fallback.
    if ctx.adapter.name.starts_with("llvmpipe") {
        assert!(ctx.subgroups, "lavapipe without subgroups: {}", ctx.adapter);
    }
    if ctx.adapter.is_software {
        // Only software adapters here (CI): auto must fall back to the CPU.
        match select(DeviceChoice::Auto).unwrap() {
            None => {}
            Some(hw) => assert!(!hw.adapter.is_software, "auto took {}", hw.adapter),
        }
    }
}

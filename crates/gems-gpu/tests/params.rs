//! The resident Gaussian container: upload/download round trips, growth, Adam state transfer.

mod common;

use common::{ctx, gaussians, values};
use gems_gpu::{GpuError, GpuGaussians, Group, GroupMoments};

#[test]
fn upload_download_round_trip_is_exact() {
    let ctx = ctx();
    let mut g = gaussians(777, 1);
    g.sh_degree = 2;
    let gpu = GpuGaussians::upload(ctx, &g, 1000).unwrap();
    assert_eq!((gpu.len(), gpu.capacity(), gpu.sh_degree), (777, 1000, 2));
    assert_eq!(gpu.download(ctx).unwrap(), g);
    for group in Group::ALL {
        let m = gpu.moments(ctx, group).unwrap();
        assert_eq!(m.step, 0);
        assert!(m.m.iter().chain(&m.v).all(|&x| x == 0.0), "{group:?}");
        assert_eq!(m.m.len(), 777 * group.width());
    }
}

#[test]
fn reserve_keeps_parameters_and_moments() {
    let ctx = ctx();
    let g = gaussians(300, 2);
    let mut gpu = GpuGaussians::upload(ctx, &g, 0).unwrap();
    assert_eq!(gpu.capacity(), 300);
    let mom = GroupMoments {
        m: values(300 * 48, 3, -1.0, 1.0),
        v: values(300 * 48, 4, 0.0, 1.0),
        step: 17,
    };
    gpu.set_moments(ctx, Group::Sh, &mom).unwrap();
    gpu.reserve(ctx, 5000).unwrap();
    assert_eq!(gpu.capacity(), 5000);
    assert_eq!(gpu.download(ctx).unwrap(), g);
    assert_eq!(gpu.moments(ctx, Group::Sh).unwrap(), mom);
    // Shrinking is a no-op.
    gpu.reserve(ctx, 10).unwrap();
    assert_eq!(gpu.capacity(), 5000);
}

#[test]
fn write_replaces_parameters_and_checks_the_count() {
    let ctx = ctx();
    let mut gpu = GpuGaussians::upload(ctx, &gaussians(50, 5), 64).unwrap();
    let other = gaussians(50, 6);
    gpu.write(ctx, &other).unwrap();
    assert_eq!(gpu.download(ctx).unwrap(), other);
    assert!(matches!(
        gpu.write(ctx, &gaussians(49, 6)),
        Err(GpuError::Shape(_))
    ));
    let bad = GroupMoments {
        m: vec![0.0; 3],
        v: vec![0.0; 3],
        step: 1,
    };
    assert!(gpu.set_moments(ctx, Group::Means, &bad).is_err());
}

#[test]
fn empty_and_invalid_gaussians() {
    let ctx = ctx();
    let empty = gems_splat::Gaussians::with_degree(3);
    let gpu = GpuGaussians::upload(ctx, &empty, 0).unwrap();
    assert!(gpu.is_empty());
    assert_eq!(gpu.download(ctx).unwrap(), empty);
    let mut bad = gaussians(3, 7);
    bad.quats.pop();
    assert!(matches!(
        GpuGaussians::upload(ctx, &bad, 0),
        Err(GpuError::Splat(_))
    ));
}

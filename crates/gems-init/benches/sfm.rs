//! Benchmarks of the SfM stage: bundle adjustment alone, and the whole pipeline on a small
//! blurred capture.

#[path = "../tests/common/mod.rs"]
mod common;

use gems_init::sfm::ba::{BaOptions, Focal, Observation, Pinhole, bundle_adjust};
use gems_init::sfm::{SfmOptions, run_sfm};
use gems_math::{Intrinsics, Se3};
use nalgebra::{Rotation3, Vector2, Vector3};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn main() {
    divan::main();
}

/// 20 views on an arc, 2000 points seen by every view, perturbed start, 10 LM iterations.
#[divan::bench(sample_count = 5)]
fn bundle_adjust_20_views_2000_points(bencher: divan::Bencher) {
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let k = Intrinsics {
        fx: 200.0,
        fy: 200.0,
        cx: 120.0,
        cy: 80.0,
        width: 240,
        height: 160,
    };
    let pts: Vec<Vector3<f64>> = (0..2000)
        .map(|_| {
            Vector3::new(
                rng.random_range(-2.0..2.0),
                rng.random_range(-1.0..1.0),
                rng.random_range(3.0..6.0),
            )
        })
        .collect();
    let poses: Vec<Se3> = (0..20)
        .map(|i| {
            let a = -0.3 + 0.03 * i as f64;
            let r = Rotation3::new(Vector3::new(0.0, -a, 0.0));
            let c = Vector3::new(4.0 * a.sin(), 0.0, 4.5 - 4.0 * a.cos());
            Se3::new(r.into_inner(), -(r * c))
        })
        .collect();
    let mut obs = Vec::new();
    for (ci, p) in poses.iter().enumerate() {
        for (pi, x) in pts.iter().enumerate() {
            let xy = k.project(&p.act(x))
                + Vector2::new(rng.random_range(-0.5..0.5), rng.random_range(-0.5..0.5));
            obs.push(Observation {
                cam: ci,
                point: pi,
                xy,
            });
        }
    }
    let start: Vec<Vector3<f64>> = pts
        .iter()
        .map(|x| x + Vector3::new(0.02, -0.01, 0.03))
        .collect();
    let mut fixed = vec![false; 20];
    fixed[0] = true;
    bencher.bench_local(|| {
        let mut p = poses.clone();
        let mut x = start.clone();
        let mut kk = k;
        bundle_adjust(
            &mut p,
            &fixed,
            &mut x,
            &obs,
            &mut kk,
            &BaOptions {
                huber_px: 1.0,
                max_iters: 10,
                focal: Focal::Free,
                path: None,
            },
        )
    });
}

/// The whole pipeline (features, matching, tracking, incremental mapping, BA) on 12 views of
/// 240×180 at blur level 7, focal known.
#[divan::bench(sample_count = 3)]
fn run_sfm_12_views_240px_level7(bencher: divan::Bencher) {
    let s = common::scene(12, 240, 180, 7, 0.12, 42);
    let opts = SfmOptions {
        focal_px: Some(s.focal),
        working_sizes: vec![192],
        ..SfmOptions::default()
    };
    bencher.bench_local(|| {
        run_sfm(&s.images, &opts)
            .map(|r| r.stats.registered)
            .unwrap_or(0)
    });
}

//! Trajectory evaluation cost: the trainer calls `eval_with_jacobians` for n = 15 virtual cameras
//! per training image per step.
use gems_math::{Trajectory, TrajectoryKind};

fn main() {
    divan::main();
}

fn knots(n: usize) -> Vec<[f64; 6]> {
    (0..n)
        .map(|j| {
            let s = 1e-2 * (j as f64 + 1.0);
            [s, -0.5 * s, 0.3 * s, 0.2 * s, -s, 0.7 * s]
        })
        .collect()
}

#[divan::bench(args = [TrajectoryKind::Bezier, TrajectoryKind::Linear, TrajectoryKind::CubicBSpline])]
fn eval_15_views_with_jacobians(bencher: divan::Bencher, kind: TrajectoryKind) {
    let traj = Trajectory::new(kind, knots(kind.default_knots())).unwrap();
    bencher.bench(|| {
        for i in 0..15 {
            divan::black_box(traj.eval_with_jacobians(i as f64 / 14.0));
        }
    });
}

#[divan::bench(args = [TrajectoryKind::Bezier, TrajectoryKind::Linear, TrajectoryKind::CubicBSpline])]
fn eval_15_views(bencher: divan::Bencher, kind: TrajectoryKind) {
    let traj = Trajectory::new(kind, knots(kind.default_knots())).unwrap();
    bencher.bench(|| {
        for i in 0..15 {
            divan::black_box(traj.eval(i as f64 / 14.0));
        }
    });
}

//! Simulator behaviour (ESIM semantics, `uzh-rpg/rpg_esim:event_camera_simulator/esim/src/event_simulator.cpp`).

use gems_events::{SimConfig, Simulator};

/// Luminance whose log(Y + ε) equals `l`.
fn luma_for_log(l: f32, eps: f32) -> f32 {
    l.exp() - eps
}

fn clean(c: f32) -> SimConfig {
    SimConfig {
        c_pos: c,
        c_neg: c,
        ..SimConfig::default()
    }
}

#[test]
fn linear_log_ramp_gives_exact_events_and_times() {
    let eps = 1e-3;
    let mut sim = Simulator::new(clean(0.25), 1, 1).unwrap();
    // log goes 0 → 1.1 over [0, 1000] µs: crossings at 0.25, 0.5, 0.75, 1.0
    // → t = 1000·L/1.1 = 227.3, 454.5, 681.8, 909.1 µs
    sim.feed_luma(&[luma_for_log(0.0, eps)], 0).unwrap();
    sim.feed_luma(&[luma_for_log(1.1, eps)], 1000).unwrap();
    // then down to 0.1 over [1000, 2000]: levels 0.75, 0.5, 0.25 at 1000 + 1000·(1.1 − L)/1.0
    sim.feed_luma(&[luma_for_log(0.1, eps)], 2000).unwrap();
    let ev = sim.finish();
    let expect_t: Vec<i64> = vec![227, 455, 682, 909, 1350, 1600, 1850];
    assert_eq!(ev.t(), expect_t.as_slice());
    assert_eq!(ev.p(), &[1, 1, 1, 1, -1, -1, -1]);
    assert!(ev.x().iter().all(|&x| x == 0) && ev.y().iter().all(|&y| y == 0));
}

#[test]
fn piecewise_ramp_interpolates_per_frame_interval() {
    // Two frame intervals with different slopes; each crossing is placed within its own interval.
    let eps = 1e-3;
    let mut sim = Simulator::new(clean(0.3), 2, 1).unwrap();
    sim.feed_luma(&[luma_for_log(0.0, eps), luma_for_log(0.0, eps)], 100)
        .unwrap();
    sim.feed_luma(&[luma_for_log(0.4, eps), luma_for_log(-0.7, eps)], 300)
        .unwrap();
    sim.feed_luma(&[luma_for_log(0.7, eps), luma_for_log(-0.7, eps)], 400)
        .unwrap();
    let ev = sim.finish();
    // pixel 0: 0.3 at 100 + 200·0.3/0.4 = 250; 0.6 at 300 + 100·0.2/0.3 = 366.67 → 367
    // pixel 1: −0.3 at 100 + 200·0.3/0.7 = 185.71 → 186; −0.6 at 100 + 200·0.6/0.7 = 271.43 → 271
    let got: Vec<(i64, u16, i8)> = (0..ev.len())
        .map(|i| (ev.t()[i], ev.x()[i], ev.p()[i]))
        .collect();
    assert_eq!(
        got,
        vec![(186, 1, -1), (250, 0, 1), (271, 1, -1), (367, 0, 1)]
    );
}

#[test]
fn polarity_sum_reproduces_log_change_within_threshold() {
    let (w, h) = (32u16, 24u16);
    let (cp, cn) = (0.2f32, 0.3f32);
    let cfg = SimConfig {
        c_pos: cp,
        c_neg: cn,
        ..SimConfig::default()
    };
    let mut sim = Simulator::new(cfg.clone(), w, h).unwrap();
    let frame = |k: usize| -> Vec<f32> {
        (0..w as usize * h as usize)
            .map(|i| {
                let (x, y) = ((i % w as usize) as f32, (i / w as usize) as f32);
                0.5 + 0.45 * (0.3 * x + 0.2 * y + 0.4 * k as f32).sin()
            })
            .collect()
    };
    let first = frame(0);
    sim.feed_luma(&first, 0).unwrap();
    let n_frames = 30;
    for k in 1..n_frames {
        sim.feed_luma(&frame(k), 1000 * k as i64).unwrap();
    }
    let last = frame(n_frames - 1);
    let ev = sim.finish();
    assert!(
        ev.len() > 1000,
        "a moving texture must fire many events, got {}",
        ev.len()
    );
    let mut sum = vec![0f32; first.len()];
    for i in 0..ev.len() {
        let k = ev.y()[i] as usize * w as usize + ev.x()[i] as usize;
        sum[k] += if ev.p()[i] > 0 { cp } else { -cn };
    }
    for k in 0..first.len() {
        let dlog = (last[k] + cfg.log_eps).ln() - (first[k] + cfg.log_eps).ln();
        // the reference lags the signal by less than one threshold of the last direction
        assert!(
            (dlog - sum[k]).abs() < cp.max(cn) + 1e-4,
            "pixel {k}: log change {dlog}, events say {}",
            sum[k]
        );
    }
}

#[test]
fn same_seed_same_events_different_seed_different_events() {
    let run = |seed: u64| {
        let cfg = SimConfig {
            sigma_pos: 0.03,
            sigma_neg: 0.03,
            seed,
            ..SimConfig::default()
        };
        let mut sim = Simulator::new(cfg, 16, 16).unwrap();
        for k in 0..10 {
            let f: Vec<f32> = (0..256)
                .map(|i| 0.5 + 0.4 * ((i as f32) * 0.37 + k as f32 * 0.5).sin())
                .collect();
            sim.feed_luma(&f, k * 500).unwrap();
        }
        sim.finish()
    };
    let a = run(7);
    assert_eq!(a, run(7));
    assert_ne!(a, run(8));
    assert!(a.t().is_sorted());
}

#[test]
fn results_do_not_depend_on_thread_count() {
    let run = || {
        let mut sim = Simulator::new(SimConfig::default(), 64, 48).unwrap();
        for k in 0..6 {
            let f: Vec<f32> = (0..64 * 48)
                .map(|i| 0.5 + 0.4 * ((i as f32) * 0.11 + k as f32).cos())
                .collect();
            sim.feed_luma(&f, k * 100).unwrap();
        }
        sim.finish()
    };
    let one = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap()
        .install(run);
    let four = rayon::ThreadPoolBuilder::new()
        .num_threads(4)
        .build()
        .unwrap()
        .install(run);
    assert_eq!(one, four);
}

#[test]
fn mismatch_is_per_pixel_fixed_and_floored() {
    let cfg = SimConfig {
        c_pos: 0.02,
        sigma_pos: 0.5,
        seed: 3,
        ..SimConfig::default()
    };
    let sim = Simulator::new(cfg, 50, 50).unwrap();
    let th = sim.thresholds_pos();
    assert!(th.iter().all(|&c| c >= 0.01));
    assert!(
        th.contains(&0.01),
        "a σ of 0.5 around 0.02 must hit the floor"
    );
    assert!(th.iter().any(|&c| c > 0.3));
    assert!(
        sim.thresholds_neg().iter().all(|&c| c == 0.2),
        "σ− = 0 keeps C− exact"
    );
}

#[test]
fn refractory_drops_events_but_reference_advances() {
    let eps = 1e-3;
    let cfg = SimConfig {
        c_pos: 0.1,
        c_neg: 0.1,
        refractory_us: 250,
        ..SimConfig::default()
    };
    let mut sim = Simulator::new(cfg, 1, 1).unwrap();
    sim.feed_luma(&[luma_for_log(0.0, eps)], 0).unwrap();
    // crossings at 0.1 … 1.0 → t = 100, 200, …, 1000; with 250 µs refractory: 100, 400, 700, 1000
    sim.feed_luma(&[luma_for_log(1.0, eps)], 1000).unwrap();
    // reference is at 1.0 although the crossing at 0.9 was dropped: a step to 1.15 fires once more
    sim.feed_luma(&[luma_for_log(1.15, eps)], 2000).unwrap();
    let ev = sim.finish();
    assert_eq!(ev.t(), &[100, 400, 700, 1000, 1667]);
}

#[test]
fn bad_input_is_an_error_not_a_panic() {
    assert!(
        Simulator::new(
            SimConfig {
                c_pos: 0.0,
                ..SimConfig::default()
            },
            4,
            4
        )
        .is_err()
    );
    assert!(Simulator::new(SimConfig::default(), 0, 4).is_err());
    let mut sim = Simulator::new(SimConfig::default(), 2, 2).unwrap();
    assert!(sim.feed_luma(&[0.5; 3], 0).is_err());
    assert!(sim.feed_luma(&[0.5, f32::NAN, 0.5, 0.5], 0).is_err());
    assert!(sim.feed_luma(&[-0.5, 0.5, 0.5, 0.5], 0).is_err());
    sim.feed_luma(&[0.5; 4], 10).unwrap();
    assert!(sim.feed_luma(&[0.6; 4], 10).is_err(), "time must increase");
    assert!(sim.feed_rgb(&[0.6; 4], 20).is_err());
    sim.feed_rgb(&[0.9; 12], 20).unwrap();
    assert_eq!(
        sim.events().len(),
        4 * ((0.9f32 + 1e-3).ln() - (0.5f32 + 1e-3).ln()).div_euclid(0.2) as usize
    );
}

mod prop {
    use gems_events::{SimConfig, Simulator};
    use proptest::prelude::*;

    proptest! {
        #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]
        /// For any luminance sequence, Σ polarity·C equals the log change up to one threshold, and
        /// events are time-sorted inside the fed interval.
        #[test]
        fn polarity_sum_tracks_log_change(
            seq in proptest::collection::vec(0.0f32..1.0, 2..20),
            cp in 0.05f32..0.6,
            cn in 0.05f32..0.6,
        ) {
            let cfg = SimConfig { c_pos: cp, c_neg: cn, ..SimConfig::default() };
            let mut sim = Simulator::new(cfg.clone(), 1, 1).unwrap();
            for (k, &v) in seq.iter().enumerate() {
                sim.feed_luma(&[v], 100 * k as i64).unwrap();
            }
            let ev = sim.finish();
            let sum: f32 = ev.p().iter().map(|&p| if p > 0 { cp } else { -cn }).sum();
            let dlog = (seq[seq.len() - 1] + cfg.log_eps).ln() - (seq[0] + cfg.log_eps).ln();
            prop_assert!((dlog - sum).abs() < cp.max(cn) + 1e-3, "Δlog {} vs Σ {}", dlog, sum);
            prop_assert!(ev.t().is_sorted());
            prop_assert!(ev.t().iter().all(|&t| t >= 0 && t <= 100 * (seq.len() as i64 - 1)));
        }
    }
}

//! Umeyama alignment and APE statistics (evo definitions).

use gems_math::*;

fn lcg(state: &mut u64) -> f64 {
    // Deterministic uniform(-1, 1) for test noise without a rand dependency.
    *state = state
        .wrapping_mul(6364136223846793005)
        .wrapping_add(1442695040888963407);
    ((*state >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
}

fn points(n: usize, seed: u64) -> Vec<[f64; 3]> {
    let mut s = seed;
    (0..n)
        .map(|_| [lcg(&mut s) * 3.0, lcg(&mut s) * 2.0, lcg(&mut s)])
        .collect()
}

fn known_sim() -> Sim3 {
    Sim3 {
        scale: 2.5,
        rot: So3::exp(&Vector3::new(0.3, -1.2, 0.8)).0,
        trans: Vector3::new(1.0, -4.0, 0.5),
    }
}

#[test]
fn recovers_known_similarity_exactly() {
    let src = points(20, 7);
    let sim = known_sim();
    let dst: Vec<[f64; 3]> = src.iter().map(|p| sim.act(p)).collect();
    let est = umeyama(&src, &dst, true).unwrap();
    assert!((est.scale - sim.scale).abs() < 1e-12);
    assert!((est.rot - sim.rot).abs().max() < 1e-12);
    assert!((est.trans - sim.trans).norm() < 1e-11);
    let (stats, _) = ape_translation(&src, &dst, Alignment::Sim3).unwrap();
    assert!(stats.rmse < 1e-11 && stats.max < 1e-11);
    // Rigid alignment cannot absorb the scale.
    let (rigid, _) = ape_translation(&src, &dst, Alignment::Se3).unwrap();
    assert!(rigid.rmse > 0.5);
}

#[test]
fn recovers_similarity_under_noise() {
    let src = points(200, 11);
    let sim = known_sim();
    let mut s = 99u64;
    let sigma = 0.01;
    let dst: Vec<[f64; 3]> = src
        .iter()
        .map(|p| {
            let q = sim.act(p);
            [
                q[0] + sigma * lcg(&mut s),
                q[1] + sigma * lcg(&mut s),
                q[2] + sigma * lcg(&mut s),
            ]
        })
        .collect();
    let est = umeyama(&src, &dst, true).unwrap();
    assert!((est.scale - sim.scale).abs() < 2e-3, "scale {}", est.scale);
    assert!(So3(sim.rot.transpose() * est.rot).log().norm() < 2e-3);
    let (stats, _) = ape_translation(&src, &dst, Alignment::Sim3).unwrap();
    // Uniform(−σ, σ) per axis: E‖n‖² = 3σ²/3 = σ², so rmse ≈ σ.
    assert!(
        stats.rmse > 0.7 * sigma && stats.rmse < 1.1 * sigma,
        "rmse {}",
        stats.rmse
    );
}

#[test]
fn handles_reflection_and_rigid_case() {
    // Planar-ish data whose naive SVD solution is a reflection must still give det R = +1.
    let src = vec![
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [1.0, 1.0, 0.0],
    ];
    let dst: Vec<[f64; 3]> = src.iter().map(|p| [p[0], -p[1], p[2]]).collect();
    let est = umeyama(&src, &dst, false).unwrap();
    assert!((est.rot.determinant() - 1.0).abs() < 1e-12);
    let rigid = Sim3 {
        scale: 1.0,
        ..known_sim()
    };
    let pts = points(10, 3);
    let moved: Vec<[f64; 3]> = pts.iter().map(|p| rigid.act(p)).collect();
    let est = umeyama(&pts, &moved, false).unwrap();
    assert_eq!(est.scale, 1.0);
    assert!((est.rot - rigid.rot).abs().max() < 1e-12);
}

#[test]
fn rejects_bad_input() {
    assert!(matches!(
        umeyama(&points(3, 1), &points(4, 1), true),
        Err(MathError::LengthMismatch { .. })
    ));
    let collinear: Vec<[f64; 3]> = (0..5).map(|i| [i as f64, 2.0 * i as f64, 0.0]).collect();
    assert!(matches!(
        umeyama(&collinear, &collinear, true),
        Err(MathError::Degenerate(_))
    ));
    assert!(error_stats(&[]).is_err());
}

#[test]
fn statistics_follow_evo() {
    let s = error_stats(&[4.0, 1.0, 3.0, 2.0]).unwrap();
    assert_eq!(s.sse, 30.0);
    assert!((s.rmse - 7.5f64.sqrt()).abs() < 1e-15);
    assert_eq!(s.mean, 2.5);
    assert_eq!(s.median, 2.5);
    assert!((s.std - 1.25f64.sqrt()).abs() < 1e-15, "population std");
    assert_eq!((s.min, s.max), (1.0, 4.0));
    assert_eq!(error_stats(&[5.0, 1.0, 3.0]).unwrap().median, 3.0);
}

use proptest::prelude::*;

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]
    #[test]
    fn umeyama_recovers_random_similarities(
        rot in prop::array::uniform3(-3.0f64..3.0),
        trans in prop::array::uniform3(-10.0f64..10.0),
        log_scale in -3.0f64..3.0,
        seed in 0u64..10_000,
    ) {
        let phi = Vector3::from(rot);
        prop_assume!(phi.norm() < 3.1);
        let sim = Sim3 { scale: log_scale.exp(), rot: So3::exp(&phi).0, trans: Vector3::from(trans) };
        let src = points(12, seed);
        let dst: Vec<[f64; 3]> = src.iter().map(|p| sim.act(p)).collect();
        let est = umeyama(&src, &dst, true).unwrap();
        prop_assert!((est.scale / sim.scale - 1.0).abs() < 1e-9);
        prop_assert!((est.rot - sim.rot).abs().max() < 1e-9);
        prop_assert!((est.trans - sim.trans).norm() < 1e-8 * (1.0 + sim.trans.norm()));
    }
}

#[test]
fn camera_similarity_recovers_a_similarity_from_cameras_on_a_straight_line() {
    // Centres on one line leave a centre-only alignment's rotation about it free; the cameras'
    // orientations fix it.
    let truth = Sim3 {
        scale: 2.5,
        rot: *So3::exp(&Vector3::new(0.4, -0.3, 1.1)).matrix(),
        trans: Vector3::new(1.0, -2.0, 0.5),
    };
    let pairs: Vec<(Se3, Se3)> = (0..5)
        .map(|i| {
            let a = Se3::new(
                *So3::exp(&Vector3::new(0.05 * i as f64, 0.1, -0.02 * i as f64)).matrix(),
                Vector3::new(0.3 * i as f64, 0.0, 0.0),
            );
            let b = Se3::new(
                truth.rot * a.rot,
                truth.rot * a.trans * truth.scale + truth.trans,
            );
            (a, b)
        })
        .collect();
    let got = camera_similarity(&pairs).unwrap();
    assert!((got.scale - truth.scale).abs() < 1e-12);
    assert!((got.rot - truth.rot).norm() < 1e-12);
    assert!((got.trans - truth.trans).norm() < 1e-12);
    assert!(
        umeyama(
            &pairs
                .iter()
                .map(|(a, _)| a.trans.into())
                .collect::<Vec<_>>(),
            &pairs
                .iter()
                .map(|(_, b)| b.trans.into())
                .collect::<Vec<_>>(),
            true
        )
        .is_err()
    );
    // One camera, or cameras at one centre, fix no scale.
    assert!(camera_similarity(&pairs[..1]).is_none());
    let same_centre: Vec<_> = pairs
        .iter()
        .map(|(a, b)| (Se3::new(a.rot, pairs[0].0.trans), *b))
        .collect();
    assert!(camera_similarity(&same_centre).is_none());
}

#[test]
fn camera_discrepancy_ignores_a_similarity_and_measures_a_change_of_shape() {
    let truth = known_sim();
    let cameras: Vec<Se3> = (0..6)
        .map(|i| {
            let t = i as f64;
            Se3::new(
                *So3::exp(&Vector3::new(0.03 * t, 0.1, -0.02 * t)).matrix(),
                Vector3::new(0.4 * t, 0.1 * t * t, 0.05 * t),
            )
        })
        .collect();
    let carried: Vec<(Se3, Se3)> = cameras.iter().map(|a| (*a, truth.act_c2w(a))).collect();
    let d = camera_discrepancy(&carried).unwrap();
    assert!(d.centre_pct < 1e-10 && d.rotation_deg < 1e-10, "{d:?}");
    // One camera of six moved by 1 % of B's extent along x, and turned by 0.6° about z: the
    // similarity refits (it also moves the others), so the RMSE lies between the moved camera's
    // share, 1/√6 of its move, and the move itself.
    let extent = carried
        .iter()
        .flat_map(|(_, a)| carried.iter().map(move |(_, b)| (a.trans - b.trans).norm()))
        .fold(0.0, f64::max);
    let mut moved = carried.clone();
    let turn = *So3::exp(&Vector3::new(0.0, 0.0, 0.6_f64.to_radians())).matrix();
    moved[3].1 = Se3::new(
        turn * moved[3].1.rot,
        moved[3].1.trans + Vector3::new(0.01 * extent, 0.0, 0.0),
    );
    let d = camera_discrepancy(&moved).unwrap();
    assert!(
        d.centre_pct > 0.9 / 6f64.sqrt() && d.centre_pct < 1.0,
        "{d:?}"
    );
    assert!(
        d.rotation_deg > 0.5 / 6f64.sqrt() && d.rotation_deg < 0.6,
        "{d:?}"
    );
    assert!(camera_discrepancy(&carried[..1]).is_none());
}

#[test]
fn camera_discrepancy_tells_a_bent_path_from_cameras_off_on_their_own() {
    // Sixteen cameras on an arc, as a captured path; B is A carried by a similarity.
    let truth = known_sim();
    let cameras: Vec<Se3> = (0..16)
        .map(|i| {
            let t = i as f64 / 15.0 - 0.5;
            Se3::new(
                *So3::exp(&Vector3::new(0.0, 0.6 * t, 0.0)).matrix(),
                Vector3::new(2.0 * t.sin(), 0.1 * t, 2.0 * (1.0 - t.cos())),
            )
        })
        .collect();
    let carried: Vec<(Se3, Se3)> = cameras.iter().map(|a| (*a, truth.act_c2w(a))).collect();
    let d = camera_discrepancy(&carried).unwrap();
    assert!(d.centre_pct < 1e-10, "{d:?}");
    let scale = truth.scale;
    // Each camera off on its own by a seeded uniform offset, about 1 % of the path's extent:
    // the quadratic takes about 3/16 of it by chance.
    let mut state = 7u32;
    let mut next = || {
        state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        (state >> 8) as f64 / (1u32 << 24) as f64 - 0.5
    };
    let jittered: Vec<(Se3, Se3)> = carried
        .iter()
        .map(|(a, b)| {
            let off = Vector3::new(next(), next(), next()) * 0.04 * scale;
            (*a, Se3::new(b.rot, b.trans + off))
        })
        .collect();
    let d = camera_discrepancy(&jittered).unwrap();
    assert!(d.centre_pct > 0.3, "{d:?}");
    assert!(d.systematic_share < 0.3, "{d:?}");
    // The path bent: each camera pushed sideways by a parabola in its place along the path,
    // the kind of change a similarity cannot undo.
    let bent: Vec<(Se3, Se3)> = carried
        .iter()
        .enumerate()
        .map(|(i, (a, b))| {
            let t = i as f64 / 15.0 - 0.5;
            let off = truth.rot * Vector3::new(0.0, 0.0, 0.08 * (t * t - 1.0 / 12.0)) * scale;
            (*a, Se3::new(b.rot, b.trans + off))
        })
        .collect();
    let d = camera_discrepancy(&bent).unwrap();
    assert!(d.centre_pct > 0.2, "{d:?}");
    assert!(d.systematic_share > 0.8, "{d:?}");
}

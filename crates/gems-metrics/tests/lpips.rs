//! LPIPS-Alex against the reference values computed with the random weights.

mod common;

use gems_metrics::{Lpips, LpipsError};

#[test]
fn lpips_matches_reference_with_random_weights() {
    let net = Lpips::load(&[common::LPIPS_WEIGHTS]).unwrap();
    for name in ["small", "wide"] {
        let p = common::load(name);
        let v = net
            .distance(&p.render32(), &p.target32(), p.height, p.width)
            .unwrap();
        let r = p.meta["lpips_alex_random_weights"];
        assert!(
            (v - r).abs() < 1e-5 * r.max(1.0) && (v - r).abs() / r < 1e-4,
            "{name}: {v} vs {r}"
        );
        // Symmetric and zero on identical images.
        let back = net
            .distance(&p.target32(), &p.render32(), p.height, p.width)
            .unwrap();
        assert!((back - v).abs() < 1e-6);
        assert_eq!(
            net.distance(&p.render32(), &p.render32(), p.height, p.width)
                .unwrap(),
            0.0
        );
    }
}

#[test]
fn lpips_errors_name_the_file() {
    let err = Lpips::load(&["/nonexistent/alex.pth"]).err().unwrap();
    assert!(err.to_string().contains("/nonexistent/alex.pth"), "{err}");
    assert!(matches!(Lpips::load::<&str>(&[]), Err(LpipsError::NoFiles)));
    let net = Lpips::load(&[common::LPIPS_WEIGHTS]).unwrap();
    let img = vec![0.5f32; 20 * 20 * 3];
    assert!(matches!(
        net.distance(&img, &img, 20, 20),
        Err(LpipsError::TooSmall { .. })
    ));
}

//! A small deterministic test scene: colourful Gaussians in front of a camera.
#![allow(dead_code)]

use gems_math::Intrinsics;
use gems_math::{Se3, Vector3, Vector6, look_at_c2w};
use gems_splat::Gaussians;

/// `n` Gaussians of log-scale around `log_scale`, means in a box of half-size (2, 1.5, 1)·`spread`.
pub fn scene(n: u32, log_scale: f32, spread: f32) -> Gaussians {
    let mut g = Gaussians::with_degree(0);
    for i in 0..n {
        let f = |s: u32| {
            ((i.wrapping_mul(2654435761)
                .wrapping_add(s.wrapping_mul(40503))
                >> 8) as f32
                / (1u32 << 24) as f32)
                - 0.5
        };
        let mut sh = [[0.0f32; 3]; 16];
        sh[0] = [f(4) * 3.0, f(5) * 3.0, f(6) * 3.0];
        g.push(
            [f(1) * 4.0 * spread, f(2) * 3.0 * spread, f(3) * 2.0],
            [1.0, 0.0, 0.0, 0.0],
            [log_scale + 0.5 * f(7); 3],
            2.0,
            sh,
        );
    }
    g
}

pub fn intrinsics() -> Intrinsics {
    Intrinsics {
        fx: 120.0,
        fy: 120.0,
        cx: 40.0,
        cy: 30.0,
        width: 80,
        height: 60,
    }
}

/// A camera on a circle around the scene, looking at the origin.
pub fn camera(angle: f64) -> Se3 {
    let eye = Vector3::new(6.0 * angle.sin(), -0.5, -6.0 * angle.cos());
    look_at_c2w(&eye, &Vector3::zeros(), &Vector3::new(0.0, -1.0, 0.0)).unwrap()
}

pub fn perturb(c2w: &Se3, d: [f64; 6]) -> Se3 {
    *c2w * Se3::exp(&Vector6::from(d))
}

/// Mean pixel distance between the projections of the Gaussian means under two poses: the
/// image-space pose error that matters (a small distant scene cannot separate a sideways shift
/// from a small rotation, so the SE(3) distance is the wrong yardstick).
pub fn reprojection_error(g: &Gaussians, k: &Intrinsics, a: &Se3, b: &Se3) -> f64 {
    let proj = |c2w: &Se3, p: &[f32; 3]| {
        let q = c2w
            .inverse()
            .act(&Vector3::new(p[0] as f64, p[1] as f64, p[2] as f64));
        (k.fx * q.x / q.z + k.cx, k.fy * q.y / q.z + k.cy)
    };
    g.means
        .iter()
        .map(|p| {
            let (pa, pb) = (proj(a, p), proj(b, p));
            ((pa.0 - pb.0).powi(2) + (pa.1 - pb.1).powi(2)).sqrt()
        })
        .sum::<f64>()
        / g.len() as f64
}

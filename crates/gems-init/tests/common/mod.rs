//! A small synthetic blurry capture with known poses, for tests and benches: a textured room
//! (back wall, floor, two side walls, a box) seen from 20 views on an arc, each view the mean of
//! L sub-frames of an 11-frame burst along a random camera shake (the GeMS blur-level protocol:
//! level L averages the middle L frames; the middle frame is the ground truth).

#![allow(dead_code)]

use gems_init::sfm::SfmImage;
use gems_math::{Se3, camera_center_from_w2c};
use nalgebra::{Rotation3, Vector3};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

pub struct Scene {
    pub images: Vec<SfmImage>,
    /// Ground-truth cam_from_world pose of each view (middle burst frame).
    pub gt: Vec<Se3>,
    pub focal: f64,
}

struct Plane {
    /// Point on the plane and two in-plane unit axes (texture u, v), normal = u × v.
    o: Vector3<f64>,
    u: Vector3<f64>,
    v: Vector3<f64>,
    /// Extent along u and v from o (metres).
    su: f64,
    sv: f64,
    tex: usize,
}

const TEX: usize = 256;

/// Smooth random texture: coloured discs with soft edges on a grey base.
fn texture(rng: &mut ChaCha8Rng) -> Vec<[f32; 3]> {
    let mut t = vec![[0.45f32, 0.45, 0.45]; TEX * TEX];
    for _ in 0..140 {
        let cx = rng.random_range(0.0..TEX as f32);
        let cy = rng.random_range(0.0..TEX as f32);
        let r = rng.random_range(5.0..24.0f32);
        let c = [
            rng.random_range(0.0..1.0f32),
            rng.random_range(0.0..1.0f32),
            rng.random_range(0.0..1.0f32),
        ];
        let r0 = (cy - r - 2.0).max(0.0) as usize;
        let r1 = ((cy + r + 2.0) as usize).min(TEX - 1);
        let c0 = (cx - r - 2.0).max(0.0) as usize;
        let c1 = ((cx + r + 2.0) as usize).min(TEX - 1);
        for y in r0..=r1 {
            for x in c0..=c1 {
                let d = ((x as f32 - cx).powi(2) + (y as f32 - cy).powi(2)).sqrt();
                let a = (r + 1.0 - d).clamp(0.0, 1.0);
                let p = &mut t[y * TEX + x];
                for k in 0..3 {
                    p[k] = p[k] * (1.0 - a) + c[k] * a;
                }
            }
        }
    }
    t
}

fn lookup(t: &[[f32; 3]], u: f64, v: f64) -> [f32; 3] {
    let x = (u * TEX as f64 - 0.5).clamp(0.0, (TEX - 1) as f64);
    let y = (v * TEX as f64 - 0.5).clamp(0.0, (TEX - 1) as f64);
    let (x0, y0) = (x.floor() as usize, y.floor() as usize);
    let (x1, y1) = ((x0 + 1).min(TEX - 1), (y0 + 1).min(TEX - 1));
    let (ax, ay) = ((x - x0 as f64) as f32, (y - y0 as f64) as f32);
    let mut o = [0.0; 3];
    for k in 0..3 {
        let top = t[y0 * TEX + x0][k] * (1.0 - ax) + t[y0 * TEX + x1][k] * ax;
        let bot = t[y1 * TEX + x0][k] * (1.0 - ax) + t[y1 * TEX + x1][k] * ax;
        o[k] = top * (1.0 - ay) + bot * ay;
    }
    o
}

fn planes() -> Vec<Plane> {
    let p = |o: [f64; 3], u: [f64; 3], v: [f64; 3], su, sv, tex| Plane {
        o: Vector3::from(o),
        u: Vector3::from(u),
        v: Vector3::from(v),
        su,
        sv,
        tex,
    };
    vec![
        // back wall z = 6, x ∈ [-4, 4], y ∈ [-2.5, 1.5] (y down)
        p(
            [-4.0, -2.5, 6.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            8.0,
            4.0,
            0,
        ),
        // floor y = 1.5
        p(
            [-4.0, 1.5, -1.0],
            [1.0, 0.0, 0.0],
            [0.0, 0.0, 1.0],
            8.0,
            7.0,
            1,
        ),
        // left wall x = -4
        p(
            [-4.0, -2.5, -1.0],
            [0.0, 0.0, 1.0],
            [0.0, 1.0, 0.0],
            7.0,
            4.0,
            2,
        ),
        // right wall x = 4
        p(
            [4.0, -2.5, -1.0],
            [0.0, 0.0, 1.0],
            [0.0, 1.0, 0.0],
            7.0,
            4.0,
            3,
        ),
        // front face of a box standing on the floor
        p(
            [-1.2, 0.2, 3.8],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            1.4,
            1.3,
            4,
        ),
        // its left face
        p(
            [-1.2, 0.2, 3.8],
            [0.0, 0.0, 1.0],
            [0.0, 1.0, 0.0],
            1.0,
            1.3,
            2,
        ),
        // its top
        p(
            [-1.2, 0.2, 3.8],
            [1.0, 0.0, 0.0],
            [0.0, 0.0, 1.0],
            1.4,
            1.0,
            3,
        ),
    ]
}

fn render(
    pose: &Se3,
    f: f64,
    w: u32,
    h: u32,
    planes: &[Plane],
    texs: &[Vec<[f32; 3]>],
    acc: &mut [f32],
) {
    let rt = pose.rot.transpose();
    let c = camera_center_from_w2c(pose);
    for y in 0..h {
        for x in 0..w {
            // 2×2 supersampling against aliasing of texture edges.
            let mut col = [0.0f32; 3];
            for (sx, sy) in [(0.25, 0.25), (0.75, 0.25), (0.25, 0.75), (0.75, 0.75)] {
                let d = rt
                    * Vector3::new(
                        (x as f64 + sx - w as f64 / 2.0) / f,
                        (y as f64 + sy - h as f64 / 2.0) / f,
                        1.0,
                    );
                let mut best = (f64::INFINITY, [0.1f32, 0.1, 0.1]);
                for p in planes {
                    let n = p.u.cross(&p.v);
                    let den = n.dot(&d);
                    if den.abs() < 1e-12 {
                        continue;
                    }
                    let s = n.dot(&(p.o - c)) / den;
                    if s <= 0.0 || s >= best.0 {
                        continue;
                    }
                    let q = c + d * s - p.o;
                    let (a, b) = (q.dot(&p.u) / p.su, q.dot(&p.v) / p.sv);
                    if (0.0..=1.0).contains(&a) && (0.0..=1.0).contains(&b) {
                        best = (s, lookup(&texs[p.tex], a, b));
                    }
                }
                for (c, b) in col.iter_mut().zip(best.1) {
                    *c += 0.25 * b;
                }
            }
            let i = 3 * (y * w + x) as usize;
            for (a, c) in acc[i..i + 3].iter_mut().zip(col) {
                *a += c;
            }
        }
    }
}

/// `views` cameras on an arc looking into the room; blur `level` ∈ {1,3,…,11} averages the
/// middle `level` frames of an 11-frame burst whose full extent moves the image by about
/// `max_blur_frac` of the image width.
pub fn scene(views: usize, w: u32, h: u32, level: usize, max_blur_frac: f64, seed: u64) -> Scene {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let texs: Vec<_> = (0..5).map(|_| texture(&mut rng)).collect();
    let planes = planes();
    let f = 0.5 * w as f64 / (0.5 * 70f64.to_radians()).tan();
    let target = Vector3::new(0.0, 0.0, 4.5);
    let mut images = Vec::new();
    let mut gt = Vec::new();
    for i in 0..views {
        let a = -0.35 + 0.7 * i as f64 / (views - 1).max(1) as f64;
        let centre = Vector3::new(
            4.0 * a.sin(),
            -0.3 + 0.15 * (3.0 * a).sin(),
            4.5 - 4.0 * a.cos(),
        );
        let look = |c: Vector3<f64>| {
            let z = (target - c).normalize();
            let x = Vector3::new(0.0, 1.0, 0.0).cross(&z).normalize();
            let y = z.cross(&x);
            let r = nalgebra::Matrix3::from_rows(&[x.transpose(), y.transpose(), z.transpose()]);
            Se3::new(r, -(r * c))
        };
        let mid = look(centre);
        // Shake: a random rotation rate and translation per burst, scaled so that 10 frame
        // intervals move the image by max_blur_frac·w.
        let axis = Vector3::new(
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(-0.3..0.3),
        )
        .normalize();
        let total_angle = max_blur_frac * w as f64 / f;
        let trans = Vector3::new(
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            0.0,
        ) * 0.02;
        let mut acc = vec![0.0f32; (3 * w * h) as usize];
        let half = (level / 2) as i64;
        for k in -half..=half {
            let s = k as f64 / 10.0;
            let r = Rotation3::new(axis * total_angle * s).into_inner() * mid.rot;
            let c = centre + trans * s * 10.0;
            let p = Se3::new(r, -(r * c));
            render(&p, f, w, h, &planes, &texs, &mut acc);
        }
        let n = (2 * half + 1) as f32;
        let img = image::RgbImage::from_fn(w, h, |x, y| {
            let i = 3 * (y * w + x) as usize;
            image::Rgb([0, 1, 2].map(|k| (acc[i + k] / n * 255.0).round().clamp(0.0, 255.0) as u8))
        });
        images.push(SfmImage {
            name: format!("{i:03}.png"),
            image: img,
        });
        gt.push(mid);
    }
    Scene {
        images,
        gt,
        focal: f,
    }
}

/// Translation RMSE after Sim(3) (Umeyama) alignment of the registered camera centres to the
/// ground truth, as a fraction of the ground-truth path extent (largest centre distance).
pub fn aligned_rmse_fraction(est: &[Option<Se3>], gt: &[Se3]) -> f64 {
    let (src, dst): (Vec<[f64; 3]>, Vec<[f64; 3]>) = est
        .iter()
        .zip(gt)
        .filter_map(|(e, g)| {
            e.map(|e| -> ([f64; 3], [f64; 3]) {
                (
                    camera_center_from_w2c(&e).into(),
                    camera_center_from_w2c(g).into(),
                )
            })
        })
        .unzip();
    let sim = gems_math::align::umeyama(&src, &dst, true).expect("alignment");
    let mse = src
        .iter()
        .zip(&dst)
        .map(|(s, d)| {
            let a = sim.act(s);
            (0..3).map(|k| (a[k] - d[k]).powi(2)).sum::<f64>()
        })
        .sum::<f64>()
        / src.len() as f64;
    let mut extent: f64 = 0.0;
    for a in gt {
        for b in gt {
            extent = extent.max((camera_center_from_w2c(a) - camera_center_from_w2c(b)).norm());
        }
    }
    mse.sqrt() / extent
}

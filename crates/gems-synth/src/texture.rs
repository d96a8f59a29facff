//! Solid (3D) procedural textures: value-noise fBm, checkers, stripes and blobs.
//!
//! Every texture is a pure function of the world-space point and a per-material seed, so a
//! surface point has the same colour from every camera and every sub-frame (multi-view
//! consistency is what SfM and training rely on), and the result never depends on threads.

use crate::geom::V3;

/// 32-bit integer hash of three lattice coordinates and a seed: the coordinates are mixed by
/// large odd multipliers, then one lowbias32 finaliser (Wellons) scrambles the bits. Hashing is
/// the inner loop of every texture lookup, so one finaliser round instead of three matters.
pub fn hash3(ix: i32, iy: i32, iz: i32, seed: u32) -> u32 {
    let mut h = seed
        ^ (ix as u32).wrapping_mul(0x8da6_b343)
        ^ (iy as u32).wrapping_mul(0xd816_3841)
        ^ (iz as u32).wrapping_mul(0xcb1a_b31f);
    h ^= h >> 16;
    h = h.wrapping_mul(0x7feb_352d);
    h ^= h >> 15;
    h = h.wrapping_mul(0x846c_a68b);
    h ^= h >> 16;
    h
}

/// Uniform value in [0, 1) from a hash.
pub fn unit(h: u32) -> f32 {
    (h >> 8) as f32 * (1.0 / 16_777_216.0)
}

/// `floor` as an integer without the libm call (x86-64's baseline has no SSE4.1 `roundps`, so
/// `f32::floor` is a function call in the texture inner loop). Valid for |x| < 2³¹.
pub fn ifloor(x: f32) -> i32 {
    let i = x as i32;
    if (i as f32) > x { i - 1 } else { i }
}

fn smooth(t: f32) -> f32 {
    t * t * (3.0 - 2.0 * t)
}

fn lerp(a: f32, b: f32, t: f32) -> f32 {
    a + (b - a) * t
}

/// Trilinearly smoothed lattice value noise in [0, 1).
pub fn value_noise(p: V3, seed: u32) -> f32 {
    let (ix, iy, iz) = (ifloor(p.x), ifloor(p.y), ifloor(p.z));
    let (tx, ty, tz) = (
        smooth(p.x - ix as f32),
        smooth(p.y - iy as f32),
        smooth(p.z - iz as f32),
    );
    let c = |dx: i32, dy: i32, dz: i32| unit(hash3(ix + dx, iy + dy, iz + dz, seed));
    let x00 = lerp(c(0, 0, 0), c(1, 0, 0), tx);
    let x10 = lerp(c(0, 1, 0), c(1, 1, 0), tx);
    let x01 = lerp(c(0, 0, 1), c(1, 0, 1), tx);
    let x11 = lerp(c(0, 1, 1), c(1, 1, 1), tx);
    lerp(lerp(x00, x10, ty), lerp(x01, x11, ty), tz)
}

/// Fractal sum of `octaves` value-noise layers (lacunarity 2, gain 0.5), normalised to [0, 1).
pub fn fbm(p: V3, octaves: u32, seed: u32) -> f32 {
    let (mut sum, mut amp, mut total, mut freq) = (0.0, 1.0, 0.0, 1.0);
    for o in 0..octaves {
        sum += amp * value_noise(p * freq, seed.wrapping_add(o.wrapping_mul(0x632b_e5ab)));
        total += amp;
        amp *= 0.5;
        freq *= 2.0;
    }
    sum / total
}

/// Soft-edged blobs: at most one sphere per lattice cell, of random radius (0.12–0.45 cells, so
/// sizes vary ~4× and the pattern carries structure at several scales) placed so it lies inside
/// its cell — only the point's own cell needs testing. Returns 1 inside a blob, 0 outside, with
/// a narrow smooth edge; about a third of the cells stay empty.
pub fn blobs(p: V3, seed: u32) -> f32 {
    let (ix, iy, iz) = (ifloor(p.x), ifloor(p.y), ifloor(p.z));
    let (fx, fy, fz) = (ix as f32, iy as f32, iz as f32);
    let h = hash3(ix, iy, iz, seed);
    if h.is_multiple_of(3) {
        return 0.0;
    }
    let radius = 0.12 + 0.33 * unit(h.rotate_left(7));
    let free = 1.0 - 2.0 * radius;
    let h2 = hash3(ix, iy, iz, h);
    let centre = V3::new(
        fx + radius + free * unit(h2),
        fy + radius + free * unit(hash3(1, 0, 0, h2)),
        fz + radius + free * unit(hash3(0, 1, 0, h2)),
    );
    ((radius - (p - centre).norm()) / 0.04).clamp(0.0, 1.0)
}

/// The main pattern of a material: a scalar field in [0, 1] that picks between two colours.
#[derive(Clone, Copy, Debug)]
pub enum Pattern {
    /// 3D checkerboard with cell size `size`.
    Checker { size: f32 },
    /// Sinusoidal stripes along `dir` with period `period`, sharpened towards a square wave.
    Stripes { dir: V3, period: f32 },
    /// Random blobs on a lattice of cell size `cell`.
    Blobs { cell: f32 },
    /// fBm noise with base feature size `size`, thresholded softly into patches.
    Noise { size: f32 },
}

impl Pattern {
    pub fn eval(&self, p: V3, seed: u32) -> f32 {
        match *self {
            Pattern::Checker { size } => {
                let s = (p.x / size).floor() + (p.y / size).floor() + (p.z / size).floor();
                if (s as i64).rem_euclid(2) == 0 {
                    1.0
                } else {
                    0.0
                }
            }
            Pattern::Stripes { dir, period } => {
                let s = (p.dot(dir) * std::f32::consts::TAU / period).sin();
                (0.5 + 1.5 * s).clamp(0.0, 1.0)
            }
            Pattern::Blobs { cell } => blobs(p * (1.0 / cell), seed),
            Pattern::Noise { size } => {
                let n = fbm(p * (1.0 / size), 4, seed);
                ((n - 0.5) * 4.0 + 0.5).clamp(0.0, 1.0)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ifloor_matches_floor() {
        for x in [-2.5f32, -2.0, -1e-7, 0.0, 1e-7, 0.999, 1.0, 3.7, -1234.5] {
            assert_eq!(ifloor(x), x.floor() as i32, "{x}");
        }
    }

    #[test]
    fn noise_is_bounded_continuous_and_seeded() {
        let mut prev = value_noise(V3::new(0.0, 0.3, 0.7), 1);
        let mut differs = false;
        for i in 1..2000 {
            let p = V3::new(i as f32 * 0.001, 0.3, 0.7);
            let v = value_noise(p, 1);
            assert!((0.0..1.0).contains(&v));
            // Smooth: a 1e-3 step cannot jump by more than the largest lattice gradient allows.
            assert!((v - prev).abs() < 0.01, "jump at {i}");
            prev = v;
            differs |= (v - value_noise(p, 2)).abs() > 1e-3;
        }
        assert!(differs, "the seed must change the noise");
        let f = fbm(V3::new(1.3, -2.1, 0.4), 5, 7);
        assert!((0.0..1.0).contains(&f));
    }

    #[test]
    fn patterns_span_both_colours() {
        let pats = [
            Pattern::Checker { size: 0.5 },
            Pattern::Stripes {
                dir: V3::new(1.0, 0.0, 0.0),
                period: 0.5,
            },
            Pattern::Blobs { cell: 0.5 },
            Pattern::Noise { size: 0.5 },
        ];
        for pat in pats {
            let (mut lo, mut hi) = (1.0f32, 0.0f32);
            for i in 0..400 {
                let p = V3::new(i as f32 * 0.037, (i % 17) as f32 * 0.05, 0.21);
                let v = pat.eval(p, 3);
                assert!((0.0..=1.0).contains(&v));
                lo = lo.min(v);
                hi = hi.max(v);
            }
            assert!(lo < 0.1 && hi > 0.9, "{pat:?} spans only [{lo}, {hi}]");
        }
    }
}

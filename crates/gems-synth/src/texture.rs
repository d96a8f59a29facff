//! Solid (3D) procedural textures: value-noise fBm, checkers, stripes and blobs.
//!
//! Every texture is a pure function of the world-space point and a per-material seed, so a
//! surface point has the same colour from every camera and every sub-frame (multi-view
//! consistency is what SfM and training rely on), and the result never depends on threads.

use crate::geom::V3;

/// 32-bit integer hash (lowbias32 finaliser, Wellons) of three lattice coordinates and a seed.
pub fn hash3(ix: i32, iy: i32, iz: i32, seed: u32) -> u32 {
    let mut h = seed ^ 0x9e37_79b9;
    for v in [ix as u32, iy as u32, iz as u32] {
        h ^= v.wrapping_mul(0x85eb_ca6b);
        h ^= h >> 16;
        h = h.wrapping_mul(0x7feb_352d);
        h ^= h >> 15;
        h = h.wrapping_mul(0x846c_a68b);
        h ^= h >> 16;
    }
    h
}

/// Uniform value in [0, 1) from a hash.
pub fn unit(h: u32) -> f32 {
    (h >> 8) as f32 * (1.0 / 16_777_216.0)
}

fn smooth(t: f32) -> f32 {
    t * t * (3.0 - 2.0 * t)
}

fn lerp(a: f32, b: f32, t: f32) -> f32 {
    a + (b - a) * t
}

/// Trilinearly smoothed lattice value noise in [0, 1).
pub fn value_noise(p: V3, seed: u32) -> f32 {
    let (fx, fy, fz) = (p.x.floor(), p.y.floor(), p.z.floor());
    let (ix, iy, iz) = (fx as i32, fy as i32, fz as i32);
    let (tx, ty, tz) = (smooth(p.x - fx), smooth(p.y - fy), smooth(p.z - fz));
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

/// Soft-edged blobs: one sphere of random radius and centre per lattice cell (3³ neighbourhood),
/// returning 1 inside a blob, 0 outside, with a narrow smooth edge. Blob sizes vary 3× per cell so
/// the pattern carries structure at several scales.
pub fn blobs(p: V3, seed: u32) -> f32 {
    let (fx, fy, fz) = (p.x.floor(), p.y.floor(), p.z.floor());
    let (ix, iy, iz) = (fx as i32, fy as i32, fz as i32);
    let mut best = 0.0f32;
    for dz in -1..=1 {
        for dy in -1..=1 {
            for dx in -1..=1 {
                let (cx, cy, cz) = (ix + dx, iy + dy, iz + dz);
                let h = hash3(cx, cy, cz, seed);
                let centre = V3::new(
                    cx as f32 + unit(h),
                    cy as f32 + unit(hash3(cx, cy, cz, h)),
                    cz as f32 + unit(hash3(cz, cx, cy, h ^ 0x5bd1_e995)),
                );
                let radius = 0.2 + 0.45 * unit(h.rotate_left(13));
                let d = (p - centre).norm();
                let v = ((radius - d) / 0.04).clamp(0.0, 1.0);
                best = best.max(v);
            }
        }
    }
    best
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

//! Small fixed-size vector/rotation helpers for the ray caster and the camera model.
//!
//! gems-math owns the project's SE(3) maths; the generator only needs 3-vectors, 3×3 rotations and
//! the SO(3) exponential, so it keeps these few lines private instead of coupling the fixture
//! generator to the trainer's maths crate (a change there must not silently change every fixture).

use std::ops::{Add, Mul, Neg, Sub};

/// A 3-vector in f32: the ray caster's working type.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct V3 {
    pub x: f32,
    pub y: f32,
    pub z: f32,
}

impl V3 {
    pub const fn new(x: f32, y: f32, z: f32) -> Self {
        Self { x, y, z }
    }
    pub fn dot(self, o: V3) -> f32 {
        self.x * o.x + self.y * o.y + self.z * o.z
    }
    pub fn cross(self, o: V3) -> V3 {
        V3::new(
            self.y * o.z - self.z * o.y,
            self.z * o.x - self.x * o.z,
            self.x * o.y - self.y * o.x,
        )
    }
    pub fn norm(self) -> f32 {
        self.dot(self).sqrt()
    }
    pub fn normalized(self) -> V3 {
        self * (1.0 / self.norm())
    }
    pub fn mul_elem(self, o: V3) -> V3 {
        V3::new(self.x * o.x, self.y * o.y, self.z * o.z)
    }
    pub fn get(self, axis: usize) -> f32 {
        match axis {
            0 => self.x,
            1 => self.y,
            _ => self.z,
        }
    }
}

impl Add for V3 {
    type Output = V3;
    fn add(self, o: V3) -> V3 {
        V3::new(self.x + o.x, self.y + o.y, self.z + o.z)
    }
}
impl Sub for V3 {
    type Output = V3;
    fn sub(self, o: V3) -> V3 {
        V3::new(self.x - o.x, self.y - o.y, self.z - o.z)
    }
}
impl Mul<f32> for V3 {
    type Output = V3;
    fn mul(self, s: f32) -> V3 {
        V3::new(self.x * s, self.y * s, self.z * s)
    }
}
impl Neg for V3 {
    type Output = V3;
    fn neg(self) -> V3 {
        V3::new(-self.x, -self.y, -self.z)
    }
}

/// Row-major 3×3 matrix in f64 (poses are kept in f64 so written files are exact).
pub type M3 = [[f64; 3]; 3];

pub fn mat_mul(a: &M3, b: &M3) -> M3 {
    let mut r = [[0.0; 3]; 3];
    for (i, row) in r.iter_mut().enumerate() {
        for (j, v) in row.iter_mut().enumerate() {
            *v = (0..3).map(|k| a[i][k] * b[k][j]).sum();
        }
    }
    r
}

pub fn mat_vec(a: &M3, v: [f64; 3]) -> [f64; 3] {
    [0, 1, 2].map(|i| a[i][0] * v[0] + a[i][1] * v[1] + a[i][2] * v[2])
}

pub fn mat_t_vec(a: &M3, v: [f64; 3]) -> [f64; 3] {
    [0, 1, 2].map(|i| a[0][i] * v[0] + a[1][i] * v[1] + a[2][i] * v[2])
}

pub fn sub3(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

pub fn add3(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

pub fn norm3(a: [f64; 3]) -> f64 {
    (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt()
}

pub fn cross3(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

pub fn scale3(a: [f64; 3], s: f64) -> [f64; 3] {
    a.map(|v| v * s)
}

/// SO(3) exponential (Rodrigues) of a rotation vector, with the Taylor form near zero.
pub fn so3_exp(w: [f64; 3]) -> M3 {
    let th2 = w[0] * w[0] + w[1] * w[1] + w[2] * w[2];
    let th = th2.sqrt();
    let (a, b) = if th < 1e-6 {
        (1.0 - th2 / 6.0, 0.5 - th2 / 24.0)
    } else {
        (th.sin() / th, (1.0 - th.cos()) / th2)
    };
    let k = [[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]];
    let k2 = mat_mul(&k, &k);
    let mut r = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            r[i][j] = f64::from(u8::from(i == j)) + a * k[i][j] + b * k2[i][j];
        }
    }
    r
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn so3_exp_is_orthonormal_and_rotates_by_angle() {
        let w = [0.3, -0.2, 0.5];
        let r = so3_exp(w);
        let rt_r = mat_mul(&[0, 1, 2].map(|i| [0, 1, 2].map(|j| r[j][i])), &r);
        for (i, row) in rt_r.iter().enumerate() {
            for (j, v) in row.iter().enumerate() {
                assert!((v - f64::from(u8::from(i == j))).abs() < 1e-12);
            }
        }
        // The axis is fixed and a perpendicular vector turns by |w|.
        let axis = mat_vec(&r, w);
        assert!(norm3(sub3(axis, w)) < 1e-12);
        let p = cross3(w, [1.0, 0.0, 0.0]);
        let q = mat_vec(&r, p);
        let cos = (p[0] * q[0] + p[1] * q[1] + p[2] * q[2]) / (norm3(p) * norm3(q));
        assert!((cos.acos() - norm3(w)).abs() < 1e-9);
        // Small-angle branch agrees with the closed form.
        let small = so3_exp([1e-7, 0.0, 0.0]);
        assert!((small[2][1] - 1e-7).abs() < 1e-15);
    }
}

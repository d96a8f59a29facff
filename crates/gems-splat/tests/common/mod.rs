//! Test helpers: loading the gsplat reference cases and comparing arrays.
#![allow(dead_code)]

use std::collections::HashMap;

use gems_splat::{Camera, Gaussians, SH_COEFFS};
use safetensors::{Dtype, SafeTensors};

pub struct Case {
    pub name: String,
    pub tensors: HashMap<String, (Vec<usize>, Vec<f64>)>,
    pub width: u32,
    pub height: u32,
    pub sh_degree: u32,
}

impl Case {
    pub fn load(name: &str) -> Case {
        let path = format!(
            "{}/../../testdata/splat/{name}.safetensors",
            env!("CARGO_MANIFEST_DIR")
        );
        let bytes = std::fs::read(&path).unwrap_or_else(|e| panic!("{path}: {e}"));
        let (_, meta) = SafeTensors::read_metadata(&bytes).unwrap();
        let meta = meta.metadata().clone().unwrap();
        let st = SafeTensors::deserialize(&bytes).unwrap();
        let mut tensors = HashMap::new();
        for (k, v) in st.tensors() {
            let data: Vec<f64> = match v.dtype() {
                Dtype::F64 => v
                    .data()
                    .chunks_exact(8)
                    .map(|b| f64::from_le_bytes(b.try_into().unwrap()))
                    .collect(),
                Dtype::I32 => v
                    .data()
                    .chunks_exact(4)
                    .map(|b| i32::from_le_bytes(b.try_into().unwrap()) as f64)
                    .collect(),
                d => panic!("unexpected dtype {d:?}"),
            };
            tensors.insert(k.clone(), (v.shape().to_vec(), data));
        }
        let num = |k: &str| meta[k].parse::<u32>().unwrap();
        Case {
            name: name.into(),
            tensors,
            width: num("width"),
            height: num("height"),
            sh_degree: num("sh_degree"),
        }
    }

    pub fn get(&self, k: &str) -> &[f64] {
        &self.tensors[k].1
    }

    pub fn gaussians(&self) -> Gaussians {
        let means = self.get("means");
        let n = means.len() / 3;
        let q = self.get("quats");
        let ls = self.get("log_scales");
        let op = self.get("opacity_logits");
        let sh = self.get("sh_coeffs");
        let mut g = Gaussians::with_degree(self.sh_degree);
        for i in 0..n {
            let mut coeffs = [[0.0f32; 3]; SH_COEFFS];
            for (k, row) in coeffs.iter_mut().enumerate() {
                for (ch, v) in row.iter_mut().enumerate() {
                    *v = sh[(i * 16 + k) * 3 + ch] as f32;
                }
            }
            g.push(
                [0, 1, 2].map(|k| means[i * 3 + k] as f32),
                [0, 1, 2, 3].map(|k| q[i * 4 + k] as f32),
                [0, 1, 2].map(|k| ls[i * 3 + k] as f32),
                op[i] as f32,
                coeffs,
            );
        }
        g
    }

    pub fn cameras(&self) -> Vec<Camera> {
        let vm = self.get("viewmats");
        let ks = self.get("Ks");
        let nc = vm.len() / 16;
        (0..nc)
            .map(|c| {
                let m = &vm[c * 16..(c + 1) * 16];
                let k = &ks[c * 9..(c + 1) * 9];
                Camera {
                    fx: k[0] as f32,
                    fy: k[4] as f32,
                    cx: k[2] as f32,
                    cy: k[5] as f32,
                    width: self.width,
                    height: self.height,
                    rotation: [0, 1, 2].map(|r| [0, 1, 2].map(|cc| m[r * 4 + cc] as f32)),
                    translation: [0, 1, 2].map(|r| m[r * 4 + 3] as f32),
                }
            })
            .collect()
    }

    pub fn backgrounds(&self) -> Vec<[f32; 3]> {
        self.get("backgrounds")
            .chunks(3)
            .map(|b| [b[0] as f32, b[1] as f32, b[2] as f32])
            .collect()
    }
}

/// Asserts |a − e| ≤ atol + rtol·|e| elementwise.
pub fn assert_close(what: &str, actual: &[f64], expected: &[f64], rtol: f64, atol: f64) {
    assert_eq!(actual.len(), expected.len(), "{what}: length");
    let mut worst = (0.0f64, 0usize);
    for (k, (a, e)) in actual.iter().zip(expected).enumerate() {
        let excess = (a - e).abs() - (atol + rtol * e.abs());
        assert!(a.is_finite(), "{what}[{k}] is not finite");
        if excess > worst.0 {
            worst = (excess, k);
        }
    }
    let k = worst.1;
    assert!(
        worst.0 <= 0.0,
        "{what}[{k}]: got {} expected {} (rtol {rtol}, atol {atol})",
        actual[k],
        expected[k]
    );
}

/// Gradient tolerance of the test data README: rel 1e-3 with a floor of 1e-3·max|expected|.
pub fn assert_grad_close(what: &str, actual: &[f64], expected: &[f64]) {
    let max = expected.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    assert_close(what, actual, expected, 1e-3, 1e-3 * max);
}

pub fn flat3<T: Copy + Into<f64>>(v: &[[T; 3]]) -> Vec<f64> {
    v.iter().flat_map(|a| a.map(Into::into)).collect()
}

pub fn flat4<T: Copy + Into<f64>>(v: &[[T; 4]]) -> Vec<f64> {
    v.iter().flat_map(|a| a.map(Into::into)).collect()
}

pub fn flat_sh<T: Copy + Into<f64>>(v: &[[[T; 3]; 16]]) -> Vec<f64> {
    v.iter()
        .flat_map(|a| a.iter().flat_map(|r| r.map(Into::into)))
        .collect()
}

/// `[C,4,4]` → (dL/dR `[C,3,3]`, dL/dt `[C,3]`).
pub fn split_viewmat_grad(vm: &[f64]) -> (Vec<f64>, Vec<f64>) {
    let nc = vm.len() / 16;
    let mut r = Vec::new();
    let mut t = Vec::new();
    for c in 0..nc {
        for i in 0..3 {
            for j in 0..3 {
                r.push(vm[c * 16 + i * 4 + j]);
            }
            t.push(vm[c * 16 + i * 4 + 3]);
        }
    }
    (r, t)
}

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// A random scene of `n` Gaussians in front of `nc` cameras of `w`×`h` that orbit the origin a
/// little. `sh_scale` scales the higher SH coefficients; the DC term keeps colours positive.
pub fn random_scene(
    seed: u64,
    n: usize,
    nc: usize,
    w: u32,
    h: u32,
    sh_degree: u32,
    scale_range: (f32, f32),
) -> (Gaussians, Vec<Camera>, Vec<[f32; 3]>) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut g = Gaussians::with_degree(sh_degree);
    for _ in 0..n {
        let mean = [
            rng.random_range(-1.2f32..1.2),
            rng.random_range(-0.8f32..0.8),
            rng.random_range(-0.8f32..0.8),
        ];
        let quat = [0; 4].map(|_| rng.random_range(-1.0f32..1.0));
        let ls = [0; 3].map(|_| rng.random_range(scale_range.0..scale_range.1));
        let logit = rng.random_range(-2.0f32..2.5);
        let mut sh = [[0.0f32; 3]; SH_COEFFS];
        for (k, row) in sh.iter_mut().enumerate() {
            for v in row.iter_mut() {
                *v = if k == 0 {
                    rng.random_range(0.2f32..1.5)
                } else {
                    rng.random_range(-0.15f32..0.15)
                };
            }
        }
        g.push(mean, quat, ls, logit, sh);
    }
    let cams = (0..nc)
        .map(|c| {
            let a = 0.15 * c as f32 + rng.random_range(-0.05f32..0.05);
            let pos = [
                4.0 * a.sin(),
                rng.random_range(-0.2f32..0.2),
                -4.0 * a.cos(),
            ];
            let f = w as f32 * 0.9;
            // Computed in f32 and widened exactly, so the cameras are those the parity
            // tolerances were set on.
            Camera::look_at(
                &gems_math::Intrinsics {
                    fx: f64::from(f),
                    fy: f64::from(f * 1.02),
                    cx: f64::from(w as f32 * 0.5 + 0.3),
                    cy: f64::from(h as f32 * 0.5 - 0.2),
                    width: w,
                    height: h,
                },
                pos,
                [0.0, 0.0, 0.0],
                [0.0, -1.0, 0.0],
            )
            .unwrap()
        })
        .collect();
    let bgs = (0..nc)
        .map(|_| [0; 3].map(|_| rng.random_range(0.0f32..1.0)))
        .collect();
    (g, cams, bgs)
}

/// Random loss weights in [−1, 1].
pub fn random_weights(seed: u64, len: usize) -> Vec<f64> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..len).map(|_| rng.random_range(-1.0f64..1.0)).collect()
}

pub fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

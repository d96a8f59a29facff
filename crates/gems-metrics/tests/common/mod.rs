//! Loading of the reference vectors in testdata/metrics (repository root).
#![allow(dead_code)]

use std::collections::HashMap;

pub const PAIRS: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../../testdata/metrics/metrics_pairs.safetensors"
);
pub const LPIPS_WEIGHTS: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../../testdata/metrics/lpips_alex_random_weights.safetensors"
);

pub struct Pair {
    pub height: usize,
    pub width: usize,
    pub render: Vec<f64>,
    pub target: Vec<f64>,
    pub grad_ssim_valid: Vec<f64>,
    pub meta: HashMap<String, f64>,
}

impl Pair {
    pub fn render32(&self) -> Vec<f32> {
        self.render.iter().map(|&v| v as f32).collect()
    }
    pub fn target32(&self) -> Vec<f32> {
        self.target.iter().map(|&v| v as f32).collect()
    }
}

fn metadata() -> HashMap<String, String> {
    let bytes = std::fs::read(PAIRS).unwrap();
    let (_, meta) = safetensors::SafeTensors::read_metadata(&bytes).unwrap();
    meta.metadata().clone().unwrap_or_default()
}

pub fn load(name: &str) -> Pair {
    let bytes = std::fs::read(PAIRS).unwrap();
    let st = safetensors::SafeTensors::deserialize(&bytes).unwrap();
    let get = |k: &str| -> (Vec<usize>, Vec<f64>) {
        let t = st.tensor(&format!("{name}_{k}")).unwrap();
        assert_eq!(t.dtype(), safetensors::Dtype::F64);
        let v = t
            .data()
            .chunks_exact(8)
            .map(|c| f64::from_le_bytes(c.try_into().unwrap()))
            .collect();
        (t.shape().to_vec(), v)
    };
    let (shape, render) = get("render");
    let meta = metadata()
        .into_iter()
        .filter_map(|(k, v)| {
            k.strip_prefix(&format!("{name}_"))
                .map(|s| (s.to_owned(), v.parse().unwrap()))
        })
        .collect();
    Pair {
        height: shape[0],
        width: shape[1],
        render,
        target: get("target").1,
        grad_ssim_valid: get("grad_ssim_valid_wrt_render").1,
        meta,
    }
}

//! The file plumbing of checkpoints and trained results: named f32 tensors (Gaussians, Adam
//! moments, knots) in safetensors files. Every file is written with `gems_fs::write_atomic` (a
//! temporary file in the destination directory renamed into place), so a crash never leaves a
//! half-written file.

use std::collections::HashMap;
use std::path::Path;

use gems_splat::{Gaussians, SH_COEFFS};
use safetensors::{Dtype, SafeTensors, tensor::TensorView};

use crate::TrainError;

pub(crate) fn read(path: &Path) -> Result<Vec<u8>, TrainError> {
    std::fs::read(path).map_err(|e| TrainError::io(path, e))
}

pub(crate) fn format_err(path: &Path, reason: impl std::fmt::Display) -> TrainError {
    TrainError::Format {
        path: path.to_path_buf(),
        reason: reason.to_string(),
    }
}

/// Named f32 tensors to be written as one safetensors file.
#[derive(Default)]
pub(crate) struct TensorSet {
    tensors: Vec<(String, Vec<usize>, Vec<u8>)>,
}

impl TensorSet {
    pub(crate) fn add(&mut self, name: &str, shape: Vec<usize>, data: &[f32]) {
        self.tensors
            .push((name.to_owned(), shape, bytemuck::cast_slice(data).to_vec()));
    }

    pub(crate) fn serialize(&self, metadata: HashMap<String, String>) -> Result<Vec<u8>, String> {
        let views: Result<Vec<(String, TensorView<'_>)>, _> = self
            .tensors
            .iter()
            .map(|(n, s, d)| TensorView::new(Dtype::F32, s.clone(), d).map(|v| (n.clone(), v)))
            .collect();
        safetensors::serialize(views.map_err(|e| e.to_string())?, Some(metadata))
            .map_err(|e| e.to_string())
    }
}

/// Reads named f32 tensors of an expected element count.
pub(crate) struct TensorReader<'a> {
    st: SafeTensors<'a>,
    path: &'a Path,
}

impl<'a> TensorReader<'a> {
    pub(crate) fn new(bytes: &'a [u8], path: &'a Path) -> Result<Self, TrainError> {
        Ok(Self {
            st: SafeTensors::deserialize(bytes).map_err(|e| format_err(path, e))?,
            path,
        })
    }

    /// Element count of tensor `name`.
    pub(crate) fn element_count(&self, name: &str) -> Result<usize, TrainError> {
        Ok(self
            .st
            .tensor(name)
            .map_err(|e| format_err(self.path, e))?
            .shape()
            .iter()
            .product())
    }

    pub(crate) fn get(&self, name: &str, len: usize) -> Result<Vec<f32>, TrainError> {
        let t = self
            .st
            .tensor(name)
            .map_err(|e| format_err(self.path, format!("tensor {name}: {e}")))?;
        if t.dtype() != Dtype::F32 || t.data().len() != len * 4 {
            return Err(format_err(
                self.path,
                format!(
                    "tensor {name} is {:?} {:?}, expected {len} f32 values",
                    t.dtype(),
                    t.shape()
                ),
            ));
        }
        Ok(bytemuck::pod_collect_to_vec(t.data()))
    }
}

pub(crate) fn chunks<const W: usize>(v: &[f32]) -> Vec<[f32; W]> {
    v.chunks_exact(W)
        .map(|c| std::array::from_fn(|i| c[i]))
        .collect()
}

pub(crate) fn add_gaussians(ts: &mut TensorSet, g: &Gaussians) {
    let n = g.len();
    ts.add("means", vec![n, 3], bytemuck::cast_slice(&g.means));
    ts.add("quats", vec![n, 4], bytemuck::cast_slice(&g.quats));
    ts.add(
        "log_scales",
        vec![n, 3],
        bytemuck::cast_slice(&g.log_scales),
    );
    ts.add("opacity_logits", vec![n], &g.opacity_logits);
    ts.add("sh", vec![n, SH_COEFFS, 3], bytemuck::cast_slice(&g.sh));
}

pub(crate) fn read_gaussians(
    r: &TensorReader<'_>,
    n: usize,
    sh_degree: u32,
) -> Result<Gaussians, TrainError> {
    let sh = r.get("sh", n * SH_COEFFS * 3)?;
    Ok(Gaussians {
        means: chunks::<3>(&r.get("means", n * 3)?),
        quats: chunks::<4>(&r.get("quats", n * 4)?),
        log_scales: chunks::<3>(&r.get("log_scales", n * 3)?),
        opacity_logits: r.get("opacity_logits", n)?,
        sh: sh
            .chunks_exact(48)
            .map(|c| std::array::from_fn(|k| [c[3 * k], c[3 * k + 1], c[3 * k + 2]]))
            .collect(),
        sh_degree,
    })
}

//! LPIPS v0.1 with the AlexNet backbone (Zhang et al. 2018; the `lpips` Python package,
//! `LPIPS(net="alex", version="0.1")` called with `normalize=True`), on the CPU with candle.
//!
//! Network: inputs in [0, 1] → 2x − 1 → scaling layer (x − shift)/scale → torchvision AlexNet
//! `features` up to relu5: conv1 (11×11, stride 4, pad 2), ReLU, maxpool 3/2, conv2 (5×5, pad 2),
//! ReLU, maxpool 3/2, conv3/4/5 (3×3, pad 1) with ReLUs; the five ReLU outputs are unit-normalised
//! over channels (x / (‖x‖ + 1e-10)), differenced, squared, weighted by the 1×1 linear heads
//! `lin0..4` (no bias), averaged over space and summed over the five layers.
//!
//! # Weights
//! LPIPS is only reported when weights are given; without them it is absent, never a made-up
//! number. The official weights are two PyTorch files:
//! - the linear heads, `lpips/weights/v0.1/alex.pth` of the `lpips` package
//!   (<https://github.com/richzhang/PerceptualSimilarity>, file `lpips/weights/v0.1/alex.pth`);
//! - the AlexNet features, torchvision's `alexnet-owt-7be5be79.pth`
//!   (<https://download.pytorch.org/models/alexnet-owt-7be5be79.pth>).
//!
//! [`Lpips::load`] reads both directly (`Lpips::load(&["alex.pth", "alexnet-owt-7be5be79.pth"])`),
//! or a single safetensors file. To convert once to safetensors (lpips state_dict layout):
//! ```python
//! import lpips, safetensors.torch as st
//! m = lpips.LPIPS(net="alex", version="0.1")
//! st.save_file({k: v.contiguous() for k, v in m.state_dict().items()}, "lpips_alex.safetensors")
//! ```
//! Accepted tensor names: lpips layout (`net.slice1.0.weight`, `net.slice2.3.*`, `net.slice3.6.*`,
//! `net.slice4.8.*`, `net.slice5.10.*`, `lin0..4.model.1.weight`, optional
//! `scaling_layer.shift/scale`) or torchvision layout (`features.0/3/6/8/10.*`) for the convs.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use candle_core::{D, DType, Device, Tensor};

use crate::{MetricsError, check_pair};

/// The lpips package's ScalingLayer constants (registered buffers, not in `alex.pth`).
const DEFAULT_SHIFT: [f32; 3] = [-0.030, -0.088, -0.188];
const DEFAULT_SCALE: [f32; 3] = [0.458, 0.448, 0.450];

/// (lpips name, torchvision name, out channels, in channels, kernel, stride, padding).
const CONVS: [(&str, &str, usize, usize, usize, usize, usize); 5] = [
    ("net.slice1.0", "features.0", 64, 3, 11, 4, 2),
    ("net.slice2.3", "features.3", 192, 64, 5, 1, 2),
    ("net.slice3.6", "features.6", 384, 192, 3, 1, 1),
    ("net.slice4.8", "features.8", 256, 384, 3, 1, 1),
    ("net.slice5.10", "features.10", 256, 256, 3, 1, 1),
];

/// Errors of LPIPS loading and evaluation.
#[derive(Debug, thiserror::Error)]
pub enum LpipsError {
    #[error("cannot read LPIPS weights from {path}: {source}")]
    Read {
        path: PathBuf,
        source: candle_core::Error,
    },
    #[error("LPIPS weights ({files}) lack tensor `{name}`")]
    Missing { files: String, name: String },
    #[error("LPIPS tensor `{name}` in {files} has shape {got:?}, expected {expected:?}")]
    Shape {
        files: String,
        name: String,
        got: Vec<usize>,
        expected: Vec<usize>,
    },
    #[error("no LPIPS weight files given")]
    NoFiles,
    #[error(transparent)]
    Image(#[from] MetricsError),
    #[error("image {height}x{width} is too small for the AlexNet backbone (needs at least 31x31)")]
    TooSmall { height: usize, width: usize },
    #[error("LPIPS computation failed: {0}")]
    Compute(#[from] candle_core::Error),
}

/// A loaded LPIPS-Alex network.
pub struct Lpips {
    convs: Vec<(Tensor, Tensor, usize, usize)>,
    lins: Vec<Tensor>,
    shift: Tensor,
    scale: Tensor,
}

impl Lpips {
    /// Loads weights from one or more files (`.safetensors`, or PyTorch zip checkpoints `.pth` /
    /// `.pt` / `.bin`), merging their tensors. See the module docs for names and sources.
    pub fn load<P: AsRef<Path>>(paths: &[P]) -> Result<Self, LpipsError> {
        if paths.is_empty() {
            return Err(LpipsError::NoFiles);
        }
        let mut tensors = HashMap::new();
        for p in paths {
            let path = p.as_ref();
            let read_err = |source| LpipsError::Read {
                path: path.to_path_buf(),
                source,
            };
            let is_safetensors = path
                .extension()
                .is_some_and(|e| e.eq_ignore_ascii_case("safetensors"));
            if is_safetensors {
                tensors
                    .extend(candle_core::safetensors::load(path, &Device::Cpu).map_err(read_err)?);
            } else {
                tensors.extend(candle_core::pickle::read_all(path).map_err(read_err)?);
            }
        }
        let files = paths
            .iter()
            .map(|p| p.as_ref().display().to_string())
            .collect::<Vec<_>>()
            .join(", ");
        Self::from_tensors(&tensors, &files)
    }

    /// Builds the network from named tensors; `files` names their origin for error messages.
    pub fn from_tensors(
        tensors: &HashMap<String, Tensor>,
        files: &str,
    ) -> Result<Self, LpipsError> {
        let get =
            |names: &[String], expected: &[usize]| -> Result<Tensor, LpipsError> {
                let t = names.iter().find_map(|n| tensors.get(n)).ok_or_else(|| {
                    LpipsError::Missing {
                        files: files.to_string(),
                        name: names.join("` or `"),
                    }
                })?;
                if t.dims() != expected {
                    return Err(LpipsError::Shape {
                        files: files.to_string(),
                        name: names[0].clone(),
                        got: t.dims().to_vec(),
                        expected: expected.to_vec(),
                    });
                }
                Ok(t.to_dtype(DType::F32)?)
            };
        let mut convs = Vec::new();
        let mut lins = Vec::new();
        for (i, (lp, tv, cout, cin, k, stride, pad)) in CONVS.iter().enumerate() {
            let w = get(
                &[format!("{lp}.weight"), format!("{tv}.weight")],
                &[*cout, *cin, *k, *k],
            )?;
            let b = get(&[format!("{lp}.bias"), format!("{tv}.bias")], &[*cout])?;
            convs.push((w, b.reshape((1, *cout, 1, 1))?, *stride, *pad));
            lins.push(get(&[format!("lin{i}.model.1.weight")], &[1, *cout, 1, 1])?);
        }
        let constant = |name: &str, default: [f32; 3]| -> Result<Tensor, LpipsError> {
            match tensors.get(name) {
                Some(_) => get(&[name.to_string()], &[1, 3, 1, 1]),
                None => Ok(Tensor::from_slice(&default, (1, 3, 1, 1), &Device::Cpu)?),
            }
        };
        Ok(Lpips {
            convs,
            lins,
            shift: constant("scaling_layer.shift", DEFAULT_SHIFT)?,
            scale: constant("scaling_layer.scale", DEFAULT_SCALE)?,
        })
    }

    /// LPIPS distance between two [H, W, 3] images in [0, 1] (the lpips package's
    /// `normalize=True` path maps them to [−1, 1]).
    pub fn distance(
        &self,
        a: &[f32],
        b: &[f32],
        height: usize,
        width: usize,
    ) -> Result<f64, LpipsError> {
        check_pair(a, b, height, width)?;
        if height < 31 || width < 31 {
            return Err(LpipsError::TooSmall { height, width });
        }
        let mut data = Vec::with_capacity(a.len() * 2);
        data.extend_from_slice(a);
        data.extend_from_slice(b);
        let x =
            Tensor::from_vec(data, (2, height, width, 3), &Device::Cpu)?.permute((0, 3, 1, 2))?;
        let x = ((x * 2.0)? - 1.0)?;
        let mut h = x.broadcast_sub(&self.shift)?.broadcast_div(&self.scale)?;
        let mut total = 0.0f64;
        for (i, ((w, bias, stride, pad), lin)) in self.convs.iter().zip(&self.lins).enumerate() {
            if i == 1 || i == 2 {
                h = h.max_pool2d_with_stride(3, 2)?;
            }
            h = h
                .contiguous()?
                .conv2d(w, *pad, *stride, 1, 1)?
                .broadcast_add(bias)?
                .relu()?;
            let norm = (h.sqr()?.sum_keepdim(1)?.sqrt()? + 1e-10)?;
            let n = h.broadcast_div(&norm)?;
            let diff = (n.get(0)? - n.get(1)?)?.sqr()?;
            let weighted = diff.broadcast_mul(&lin.squeeze(0)?)?.sum(0)?;
            total += f64::from(weighted.flatten_all()?.mean(D::Minus1)?.to_vec0::<f32>()?);
        }
        Ok(total)
    }
}

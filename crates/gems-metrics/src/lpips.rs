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
//! or a single safetensors file. Both PyTorch formats are read: the zip format (`torch.save`
//! since PyTorch 1.6, via `candle_core::pickle`) and the older "legacy" stream format (magic
//! number, protocol, sys_info, the pickled state_dict, storage keys, raw storages), which older
//! checkpoints still use; the latter is parsed here with candle's pickle machine. To convert once to safetensors (lpips state_dict layout):
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

use std::io::{BufRead, BufReader, Read};

use candle_core::pickle::{Object, Stack};
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
                tensors.extend(read_pth(path).map_err(read_err)?);
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
                        files: files.to_owned(),
                        name: names.join("` or `"),
                    }
                })?;
                if t.dims() != expected {
                    return Err(LpipsError::Shape {
                        files: files.to_owned(),
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
                Some(_) => get(&[name.to_owned()], &[1, 3, 1, 1]),
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

/// The first pickle of a legacy-format PyTorch file: protocol 2, LONG1 of 10 bytes holding the
/// magic number 0x1950a86a20f9469cfc6c, STOP.
const LEGACY_MAGIC: [u8; 15] = [
    0x80, 0x02, 0x8a, 0x0a, 0x6c, 0xfc, 0x9c, 0x46, 0xf9, 0x20, 0x6a, 0xa8, 0x50, 0x19, 0x2e,
];

/// Reads every tensor of a PyTorch checkpoint, zip or legacy format.
fn read_pth(path: &Path) -> candle_core::Result<Vec<(String, Tensor)>> {
    let mut head = [0u8; 4];
    std::fs::File::open(path)?.read_exact(&mut head)?;
    if &head == b"PK\x03\x04" {
        candle_core::pickle::read_all(path)
    } else {
        read_legacy_pth(path)
    }
}

fn pickle_err(what: &str, obj: &Object) -> candle_core::Error {
    candle_core::Error::Msg(format!("unexpected {what} in legacy checkpoint: {obj:?}"))
}

fn next_pickle<R: BufRead>(r: &mut R) -> candle_core::Result<Object> {
    let mut stack = Stack::empty();
    stack.read_loop(r)?;
    stack.finalize()
}

/// One tensor of the legacy state_dict: storage key, element type, offset, shape, strides.
struct LegacyTensor {
    name: String,
    key: String,
    dtype: DType,
    offset: usize,
    shape: Vec<usize>,
    strides: Vec<usize>,
}

fn usizes(obj: Object) -> candle_core::Result<Vec<usize>> {
    match obj {
        Object::Tuple(v) | Object::List(v) => v
            .into_iter()
            .map(|o| match o {
                Object::Int(i) if i >= 0 => Ok(i as usize),
                Object::Long(i) if i >= 0 => Ok(i as usize),
                o => Err(pickle_err("dimension", &o)),
            })
            .collect(),
        o => Err(pickle_err("shape", &o)),
    }
}

fn legacy_tensor(name: String, value: Object) -> candle_core::Result<Option<LegacyTensor>> {
    let Object::Reduce { callable, args } = value else {
        return Ok(None);
    };
    let (callable, args) = match *callable {
        // nn.Parameter wrapping: _rebuild_parameter(tensor, requires_grad, hooks).
        Object::Class { ref class_name, .. } if class_name == "_rebuild_parameter" => {
            match args
                .tuple()
                .map_err(|o| pickle_err("parameter", &o))?
                .into_iter()
                .next()
            {
                Some(Object::Reduce { callable, args }) => (*callable, *args),
                other => return Err(pickle_err("parameter", &other.unwrap_or(Object::None))),
            }
        }
        c => (c, *args),
    };
    match &callable {
        Object::Class {
            module_name,
            class_name,
        } if module_name == "torch._utils"
            && (class_name == "_rebuild_tensor_v2" || class_name == "_rebuild_tensor") => {}
        _ => return Ok(None),
    }
    let mut args = args
        .tuple()
        .map_err(|o| pickle_err("tensor arguments", &o))?
        .into_iter();
    let (Some(storage), Some(offset), Some(shape), Some(strides)) =
        (args.next(), args.next(), args.next(), args.next())
    else {
        return Err(candle_core::Error::Msg(format!(
            "tensor `{name}` has too few rebuild arguments"
        )));
    };
    let storage = storage
        .persistent_load()
        .map_err(|o| pickle_err("storage reference", &o))?;
    // ('storage', <StorageType>, key, location, numel, view_metadata)
    let mut st = storage
        .tuple()
        .map_err(|o| pickle_err("storage id", &o))?
        .into_iter()
        .skip(1);
    let (Some(Object::Class { class_name, .. }), Some(Object::Unicode(key))) =
        (st.next(), st.next())
    else {
        return Err(candle_core::Error::Msg(format!(
            "tensor `{name}`: malformed storage id"
        )));
    };
    let dtype = match class_name.as_str() {
        "FloatStorage" => DType::F32,
        "DoubleStorage" => DType::F64,
        other => {
            return Err(candle_core::Error::Msg(format!(
                "tensor `{name}`: unsupported storage {other}"
            )));
        }
    };
    let offset = match offset {
        Object::Int(i) if i >= 0 => i as usize,
        Object::Long(i) if i >= 0 => i as usize,
        o => return Err(pickle_err("storage offset", &o)),
    };
    Ok(Some(LegacyTensor {
        name,
        key,
        dtype,
        offset,
        shape: usizes(shape)?,
        strides: usizes(strides)?,
    }))
}

/// Legacy (pre-zip) `torch.save` stream: magic, protocol version, sys_info, the object, the list
/// of storage keys, then per key an i64 element count and the raw little-endian storage.
fn read_legacy_pth(path: &Path) -> candle_core::Result<Vec<(String, Tensor)>> {
    let mut r = BufReader::new(std::fs::File::open(path)?);
    let mut magic = [0u8; LEGACY_MAGIC.len()];
    r.read_exact(&mut magic)?;
    if magic != LEGACY_MAGIC {
        candle_core::bail!("not a PyTorch checkpoint (neither zip nor legacy format)");
    }
    next_pickle(&mut r)?; // protocol version
    next_pickle(&mut r)?; // sys_info
    let Object::Dict(entries) = next_pickle(&mut r)? else {
        candle_core::bail!("legacy checkpoint does not hold a state_dict");
    };
    let mut tensors = Vec::new();
    for (k, v) in entries {
        if let Object::Unicode(name) = k
            && let Some(t) = legacy_tensor(name, v)?
        {
            tensors.push(t);
        }
    }
    let keys = match next_pickle(&mut r)? {
        Object::List(v) => v
            .into_iter()
            .map(|o| o.unicode().map_err(|o| pickle_err("storage key", &o)))
            .collect::<candle_core::Result<Vec<String>>>()?,
        o => return Err(pickle_err("storage key list", &o)),
    };
    let mut storages: HashMap<String, Vec<u8>> = HashMap::new();
    for key in keys {
        let mut n = [0u8; 8];
        r.read_exact(&mut n)?;
        let numel = i64::from_le_bytes(n);
        let elem = tensors
            .iter()
            .find(|t| t.key == key)
            .map_or(4, |t| t.dtype.size_in_bytes());
        let len = usize::try_from(numel)
            .ok()
            .and_then(|n| n.checked_mul(elem));
        let Some(len) = len.filter(|&l| l <= 1 << 34) else {
            candle_core::bail!("storage {key} has an invalid size {numel}");
        };
        let mut bytes = vec![0u8; len];
        r.read_exact(&mut bytes)?;
        storages.insert(key, bytes);
    }
    tensors
        .into_iter()
        .map(|t| {
            let numel: usize = t.shape.iter().product();
            let mut expected = 1;
            for (&dim, &stride) in t.shape.iter().zip(&t.strides).rev() {
                if dim > 1 && stride != expected {
                    candle_core::bail!("tensor `{}` is not contiguous", t.name);
                }
                expected *= dim;
            }
            let es = t.dtype.size_in_bytes();
            let bytes = storages
                .get(&t.key)
                .and_then(|b| b.get(t.offset * es..(t.offset + numel) * es));
            let Some(bytes) = bytes else {
                candle_core::bail!("tensor `{}` lies outside its storage", t.name);
            };
            let tensor = Tensor::from_raw_buffer(bytes, t.dtype, &t.shape, &Device::Cpu)?;
            Ok((t.name, tensor))
        })
        .collect()
}

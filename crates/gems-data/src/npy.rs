//! Reading and writing small float `.npy` arrays (via `npyz`) with untrusted-input guards.

use npyz::WriterBuilder;

use crate::error::FormatError;

/// A dense float64 array read from `.npy`, C order.
pub(crate) struct NpyF64 {
    pub shape: Vec<u64>,
    pub data: Vec<f64>,
}

/// Parses an `.npy` holding float32 or float64 values (either byte order, C or Fortran order;
/// Fortran arrays are transposed to C order). The declared size is checked against the byte
/// count before anything is allocated.
pub(crate) fn parse_f64(bytes: &[u8]) -> Result<NpyF64, FormatError> {
    let npy = npyz::NpyFile::new(bytes)
        .map_err(|e| FormatError::new(format!("not a valid .npy file: {e}")))?;
    let shape = npy.shape().to_vec();
    let header_len = npy_header_len(bytes);
    let elem = match npy.dtype() {
        npyz::DType::Plain(ts) => ts.size_field(),
        other => {
            return Err(FormatError::new(format!(
                "expected a float array, found dtype {}",
                other.descr()
            )));
        }
    };
    let len = shape
        .iter()
        .try_fold(1u64, |a, &d| a.checked_mul(d))
        .filter(|&n| {
            n.checked_mul(elem)
                .is_some_and(|b| b <= bytes.len().saturating_sub(header_len) as u64)
        })
        .ok_or_else(|| {
            FormatError::new(format!(
                "truncated .npy: shape {shape:?} needs more data than the file holds"
            ))
        })?;
    let order = npy.order();
    let descr = npy.dtype().descr().trim_matches('\'').to_owned();
    let data: Vec<f64> = if descr.ends_with("f8") {
        npy.into_vec::<f64>()
    } else if descr.ends_with("f4") {
        npy.into_vec::<f32>()
            .map(|v| v.into_iter().map(f64::from).collect())
    } else {
        return Err(FormatError::new(format!(
            "expected float32/float64 data, found dtype {descr}"
        )));
    }
    .map_err(|e| FormatError::new(format!("bad .npy data: {e}")))?;
    if data.len() as u64 != len {
        return Err(FormatError::new(format!(
            "truncated .npy: shape {shape:?} declares {len} values, found {}",
            data.len()
        )));
    }
    let data = if order == npyz::Order::Fortran && shape.len() > 1 {
        fortran_to_c(&data, &shape)
    } else {
        data
    };
    Ok(NpyF64 { shape, data })
}

/// Byte length of the magic + header of an `.npy` (0 if it cannot be determined; only used to
/// tighten the size check).
fn npy_header_len(bytes: &[u8]) -> usize {
    match bytes.get(6) {
        Some(1) if bytes.len() >= 10 => 10 + u16::from_le_bytes([bytes[8], bytes[9]]) as usize,
        Some(2 | 3) if bytes.len() >= 12 => {
            12 + u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize
        }
        _ => 0,
    }
}

fn fortran_to_c(data: &[f64], shape: &[u64]) -> Vec<f64> {
    let dims: Vec<usize> = shape.iter().map(|&d| d as usize).collect();
    let mut out = vec![0.0; data.len()];
    let mut idx = vec![0usize; dims.len()];
    for v in &mut out {
        // Fortran offset of the current C-order multi-index.
        let mut off = 0;
        let mut stride = 1;
        for (k, &d) in dims.iter().enumerate() {
            off += idx[k] * stride;
            stride *= d;
        }
        *v = data[off];
        for k in (0..dims.len()).rev() {
            idx[k] += 1;
            if idx[k] < dims[k] {
                break;
            }
            idx[k] = 0;
        }
    }
    out
}

/// Serialises a float64 C-order array as `.npy` bytes (format 1.0, little-endian `<f8`).
pub(crate) fn to_bytes_f64(shape: &[u64], data: &[f64]) -> Vec<u8> {
    let mut out = Vec::with_capacity(128 + data.len() * 8);
    let mut w = npyz::WriteOptions::new()
        .default_dtype()
        .shape(shape)
        .writer(&mut out)
        .begin_nd()
        .expect("writing to a Vec cannot fail");
    w.extend(data.iter().copied())
        .expect("writing to a Vec cannot fail");
    w.finish().expect("writing to a Vec cannot fail");
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_and_header_alignment() {
        let data: Vec<f64> = (0..34).map(|i| i as f64 * 0.5 - 3.0).collect();
        let bytes = to_bytes_f64(&[2, 17], &data);
        assert_eq!(&bytes[..6], b"\x93NUMPY");
        assert_eq!(
            npy_header_len(&bytes) % 64,
            0,
            "data must start 64-byte aligned"
        );
        let back = parse_f64(&bytes).unwrap();
        assert_eq!(back.shape, vec![2, 17]);
        assert_eq!(back.data, data);
    }

    #[test]
    fn truncated_data_is_rejected() {
        let bytes = to_bytes_f64(&[3, 17], &[1.0; 51]);
        for cut in [bytes.len() - 1, bytes.len() - 8, 20, 5] {
            assert!(parse_f64(&bytes[..cut]).is_err(), "cut at {cut}");
        }
    }

    #[test]
    fn fortran_order_is_transposed() {
        // 2×3 array [[0,1,2],[3,4,5]] stored column-major: 0,3,1,4,2,5.
        let f = [0.0, 3.0, 1.0, 4.0, 2.0, 5.0];
        assert_eq!(
            fortran_to_c(&f, &[2, 3]),
            vec![0.0, 1.0, 2.0, 3.0, 4.0, 5.0]
        );
    }
}

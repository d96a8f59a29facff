//! LLFF `poses_bounds.npy` (N×17) and ExBluRF `poses_bounds_subframes.npy` (N×S×17).
//!
//! Each row is a 3×5 row-major matrix followed by `near, far`. Columns 0–2 are the
//! camera-to-world rotation with axes in LLFF's **[down, right, backwards]** order, column 3 is the
//! camera centre, column 4 is `[height, width, focal]`. Rows are sorted by image name.
//!
//! [`LlffRow`] keeps the raw 17 numbers (so reading and re-writing is exact); [`LlffRow::pose`]
//! and [`LlffRow::from_pose`] convert to and from gems' world-to-camera OpenCV [`gems_math::Pose`]:
//! OpenCV c2w columns = `[col1, col0, −col2]`.

use std::path::Path;

use crate::error::{DataError, FormatError, Result};
use crate::fsutil::read_bytes;
use crate::npy;
use gems_math::{Intrinsics, Pose};

/// Tolerance on `|RᵀR − I|` for a row's rotation to count as a rotation. LLFF files are written
/// in float64 from orthonormal matrices, so anything larger means corrupt or mis-ordered data.
const ROTATION_TOLERANCE: f64 = 1e-3;

/// One row of an LLFF poses file.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LlffRow {
    /// Row-major 3×5 `[R(down,right,back) | centre | hwf]`.
    pub matrix: [[f64; 5]; 3],
    /// Near depth bound.
    pub near: f64,
    /// Far depth bound.
    pub far: f64,
}

impl LlffRow {
    /// World-to-camera pose (OpenCV axes).
    pub fn pose(&self) -> Pose {
        let m = &self.matrix;
        let mut r_c2w = [[0.0; 3]; 3];
        for (i, row) in r_c2w.iter_mut().enumerate() {
            *row = [m[i][1], m[i][0], -m[i][2]];
        }
        Pose::from_camera_to_world(r_c2w, [m[0][3], m[1][3], m[2][3]])
    }

    /// Image height stored in the row.
    pub fn height(&self) -> f64 {
        self.matrix[0][4]
    }
    /// Image width stored in the row.
    pub fn width(&self) -> f64 {
        self.matrix[1][4]
    }
    /// Focal length (pixels at `width × height`) stored in the row.
    pub fn focal(&self) -> f64 {
        self.matrix[2][4]
    }

    /// Pinhole intrinsics implied by the row (principal point at the image centre, as LLFF
    /// loaders assume).
    pub fn intrinsics(&self) -> Intrinsics {
        let (w, h) = (self.width(), self.height());
        Intrinsics {
            fx: self.focal(),
            fy: self.focal(),
            cx: w / 2.0,
            cy: h / 2.0,
            width: w.round() as u32,
            height: h.round() as u32,
        }
    }

    /// Row for a world-to-camera pose, image size, focal length and depth bounds.
    pub fn from_pose(
        pose: &Pose,
        height: f64,
        width: f64,
        focal: f64,
        near: f64,
        far: f64,
    ) -> Self {
        let r = pose.rotation_c2w();
        let c = pose.center();
        let mut matrix = [[0.0; 5]; 3];
        for i in 0..3 {
            matrix[i] = [r[i][1], r[i][0], -r[i][2], c[i], [height, width, focal][i]];
        }
        LlffRow { matrix, near, far }
    }

    fn from_slice(v: &[f64]) -> Self {
        let mut matrix = [[0.0; 5]; 3];
        for (i, row) in matrix.iter_mut().enumerate() {
            row.copy_from_slice(&v[i * 5..i * 5 + 5]);
        }
        LlffRow {
            matrix,
            near: v[15],
            far: v[16],
        }
    }

    fn push_to(&self, out: &mut Vec<f64>) {
        for row in &self.matrix {
            out.extend_from_slice(row);
        }
        out.push(self.near);
        out.push(self.far);
    }

    fn check(&self, what: &str) -> std::result::Result<(), FormatError> {
        if !self
            .matrix
            .iter()
            .flatten()
            .chain([&self.near, &self.far])
            .all(|v| v.is_finite())
        {
            return Err(FormatError::new(format!(
                "{what} contains NaN or infinite values"
            )));
        }
        if !(self.height() >= 1.0 && self.width() >= 1.0 && self.focal() > 0.0) {
            return Err(FormatError::new(format!(
                "{what} has invalid [height, width, focal] = [{}, {}, {}]",
                self.height(),
                self.width(),
                self.focal()
            )));
        }
        let m = &self.matrix;
        let r = [
            [m[0][0], m[0][1], m[0][2]],
            [m[1][0], m[1][1], m[1][2]],
            [m[2][0], m[2][1], m[2][2]],
        ];
        // [down, right, back] = [y, x, −z] of a right-handed frame: one swap and one negation,
        // so a valid row still has det = +1 and the plain rotation check applies.
        let err = gems_math::rotation_error(&r);
        if err.is_nan() || err > ROTATION_TOLERANCE {
            return Err(FormatError::new(format!(
                "{what} does not hold a rotation (orthonormality/determinant error {err:.3e})"
            )));
        }
        Ok(())
    }
}

/// Parses `poses_bounds.npy` bytes (N×17, float32 or float64).
pub fn parse_poses_bounds(bytes: &[u8]) -> std::result::Result<Vec<LlffRow>, FormatError> {
    let a = npy::parse_f64(bytes)?;
    if a.shape.len() != 2 || a.shape[1] != 17 {
        return Err(FormatError::new(format!(
            "expected shape (N, 17), found {:?}",
            a.shape
        )));
    }
    a.data
        .chunks_exact(17)
        .enumerate()
        .map(|(i, c)| {
            let row = LlffRow::from_slice(c);
            row.check(&format!("row {i}"))?;
            Ok(row)
        })
        .collect()
}

/// Parses `poses_bounds_subframes.npy` bytes (N×S×17): `result[i][s]` is sub-frame `s` of image
/// `i`, in exposure-time order.
pub fn parse_subframes(bytes: &[u8]) -> std::result::Result<Vec<Vec<LlffRow>>, FormatError> {
    let a = npy::parse_f64(bytes)?;
    if a.shape.len() != 3 || a.shape[2] != 17 || a.shape[1] == 0 {
        return Err(FormatError::new(format!(
            "expected shape (N, S, 17) with S ≥ 1, found {:?}",
            a.shape
        )));
    }
    let s = a.shape[1] as usize;
    a.data
        .chunks_exact(17 * s)
        .enumerate()
        .map(|(i, img)| {
            img.chunks_exact(17)
                .enumerate()
                .map(|(k, c)| {
                    let row = LlffRow::from_slice(c);
                    row.check(&format!("image {i} sub-frame {k}"))?;
                    Ok(row)
                })
                .collect()
        })
        .collect()
}

/// Serialises rows as `poses_bounds.npy` bytes (float64, N×17).
pub fn poses_bounds_to_bytes(rows: &[LlffRow]) -> Vec<u8> {
    let mut data = Vec::with_capacity(rows.len() * 17);
    for r in rows {
        r.push_to(&mut data);
    }
    npy::to_bytes_f64(&[rows.len() as u64, 17], &data)
}

/// Reads `poses_bounds.npy`.
pub fn read_poses_bounds(path: &Path) -> Result<Vec<LlffRow>> {
    parse_poses_bounds(&read_bytes(path)?).map_err(|e| DataError::from_format(path, e))
}

/// Writes `poses_bounds.npy` atomically.
pub fn write_poses_bounds(path: &Path, rows: &[LlffRow]) -> Result<()> {
    Ok(gems_fs::write_atomic(path, &poses_bounds_to_bytes(rows))?)
}

/// Reads `poses_bounds_subframes.npy`.
pub fn read_subframes(path: &Path) -> Result<Vec<Vec<LlffRow>>> {
    parse_subframes(&read_bytes(path)?).map_err(|e| DataError::from_format(path, e))
}

/// Writes `poses_bounds_subframes.npy` atomically. Every image must have the same number of
/// sub-frames (the file is a dense N×S×17 array).
pub fn write_subframes(path: &Path, rows: &[Vec<LlffRow>]) -> Result<()> {
    let s = rows.first().map_or(0, Vec::len);
    if let Some((i, r)) = rows.iter().enumerate().find(|(_, r)| r.len() != s) {
        return Err(DataError::format(
            path,
            format!(
                "cannot write: image {i} has {} sub-frames but image 0 has {s}",
                r.len()
            ),
        ));
    }
    let mut data = Vec::with_capacity(rows.len() * s * 17);
    rows.iter().flatten().for_each(|r| r.push_to(&mut data));
    Ok(gems_fs::write_atomic(
        path,
        &npy::to_bytes_f64(&[rows.len() as u64, s as u64, 17], &data),
    )?)
}

//! nerfstudio / instant-ngp / NeRF-Blender `transforms.json`, read and write.
//!
//! `transform_matrix` is **camera-to-world with OpenGL camera axes** (x right, y up, z back);
//! gems' OpenCV axes are obtained by negating the y and z columns. Intrinsics come from
//! `fl_x, fl_y, cx, cy, w, h` (top level or per frame) or, in NeRF-Blender files, from
//! `camera_angle_x` (resolved against the image size by [`CameraSpec::resolve`]). Non-zero
//! distortion (`k1..k4, p1, p2`) and non-pinhole `camera_model`s are rejected with an error.
//! Optional `train_filenames` / `val_filenames` / `test_filenames` lists mark the split.
//! E2NeRF's synthetic scenes store a list of matrices along the exposure per frame
//! ([`Frame::subframe_poses`]).

use std::path::Path;

use serde_json::{Map, Value, json};

use crate::error::{DataError, FormatError, Result};
use crate::fsutil::read_text;
use gems_math::{Intrinsics, Pose};

/// How a frame's intrinsics are given.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum CameraSpec {
    /// Explicit pinhole intrinsics.
    Pinhole(Intrinsics),
    /// Horizontal field of view in radians (NeRF-Blender), principal point at the centre.
    FovX(f64),
}

impl CameraSpec {
    /// Intrinsics for an image of `width × height` (explicit intrinsics are rescaled if the
    /// image is a resized copy).
    pub fn resolve(&self, width: u32, height: u32) -> Intrinsics {
        match *self {
            CameraSpec::Pinhole(k) => k.resized(width, height),
            CameraSpec::FovX(angle) => {
                let f = 0.5 * f64::from(width) / (0.5 * angle).tan();
                Intrinsics {
                    fx: f,
                    fy: f,
                    cx: f64::from(width) / 2.0,
                    cy: f64::from(height) / 2.0,
                    width,
                    height,
                }
            }
        }
    }
}

/// Split mark of a frame from the `*_filenames` lists.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FrameSplit {
    /// Listed in `train_filenames`.
    Train,
    /// Listed in `val_filenames` or `test_filenames`.
    Eval,
}

/// One frame of a transforms file.
#[derive(Debug, Clone, PartialEq)]
pub struct Frame {
    /// Image path as written in the file (relative to the file's folder).
    pub file_path: String,
    /// World-to-camera pose, OpenCV axes (with [`Frame::subframe_poses`]: the middle one).
    pub pose: Pose,
    /// Poses along the exposure in time order, when `transform_matrix` holds a list of matrices
    /// (E2NeRF's synthetic scenes); empty for one matrix.
    pub subframe_poses: Vec<Pose>,
    /// Intrinsics of this frame.
    pub camera: CameraSpec,
    /// Split, when the file lists one.
    pub split: Option<FrameSplit>,
}

/// Contents of a transforms file.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Transforms {
    /// Frames in file order.
    pub frames: Vec<Frame>,
}

/// World-to-camera (OpenCV) pose from a nerfstudio camera-to-world OpenGL 4×4 matrix.
pub fn pose_from_opengl_c2w(m: &[[f64; 4]; 4]) -> Pose {
    let mut r = [[0.0; 3]; 3];
    for (i, row) in r.iter_mut().enumerate() {
        *row = [m[i][0], -m[i][1], -m[i][2]];
    }
    Pose::from_camera_to_world(r, [m[0][3], m[1][3], m[2][3]])
}

/// nerfstudio camera-to-world OpenGL 4×4 matrix of a world-to-camera (OpenCV) pose.
pub fn pose_to_opengl_c2w(pose: &Pose) -> [[f64; 4]; 4] {
    let r = pose.rotation_c2w();
    let c = pose.center();
    let mut m = [[0.0; 4]; 4];
    for i in 0..3 {
        m[i] = [r[i][0], -r[i][1], -r[i][2], c[i]];
    }
    m[3] = [0.0, 0.0, 0.0, 1.0];
    m
}

fn num(obj: &Map<String, Value>, key: &str) -> Option<f64> {
    obj.get(key).and_then(Value::as_f64)
}

fn camera_of(
    obj: &Map<String, Value>,
    parent: Option<&CameraSpec>,
    what: &str,
) -> std::result::Result<Option<CameraSpec>, FormatError> {
    if let Some(model) = obj.get("camera_model").and_then(Value::as_str)
        && !matches!(model, "OPENCV" | "PINHOLE" | "SIMPLE_PINHOLE")
    {
        return Err(FormatError::new(format!(
            "{what}: camera_model {model} is not supported (gems needs undistorted pinhole images)"
        )));
    }
    for k in ["k1", "k2", "k3", "k4", "p1", "p2"] {
        if let Some(v) = num(obj, k)
            && v != 0.0
        {
            return Err(FormatError::new(format!(
                "{what}: non-zero distortion {k} = {v}; undistort the images first"
            )));
        }
    }
    if let Some(fx) = num(obj, "fl_x") {
        let fy = num(obj, "fl_y").unwrap_or(fx);
        let (w, h) = match (num(obj, "w"), num(obj, "h")) {
            (Some(w), Some(h)) => (w, h),
            _ => match parent {
                Some(CameraSpec::Pinhole(k)) => (f64::from(k.width), f64::from(k.height)),
                _ => {
                    return Err(FormatError::new(format!(
                        "{what}: fl_x given without image size w/h"
                    )));
                }
            },
        };
        let cx = num(obj, "cx").unwrap_or(w / 2.0);
        let cy = num(obj, "cy").unwrap_or(h / 2.0);
        let valid = [fx, fy, cx, cy].iter().all(|v| v.is_finite())
            && fx > 0.0
            && fy > 0.0
            && w >= 1.0
            && h >= 1.0
            && w <= f64::from(u32::MAX)
            && h <= f64::from(u32::MAX);
        if !valid {
            return Err(FormatError::new(format!(
                "{what}: invalid intrinsics fl_x={fx} fl_y={fy} cx={cx} cy={cy} w={w} h={h}"
            )));
        }
        return Ok(Some(CameraSpec::Pinhole(Intrinsics {
            fx,
            fy,
            cx,
            cy,
            width: w as u32,
            height: h as u32,
        })));
    }
    if let Some(a) = num(obj, "camera_angle_x") {
        if !(a.is_finite() && a > 0.0 && a < std::f64::consts::PI) {
            return Err(FormatError::new(format!(
                "{what}: invalid camera_angle_x {a}"
            )));
        }
        return Ok(Some(CameraSpec::FovX(a)));
    }
    Ok(parent.copied())
}

/// Parses the text of a transforms file (every frame must name its image in `file_path`).
pub fn parse_transforms(text: &str) -> std::result::Result<Transforms, FormatError> {
    parse_frames(text, None)
}

/// Parses a NeRF-Blender split file (`transforms_<split>.json`, E2NeRF's
/// `transform_<split>.json`): a frame without `file_path` names `default_path(index)`.
pub fn parse_split_transforms(
    text: &str,
    default_path: &dyn Fn(usize) -> String,
) -> std::result::Result<Transforms, FormatError> {
    parse_frames(text, Some(default_path))
}

/// One camera-to-world matrix (4×4, or 3×4 with the last row implied).
fn matrix_of(rows: &[Value], what: &str) -> std::result::Result<[[f64; 4]; 4], FormatError> {
    if rows.len() != 4 && rows.len() != 3 {
        return Err(FormatError::new(format!(
            "{what}: transform_matrix must be a 4×4 (or 3×4) array"
        )));
    }
    let mut m = [
        [0.0, 0.0, 0.0, 0.0],
        [0.0; 4],
        [0.0; 4],
        [0.0, 0.0, 0.0, 1.0],
    ];
    for (r, row) in rows.iter().enumerate() {
        let vals = row.as_array().filter(|v| v.len() == 4).ok_or_else(|| {
            FormatError::new(format!(
                "{what}: transform_matrix row {r} must have 4 numbers"
            ))
        })?;
        for (c, v) in vals.iter().enumerate() {
            m[r][c] = v.as_f64().ok_or_else(|| {
                FormatError::new(format!("{what}: transform_matrix has a non-number"))
            })?;
        }
    }
    let rot = [
        [m[0][0], m[0][1], m[0][2]],
        [m[1][0], m[1][1], m[1][2]],
        [m[2][0], m[2][1], m[2][2]],
    ];
    let err = gems_math::rotation_error(&rot);
    if !m.iter().flatten().all(|v| v.is_finite()) || err.is_nan() || err > 1e-3 {
        return Err(FormatError::new(format!(
            "{what}: transform_matrix is not a finite rigid transform (rotation error {err:.2e})"
        )));
    }
    Ok(m)
}

/// The poses of a frame's `transform_matrix`: one matrix, or (E2NeRF's synthetic scenes,
/// `iCVTEAM/E2NeRF:load_blender.py`) a list of matrices along the exposure, in time order.
fn poses_of(value: Option<&Value>, what: &str) -> std::result::Result<Vec<Pose>, FormatError> {
    let rows = value
        .and_then(Value::as_array)
        .ok_or_else(|| FormatError::new(format!("{what}: missing transform_matrix array")))?;
    let nested = rows
        .first()
        .and_then(Value::as_array)
        .and_then(|r| r.first())
        .is_some_and(Value::is_array);
    if !nested {
        return Ok(vec![pose_from_opengl_c2w(&matrix_of(rows, what)?)]);
    }
    rows.iter()
        .enumerate()
        .map(|(j, m)| {
            let rows = m.as_array().ok_or_else(|| {
                FormatError::new(format!("{what}: transform_matrix {j} is not an array"))
            })?;
            Ok(pose_from_opengl_c2w(&matrix_of(
                rows,
                &format!("{what}, matrix {j}"),
            )?))
        })
        .collect()
}

fn parse_frames(
    text: &str,
    default_path: Option<&dyn Fn(usize) -> String>,
) -> std::result::Result<Transforms, FormatError> {
    let root: Value =
        serde_json::from_str(text).map_err(|e| FormatError::new(format!("invalid JSON: {e}")))?;
    let obj = root
        .as_object()
        .ok_or_else(|| FormatError::new("top level must be a JSON object"))?;
    let shared = camera_of(obj, None, "top level")?;
    let frames = obj
        .get("frames")
        .and_then(Value::as_array)
        .ok_or_else(|| FormatError::new("missing \"frames\" array"))?;
    let list = |key: &str| -> Vec<String> {
        obj.get(key)
            .and_then(Value::as_array)
            .map(|a| {
                a.iter()
                    .filter_map(|v| v.as_str().map(str::to_owned))
                    .collect()
            })
            .unwrap_or_default()
    };
    let train = list("train_filenames");
    let eval: Vec<String> = list("val_filenames")
        .into_iter()
        .chain(list("test_filenames"))
        .collect();
    let mut out = Vec::with_capacity(frames.len());
    for (i, f) in frames.iter().enumerate() {
        let what = format!("frame {i}");
        let fo = f
            .as_object()
            .ok_or_else(|| FormatError::new(format!("{what} is not an object")))?;
        let file_path = match (fo.get("file_path").and_then(Value::as_str), default_path) {
            (Some(p), _) => p.to_owned(),
            (None, Some(default)) => default(i),
            (None, None) => return Err(FormatError::new(format!("{what}: missing file_path"))),
        };
        let mut poses = poses_of(fo.get("transform_matrix"), &what)?;
        if poses.is_empty() {
            return Err(FormatError::new(format!(
                "{what}: transform_matrix holds no matrix"
            )));
        }
        let camera = camera_of(fo, shared.as_ref(), &what)?.ok_or_else(|| {
            FormatError::new(format!(
                "{what}: no intrinsics (fl_x/fl_y/cx/cy/w/h or camera_angle_x) at top level or in the frame"
            ))
        })?;
        let split = if eval.contains(&file_path) {
            Some(FrameSplit::Eval)
        } else if train.contains(&file_path) {
            Some(FrameSplit::Train)
        } else {
            None
        };
        let (pose, subframe_poses) = if poses.len() == 1 {
            (poses.remove(0), Vec::new())
        } else {
            (poses[poses.len() / 2], poses)
        };
        out.push(Frame {
            file_path,
            pose,
            subframe_poses,
            camera,
            split,
        });
    }
    Ok(Transforms { frames: out })
}

/// Reads a transforms file.
pub fn read_transforms(path: &Path) -> Result<Transforms> {
    parse_transforms(&read_text(path)?).map_err(|e| DataError::from_format(path, e))
}

/// Serialises to nerfstudio JSON: shared intrinsics at the top level when all frames agree,
/// per-frame otherwise; `camera_model` `OPENCV` with zero distortion; split lists when any
/// frame has a split.
pub fn transforms_to_json(t: &Transforms) -> String {
    let cam_json = |c: &CameraSpec| -> Map<String, Value> {
        let mut m = Map::new();
        match c {
            CameraSpec::Pinhole(k) => {
                m.insert("camera_model".into(), json!("OPENCV"));
                m.insert("fl_x".into(), json!(k.fx));
                m.insert("fl_y".into(), json!(k.fy));
                m.insert("cx".into(), json!(k.cx));
                m.insert("cy".into(), json!(k.cy));
                m.insert("w".into(), json!(k.width));
                m.insert("h".into(), json!(k.height));
                for d in ["k1", "k2", "p1", "p2"] {
                    m.insert(d.into(), json!(0.0));
                }
            }
            CameraSpec::FovX(a) => {
                m.insert("camera_angle_x".into(), json!(a));
            }
        }
        m
    };
    let shared = t
        .frames
        .first()
        .map(|f| f.camera)
        .filter(|c| t.frames.iter().all(|f| f.camera == *c));
    let mut root = shared.as_ref().map(cam_json).unwrap_or_default();
    let frames: Vec<Value> = t
        .frames
        .iter()
        .map(|f| {
            let mut m = if shared.is_some() {
                Map::new()
            } else {
                cam_json(&f.camera)
            };
            m.insert("file_path".into(), json!(f.file_path));
            let matrix = if f.subframe_poses.is_empty() {
                json!(pose_to_opengl_c2w(&f.pose))
            } else {
                let all: Vec<_> = f.subframe_poses.iter().map(pose_to_opengl_c2w).collect();
                json!(all)
            };
            m.insert("transform_matrix".into(), matrix);
            Value::Object(m)
        })
        .collect();
    root.insert("frames".into(), Value::Array(frames));
    if t.frames.iter().any(|f| f.split.is_some()) {
        let names = |s: FrameSplit| -> Vec<&str> {
            t.frames
                .iter()
                .filter(|f| f.split == Some(s))
                .map(|f| f.file_path.as_str())
                .collect()
        };
        root.insert("train_filenames".into(), json!(names(FrameSplit::Train)));
        root.insert("val_filenames".into(), json!(names(FrameSplit::Eval)));
        root.insert("test_filenames".into(), json!(names(FrameSplit::Eval)));
    }
    let mut s =
        serde_json::to_string_pretty(&Value::Object(root)).expect("a JSON value always serialises");
    s.push('\n');
    s
}

/// Writes a transforms file atomically.
pub fn write_transforms(path: &Path, t: &Transforms) -> Result<()> {
    Ok(gems_fs::write_atomic(
        path,
        transforms_to_json(t).as_bytes(),
    )?)
}

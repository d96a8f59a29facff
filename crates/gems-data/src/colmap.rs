//! COLMAP sparse models (`cameras`, `images`, `points3D`), binary and text, read and write.
//!
//! Layout per COLMAP's `reconstruction_io_{binary,text}.cc` (little-endian, no padding). Records
//! are kept in file order so that reading and re-writing a binary model reproduces it byte for
//! byte. Poses are COLMAP's `cam_from_world` (= gems' world-to-camera, OpenCV axes): the raw
//! quaternion is kept ([`Image::qvec`]) and [`Image::pose`] converts it.
//!
//! The byte parsers (`parse_*_bin`, `parse_*_txt`) are public so they can be fuzzed; they never
//! panic and never allocate more than the input size justifies.

use std::fmt::Write as _;
use std::path::Path;

use crate::error::{DataError, FormatError, Result};
use crate::fsutil::{read_bytes, read_text};
use gems_math::{Intrinsics, Pose};

/// COLMAP camera models (ids 0–10 of COLMAP's model registry).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum CameraModel {
    /// `f, cx, cy`
    SimplePinhole,
    /// `fx, fy, cx, cy`
    Pinhole,
    /// `f, cx, cy, k`
    SimpleRadial,
    /// `f, cx, cy, k1, k2`
    Radial,
    /// `fx, fy, cx, cy, k1, k2, p1, p2`
    Opencv,
    /// `fx, fy, cx, cy, k1, k2, k3, k4`
    OpencvFisheye,
    /// `fx, fy, cx, cy, k1, k2, p1, p2, k3, k4, k5, k6`
    FullOpencv,
    /// `fx, fy, cx, cy, omega`
    Fov,
    /// `f, cx, cy, k`
    SimpleRadialFisheye,
    /// `f, cx, cy, k1, k2`
    RadialFisheye,
    /// `fx, fy, cx, cy, k1, k2, p1, p2, k3, k4, sx1, sy1`
    ThinPrismFisheye,
}

const MODELS: [(CameraModel, &str, usize); 11] = [
    (CameraModel::SimplePinhole, "SIMPLE_PINHOLE", 3),
    (CameraModel::Pinhole, "PINHOLE", 4),
    (CameraModel::SimpleRadial, "SIMPLE_RADIAL", 4),
    (CameraModel::Radial, "RADIAL", 5),
    (CameraModel::Opencv, "OPENCV", 8),
    (CameraModel::OpencvFisheye, "OPENCV_FISHEYE", 8),
    (CameraModel::FullOpencv, "FULL_OPENCV", 12),
    (CameraModel::Fov, "FOV", 5),
    (CameraModel::SimpleRadialFisheye, "SIMPLE_RADIAL_FISHEYE", 4),
    (CameraModel::RadialFisheye, "RADIAL_FISHEYE", 5),
    (CameraModel::ThinPrismFisheye, "THIN_PRISM_FISHEYE", 12),
];

impl CameraModel {
    /// COLMAP's numeric model id.
    pub fn id(self) -> i32 {
        MODELS.iter().position(|m| m.0 == self).unwrap_or(0) as i32
    }
    /// Model from COLMAP's numeric id.
    pub fn from_id(id: i32) -> Option<CameraModel> {
        usize::try_from(id)
            .ok()
            .and_then(|i| MODELS.get(i))
            .map(|m| m.0)
    }
    /// COLMAP's model name, e.g. `"PINHOLE"`.
    pub fn name(self) -> &'static str {
        MODELS[self.id() as usize].1
    }
    /// Model from its COLMAP name.
    pub fn from_name(name: &str) -> Option<CameraModel> {
        MODELS.iter().find(|m| m.1 == name).map(|m| m.0)
    }
    /// Number of parameters COLMAP stores for this model.
    pub fn num_params(self) -> usize {
        MODELS[self.id() as usize].2
    }
}

/// One COLMAP camera.
#[derive(Debug, Clone, PartialEq)]
pub struct Camera {
    /// COLMAP camera id (not necessarily consecutive or 1-based).
    pub id: u32,
    /// Camera model.
    pub model: CameraModel,
    /// Image width the calibration refers to.
    pub width: u64,
    /// Image height the calibration refers to.
    pub height: u64,
    /// Model parameters in COLMAP's order (length = `model.num_params()`).
    pub params: Vec<f64>,
}

impl Camera {
    /// Pinhole intrinsics of this camera. Models with distortion terms are accepted only when
    /// every distortion term is exactly zero; otherwise the images would first need undistorting,
    /// which gems does not do, so this returns an explanatory error message.
    pub fn intrinsics(&self) -> std::result::Result<Intrinsics, String> {
        let p = &self.params;
        if p.len() != self.model.num_params() {
            return Err(format!(
                "camera {} ({}) has {} parameters, the model needs {}",
                self.id,
                self.model.name(),
                p.len(),
                self.model.num_params()
            ));
        }
        let (fx, fy, cx, cy, dist): (f64, f64, f64, f64, &[f64]) = match self.model {
            CameraModel::SimplePinhole => (p[0], p[0], p[1], p[2], &[]),
            CameraModel::Pinhole => (p[0], p[1], p[2], p[3], &[]),
            CameraModel::SimpleRadial | CameraModel::Radial => (p[0], p[0], p[1], p[2], &p[3..]),
            CameraModel::Opencv => (p[0], p[1], p[2], p[3], &p[4..]),
            other => {
                return Err(format!(
                    "camera {} uses model {}; gems handles SIMPLE_PINHOLE, PINHOLE, SIMPLE_RADIAL, \
                     RADIAL and OPENCV (undistort the images to PINHOLE first, e.g. with \
                     `colmap image_undistorter`)",
                    self.id,
                    other.name()
                ));
            }
        };
        if dist.iter().any(|&d| d != 0.0) {
            return Err(format!(
                "camera {} ({}) has non-zero distortion {:?}; gems needs undistorted images \
                 (run `colmap image_undistorter` and use its PINHOLE model)",
                self.id,
                self.model.name(),
                dist
            ));
        }
        let (width, height) = match (u32::try_from(self.width), u32::try_from(self.height)) {
            (Ok(w), Ok(h)) if w > 0 && h > 0 => (w, h),
            _ => {
                return Err(format!(
                    "camera {} has invalid size {}x{}",
                    self.id, self.width, self.height
                ));
            }
        };
        if ![fx, fy, cx, cy].iter().all(|v| v.is_finite()) || fx <= 0.0 || fy <= 0.0 {
            return Err(format!(
                "camera {} has invalid focal/principal point {:?}",
                self.id, p
            ));
        }
        Ok(Intrinsics {
            fx,
            fy,
            cx,
            cy,
            width,
            height,
        })
    }
}

/// A 2D observation in an image; `point3d_id == u64::MAX` means "no 3D point" (text: `-1`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Point2D {
    /// Pixel x (top-left corner of the image is 0).
    pub x: f64,
    /// Pixel y.
    pub y: f64,
    /// Id of the triangulated point, or [`INVALID_POINT3D_ID`].
    pub point3d_id: u64,
}

/// COLMAP's "no 3D point" marker.
pub const INVALID_POINT3D_ID: u64 = u64::MAX;

/// One registered image.
#[derive(Debug, Clone, PartialEq)]
pub struct Image {
    /// COLMAP image id.
    pub id: u32,
    /// Rotation of cam_from_world as stored: Hamilton quaternion `[w, x, y, z]`.
    pub qvec: [f64; 4],
    /// Translation of cam_from_world.
    pub tvec: [f64; 3],
    /// Camera id of this image.
    pub camera_id: u32,
    /// Image file name relative to the image folder.
    pub name: String,
    /// 2D keypoints with their (optional) 3D point ids.
    pub points2d: Vec<Point2D>,
}

impl Image {
    /// World-to-camera pose (OpenCV axes) of this image.
    pub fn pose(&self) -> Pose {
        Pose::from_quaternion(self.qvec, self.tvec)
    }
    /// Builds an image record from a gems pose (the quaternion is taken with `w >= 0`).
    pub fn from_pose(id: u32, camera_id: u32, name: &str, pose: &Pose) -> Image {
        Image {
            id,
            qvec: pose.quaternion(),
            tvec: pose.translation,
            camera_id,
            name: name.to_owned(),
            points2d: Vec::new(),
        }
    }
}

/// One 3D point with colour and track.
#[derive(Debug, Clone, PartialEq)]
pub struct Point3D {
    /// COLMAP point id.
    pub id: u64,
    /// World position.
    pub xyz: [f64; 3],
    /// Colour, sRGB 8-bit.
    pub rgb: [u8; 3],
    /// Mean reprojection error in pixels (−1 when unknown).
    pub error: f64,
    /// Observations as `(image_id, point2d_idx)`.
    pub track: Vec<(u32, u32)>,
}

/// A COLMAP sparse model; records in file order.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct SparseModel {
    /// Cameras.
    pub cameras: Vec<Camera>,
    /// Registered images.
    pub images: Vec<Image>,
    /// Triangulated points.
    pub points: Vec<Point3D>,
}

impl SparseModel {
    /// The camera with this id.
    pub fn camera(&self, id: u32) -> Option<&Camera> {
        self.cameras.iter().find(|c| c.id == id)
    }
    /// The image with this file name.
    pub fn image_by_name(&self, name: &str) -> Option<&Image> {
        self.images.iter().find(|i| i.name == name)
    }

    /// Renames this model's images to the scene's view `names` they stand for, so that
    /// [`SparseModel::image_by_name`] finds each view by its own name, and says how they were
    /// matched. A model made on other copies of the photos names them differently: Deblur-NeRF's
    /// real scenes ship a `sparse/0` made on the PNG `images_4/` beside JPG `images/`. The rules,
    /// in order (the one `images_<f>/` folders follow): the exact file name; the file stem
    /// (`000.png` ↔ `000.jpg`); when the model has as many images as there are views and the
    /// pairing contradicts no match found by name or stem, the sorted order of both. The first
    /// rule that matches every view is taken, else the one that matches most. Images no view
    /// matches keep their names.
    pub fn key_by_view_names(&mut self, names: &[String]) -> NameMatch {
        let exact = self.match_by(names, |n| n.to_owned());
        let by_stem = self.match_by(names, |n| file_stem(n).to_owned());
        let complete = |m: &[Option<usize>]| m.iter().all(Option::is_some);
        let count = |m: &[Option<usize>]| m.iter().flatten().count();
        let (rule, pairs) = if complete(&exact) {
            (NameRule::Exact, exact)
        } else if complete(&by_stem) {
            (NameRule::Stem, by_stem)
        } else if let Some(sorted) = self
            .match_in_sorted_order(names)
            .filter(|s| agrees(s, &exact) && agrees(s, &by_stem))
        {
            (NameRule::SortedOrder, sorted)
        } else if count(&by_stem) > count(&exact) {
            (NameRule::Stem, by_stem)
        } else {
            (NameRule::Exact, exact)
        };
        for (name, image) in names.iter().zip(&pairs) {
            if let Some(i) = image {
                self.images[*i].name.clone_from(name);
            }
        }
        NameMatch {
            rule,
            matched: count(&pairs),
            views: names.len(),
            model_images: self.images.len(),
        }
    }

    /// For each name, the index of the one image whose `key(image name)` equals `key(name)`
    /// (`None` when no image or several share that key).
    fn match_by(&self, names: &[String], key: impl Fn(&str) -> String) -> Vec<Option<usize>> {
        let mut by_key: std::collections::HashMap<String, Option<usize>> = Default::default();
        for (i, img) in self.images.iter().enumerate() {
            by_key
                .entry(key(&img.name))
                .and_modify(|e| *e = None)
                .or_insert(Some(i));
        }
        names
            .iter()
            .map(|n| by_key.get(&key(n)).copied().flatten())
            .collect()
    }

    /// Each name paired with the image of the same rank when both are sorted by name; `None`
    /// when the counts differ.
    fn match_in_sorted_order(&self, names: &[String]) -> Option<Vec<Option<usize>>> {
        if names.len() != self.images.len() {
            return None;
        }
        let mut images: Vec<usize> = (0..self.images.len()).collect();
        images.sort_by(|&a, &b| self.images[a].name.cmp(&self.images[b].name));
        let mut views: Vec<usize> = (0..names.len()).collect();
        views.sort_by(|&a, &b| names[a].cmp(&names[b]));
        let mut pairs = vec![None; names.len()];
        for (v, i) in views.into_iter().zip(images) {
            pairs[v] = Some(i);
        }
        Some(pairs)
    }
}

/// Whether every pair `partial` found is also in `full`.
fn agrees(full: &[Option<usize>], partial: &[Option<usize>]) -> bool {
    full.iter().zip(partial).all(|(f, p)| p.is_none() || f == p)
}

/// `000.png` → `000`; a name without an extension is its own stem.
fn file_stem(name: &str) -> &str {
    Path::new(name)
        .file_stem()
        .and_then(|s| s.to_str())
        .unwrap_or(name)
}

/// How a model's images were matched to a scene's views ([`SparseModel::key_by_view_names`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum NameRule {
    /// Same file names.
    Exact,
    /// Same file stems, other extensions.
    Stem,
    /// Both sorted by name and paired by rank.
    SortedOrder,
}

impl NameRule {
    /// Human-readable name, as `gems info` prints it.
    pub fn describe(self) -> &'static str {
        match self {
            NameRule::Exact => "by file name",
            NameRule::Stem => "by file stem (other extension)",
            NameRule::SortedOrder => "by sorted order (names differ, counts agree)",
        }
    }
}

/// The outcome of [`SparseModel::key_by_view_names`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub struct NameMatch {
    /// The rule taken.
    pub rule: NameRule,
    /// Views that got a model image.
    pub matched: usize,
    /// Views in the scene.
    pub views: usize,
    /// Images in the model.
    pub model_images: usize,
}

/// On-disk flavour of a COLMAP model.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ModelFormat {
    /// `cameras.bin`, `images.bin`, `points3D.bin`.
    Binary,
    /// `cameras.txt`, `images.txt`, `points3D.txt`.
    Text,
}

impl ModelFormat {
    fn ext(self) -> &'static str {
        match self {
            ModelFormat::Binary => "bin",
            ModelFormat::Text => "txt",
        }
    }
}

/// Which format the model in `dir` uses (binary preferred when both exist), or `None`.
pub fn detect_format(dir: &Path) -> Option<ModelFormat> {
    [ModelFormat::Binary, ModelFormat::Text]
        .into_iter()
        .find(|f| dir.join(format!("cameras.{}", f.ext())).is_file())
}

/// Reads the model in `dir` (binary if `cameras.bin` exists, else text) and checks it:
/// unique ids, every image's camera exists, finite poses and points, track references valid.
pub fn read_model(dir: &Path) -> Result<SparseModel> {
    let format = detect_format(dir).ok_or_else(|| DataError::Missing {
        path: dir.to_path_buf(),
        what: "a COLMAP model (cameras.bin or cameras.txt)".into(),
    })?;
    let path = |stem: &str| dir.join(format!("{stem}.{}", format.ext()));
    let (cams_p, imgs_p, pts_p) = (path("cameras"), path("images"), path("points3D"));
    for p in [&imgs_p, &pts_p] {
        if !p.is_file() {
            return Err(DataError::Missing {
                path: p.clone(),
                what: "file of the COLMAP model".into(),
            });
        }
    }
    let model = match format {
        ModelFormat::Binary => SparseModel {
            cameras: parse_cameras_bin(&read_bytes(&cams_p)?).map_err(wrap(&cams_p))?,
            images: parse_images_bin(&read_bytes(&imgs_p)?).map_err(wrap(&imgs_p))?,
            points: parse_points3d_bin(&read_bytes(&pts_p)?).map_err(wrap(&pts_p))?,
        },
        ModelFormat::Text => SparseModel {
            cameras: parse_cameras_txt(&read_text(&cams_p)?).map_err(wrap(&cams_p))?,
            images: parse_images_txt(&read_text(&imgs_p)?).map_err(wrap(&imgs_p))?,
            points: parse_points3d_txt(&read_text(&pts_p)?).map_err(wrap(&pts_p))?,
        },
    };
    validate(&model, &cams_p, &imgs_p, &pts_p)?;
    tracing::debug!(
        dir = %dir.display(),
        cameras = model.cameras.len(),
        images = model.images.len(),
        points = model.points.len(),
        "read COLMAP model"
    );
    Ok(model)
}

fn wrap(p: &Path) -> impl Fn(FormatError) -> DataError + '_ {
    move |e| DataError::from_format(p, e)
}

fn validate(m: &SparseModel, cams_p: &Path, imgs_p: &Path, pts_p: &Path) -> Result<()> {
    let mut cam_ids: Vec<u32> = m.cameras.iter().map(|c| c.id).collect();
    cam_ids.sort_unstable();
    if let Some(w) = cam_ids.windows(2).find(|w| w[0] == w[1]) {
        return Err(DataError::format(
            cams_p,
            format!("duplicate camera id {}", w[0]),
        ));
    }
    let mut img_ids: Vec<(u32, usize)> =
        m.images.iter().map(|i| (i.id, i.points2d.len())).collect();
    img_ids.sort_unstable();
    if let Some(w) = img_ids.windows(2).find(|w| w[0].0 == w[1].0) {
        return Err(DataError::format(
            imgs_p,
            format!("duplicate image id {}", w[0].0),
        ));
    }
    for img in &m.images {
        if cam_ids.binary_search(&img.camera_id).is_err() {
            return Err(DataError::format(
                imgs_p,
                format!(
                    "image {} ({}) refers to camera {} which is not in the model",
                    img.id, img.name, img.camera_id
                ),
            ));
        }
        let qn: f64 = img.qvec.iter().map(|v| v * v).sum::<f64>();
        if !img.qvec.iter().chain(&img.tvec).all(|v| v.is_finite()) || qn < 1e-12 {
            return Err(DataError::format(
                imgs_p,
                format!(
                    "image {} ({}) has an invalid pose q={:?} t={:?}",
                    img.id, img.name, img.qvec, img.tvec
                ),
            ));
        }
    }
    for p in &m.points {
        if !p.xyz.iter().all(|v| v.is_finite()) {
            return Err(DataError::format(
                pts_p,
                format!("point {} has a non-finite position {:?}", p.id, p.xyz),
            ));
        }
        for &(iid, idx) in &p.track {
            // Models saved without keypoints (empty POINTS2D) cannot be cross-checked.
            match img_ids.binary_search_by_key(&iid, |e| e.0) {
                Ok(k) if (idx as usize) < img_ids[k].1 || img_ids[k].1 == 0 => {}
                Ok(_) => {
                    return Err(DataError::format(
                        pts_p,
                        format!(
                            "point {} observes keypoint {idx} of image {iid}, which has fewer keypoints",
                            p.id
                        ),
                    ));
                }
                Err(_) => {
                    return Err(DataError::format(
                        pts_p,
                        format!(
                            "point {} observes image {iid}, which is not in the model",
                            p.id
                        ),
                    ));
                }
            }
        }
    }
    Ok(())
}

/// Writes `model` into `dir` (created if needed) in the given format; each file is written
/// atomically.
pub fn write_model(dir: &Path, model: &SparseModel, format: ModelFormat) -> Result<()> {
    let (c, i, p) = match format {
        ModelFormat::Binary => (
            cameras_to_bin(&model.cameras),
            images_to_bin(&model.images),
            points3d_to_bin(&model.points),
        ),
        ModelFormat::Text => (
            cameras_to_txt(&model.cameras).into_bytes(),
            images_to_txt(&model.images).into_bytes(),
            points3d_to_txt(&model.points).into_bytes(),
        ),
    };
    let ext = format.ext();
    gems_fs::write_atomic(&dir.join(format!("cameras.{ext}")), &c)?;
    gems_fs::write_atomic(&dir.join(format!("images.{ext}")), &i)?;
    gems_fs::write_atomic(&dir.join(format!("points3D.{ext}")), &p)?;
    Ok(())
}

// ---------------------------------------------------------------------------------------------
// Binary

/// Little-endian cursor over untrusted bytes; every read is bounds-checked.
struct Cursor<'a> {
    bytes: &'a [u8],
    pos: usize,
    what: &'static str,
}

impl<'a> Cursor<'a> {
    fn new(bytes: &'a [u8], what: &'static str) -> Self {
        Cursor {
            bytes,
            pos: 0,
            what,
        }
    }
    fn take(&mut self, n: usize) -> std::result::Result<&'a [u8], FormatError> {
        if self.bytes.len() - self.pos < n {
            return Err(FormatError::new(format!(
                "truncated {} file: needed {n} more bytes at offset {} but the file has {}",
                self.what,
                self.pos,
                self.bytes.len()
            )));
        }
        let s = &self.bytes[self.pos..self.pos + n];
        self.pos += n;
        Ok(s)
    }
    fn arr<const N: usize>(&mut self) -> std::result::Result<[u8; N], FormatError> {
        let mut a = [0u8; N];
        a.copy_from_slice(self.take(N)?);
        Ok(a)
    }
    fn u8(&mut self) -> std::result::Result<u8, FormatError> {
        Ok(self.arr::<1>()?[0])
    }
    fn u32(&mut self) -> std::result::Result<u32, FormatError> {
        Ok(u32::from_le_bytes(self.arr()?))
    }
    fn i32(&mut self) -> std::result::Result<i32, FormatError> {
        Ok(i32::from_le_bytes(self.arr()?))
    }
    fn u64(&mut self) -> std::result::Result<u64, FormatError> {
        Ok(u64::from_le_bytes(self.arr()?))
    }
    fn f64(&mut self) -> std::result::Result<f64, FormatError> {
        Ok(f64::from_le_bytes(self.arr()?))
    }
    fn remaining(&self) -> usize {
        self.bytes.len() - self.pos
    }
    /// A record count, rejected if even `min_record` bytes per record cannot fit in the rest of
    /// the file (so a corrupt count cannot trigger a huge allocation).
    fn count(&mut self, min_record: usize) -> std::result::Result<usize, FormatError> {
        let n = self.u64()?;
        let fits = usize::try_from(n)
            .ok()
            .and_then(|n| n.checked_mul(min_record))
            .is_some_and(|b| b <= self.remaining());
        if !fits {
            return Err(FormatError::new(format!(
                "{} file declares {n} records of at least {min_record} bytes but only {} bytes follow (truncated or corrupt)",
                self.what,
                self.remaining()
            )));
        }
        Ok(n as usize)
    }
    fn finish(&self) -> std::result::Result<(), FormatError> {
        if self.remaining() != 0 {
            return Err(FormatError::new(format!(
                "{} file has {} unexpected trailing bytes",
                self.what,
                self.remaining()
            )));
        }
        Ok(())
    }
}

/// Parses `cameras.bin`.
pub fn parse_cameras_bin(bytes: &[u8]) -> std::result::Result<Vec<Camera>, FormatError> {
    let mut c = Cursor::new(bytes, "cameras.bin");
    let n = c.count(4 + 4 + 8 + 8)?;
    let mut cams = Vec::with_capacity(n);
    for _ in 0..n {
        let id = c.u32()?;
        let model_id = c.i32()?;
        let model = CameraModel::from_id(model_id).ok_or_else(|| {
            FormatError::new(format!("camera {id}: unknown camera model id {model_id}"))
        })?;
        let width = c.u64()?;
        let height = c.u64()?;
        let params = (0..model.num_params())
            .map(|_| c.f64())
            .collect::<std::result::Result<_, _>>()?;
        cams.push(Camera {
            id,
            model,
            width,
            height,
            params,
        });
    }
    c.finish()?;
    Ok(cams)
}

/// Parses `images.bin`.
pub fn parse_images_bin(bytes: &[u8]) -> std::result::Result<Vec<Image>, FormatError> {
    let mut c = Cursor::new(bytes, "images.bin");
    let n = c.count(4 + 7 * 8 + 4 + 1 + 8)?;
    let mut images = Vec::with_capacity(n);
    for _ in 0..n {
        let id = c.u32()?;
        let qvec = [c.f64()?, c.f64()?, c.f64()?, c.f64()?];
        let tvec = [c.f64()?, c.f64()?, c.f64()?];
        let camera_id = c.u32()?;
        let rest = &c.bytes[c.pos..];
        let len = rest.iter().position(|&b| b == 0).ok_or_else(|| {
            FormatError::new(format!(
                "truncated images.bin: name of image {id} has no terminating NUL"
            ))
        })?;
        let name = std::str::from_utf8(c.take(len)?)
            .map_err(|_| FormatError::new(format!("image {id}: name is not UTF-8")))?
            .to_owned();
        c.take(1)?;
        let np = c.count(24)?;
        let mut points2d = Vec::with_capacity(np);
        for _ in 0..np {
            points2d.push(Point2D {
                x: c.f64()?,
                y: c.f64()?,
                point3d_id: c.u64()?,
            });
        }
        images.push(Image {
            id,
            qvec,
            tvec,
            camera_id,
            name,
            points2d,
        });
    }
    c.finish()?;
    Ok(images)
}

/// Parses `points3D.bin`.
pub fn parse_points3d_bin(bytes: &[u8]) -> std::result::Result<Vec<Point3D>, FormatError> {
    let mut c = Cursor::new(bytes, "points3D.bin");
    let n = c.count(8 + 24 + 3 + 8 + 8)?;
    let mut points = Vec::with_capacity(n);
    for _ in 0..n {
        let id = c.u64()?;
        let xyz = [c.f64()?, c.f64()?, c.f64()?];
        let rgb = [c.u8()?, c.u8()?, c.u8()?];
        let error = c.f64()?;
        let nt = c.count(8)?;
        let mut track = Vec::with_capacity(nt);
        for _ in 0..nt {
            track.push((c.u32()?, c.u32()?));
        }
        points.push(Point3D {
            id,
            xyz,
            rgb,
            error,
            track,
        });
    }
    c.finish()?;
    Ok(points)
}

/// Serialises cameras in COLMAP's binary layout.
pub fn cameras_to_bin(cams: &[Camera]) -> Vec<u8> {
    let mut b = Vec::with_capacity(8 + cams.len() * 72);
    b.extend_from_slice(&(cams.len() as u64).to_le_bytes());
    for cam in cams {
        b.extend_from_slice(&cam.id.to_le_bytes());
        b.extend_from_slice(&cam.model.id().to_le_bytes());
        b.extend_from_slice(&cam.width.to_le_bytes());
        b.extend_from_slice(&cam.height.to_le_bytes());
        for p in &cam.params {
            b.extend_from_slice(&p.to_le_bytes());
        }
    }
    b
}

/// Serialises images in COLMAP's binary layout.
pub fn images_to_bin(images: &[Image]) -> Vec<u8> {
    let mut b = Vec::new();
    b.extend_from_slice(&(images.len() as u64).to_le_bytes());
    for img in images {
        b.extend_from_slice(&img.id.to_le_bytes());
        for v in img.qvec.iter().chain(&img.tvec) {
            b.extend_from_slice(&v.to_le_bytes());
        }
        b.extend_from_slice(&img.camera_id.to_le_bytes());
        b.extend_from_slice(img.name.as_bytes());
        b.push(0);
        b.extend_from_slice(&(img.points2d.len() as u64).to_le_bytes());
        for p in &img.points2d {
            b.extend_from_slice(&p.x.to_le_bytes());
            b.extend_from_slice(&p.y.to_le_bytes());
            b.extend_from_slice(&p.point3d_id.to_le_bytes());
        }
    }
    b
}

/// Serialises points in COLMAP's binary layout.
pub fn points3d_to_bin(points: &[Point3D]) -> Vec<u8> {
    let mut b = Vec::new();
    b.extend_from_slice(&(points.len() as u64).to_le_bytes());
    for p in points {
        b.extend_from_slice(&p.id.to_le_bytes());
        for v in &p.xyz {
            b.extend_from_slice(&v.to_le_bytes());
        }
        b.extend_from_slice(&p.rgb);
        b.extend_from_slice(&p.error.to_le_bytes());
        b.extend_from_slice(&(p.track.len() as u64).to_le_bytes());
        for (i, k) in &p.track {
            b.extend_from_slice(&i.to_le_bytes());
            b.extend_from_slice(&k.to_le_bytes());
        }
    }
    b
}

// ---------------------------------------------------------------------------------------------
// Text

/// Data lines of a COLMAP text file with their 1-based line numbers; `#` comments skipped.
/// Blank lines are kept only when `keep_blank` (images.txt's points2D line may be empty).
fn data_lines(text: &str, keep_blank: bool) -> impl Iterator<Item = (usize, &str)> {
    text.lines()
        .enumerate()
        .map(|(i, l)| (i + 1, l.trim_end_matches('\r')))
        .filter(move |(_, l)| {
            !l.trim_start().starts_with('#') && (keep_blank || !l.trim().is_empty())
        })
}

fn parse_num<T: std::str::FromStr>(
    tok: Option<&str>,
    line: usize,
    what: &str,
) -> std::result::Result<T, FormatError> {
    let tok = tok.ok_or_else(|| FormatError::new(format!("line {line}: missing {what}")))?;
    tok.parse()
        .map_err(|_| FormatError::new(format!("line {line}: invalid {what} {tok:?}")))
}

/// Parses `cameras.txt`.
pub fn parse_cameras_txt(text: &str) -> std::result::Result<Vec<Camera>, FormatError> {
    let mut cams = Vec::new();
    for (ln, line) in data_lines(text, false) {
        let mut t = line.split_whitespace();
        let id = parse_num(t.next(), ln, "camera id")?;
        let model_name = t
            .next()
            .ok_or_else(|| FormatError::new(format!("line {ln}: missing camera model")))?;
        let model = CameraModel::from_name(model_name).ok_or_else(|| {
            FormatError::new(format!("line {ln}: unknown camera model {model_name:?}"))
        })?;
        let width = parse_num(t.next(), ln, "width")?;
        let height = parse_num(t.next(), ln, "height")?;
        let params: Vec<f64> = t
            .map(|tok| parse_num(Some(tok), ln, "camera parameter"))
            .collect::<std::result::Result<_, _>>()?;
        if params.len() != model.num_params() {
            return Err(FormatError::new(format!(
                "line {ln}: model {model_name} needs {} parameters, found {}",
                model.num_params(),
                params.len()
            )));
        }
        cams.push(Camera {
            id,
            model,
            width,
            height,
            params,
        });
    }
    Ok(cams)
}

/// Parses `images.txt` (two lines per image; the name is the rest of the pose line, so names may
/// contain spaces).
pub fn parse_images_txt(text: &str) -> std::result::Result<Vec<Image>, FormatError> {
    let mut images = Vec::new();
    let mut lines = data_lines(text, true).peekable();
    loop {
        // Skip blank lines between records, but not the (possibly blank) points2D line.
        while lines.peek().is_some_and(|(_, l)| l.trim().is_empty()) {
            lines.next();
        }
        let Some((ln, line)) = lines.next() else {
            break;
        };
        let mut rest = line.trim_start();
        let mut toks = [""; 9];
        for tok in &mut toks {
            let end = rest.find(char::is_whitespace).unwrap_or(rest.len());
            *tok = &rest[..end];
            rest = rest[end..].trim_start();
        }
        let name = rest.trim_end();
        if name.is_empty() {
            return Err(FormatError::new(format!(
                "line {ln}: image line needs IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME"
            )));
        }
        let id = parse_num(Some(toks[0]), ln, "image id")?;
        let mut v = [0f64; 7];
        for (k, slot) in v.iter_mut().enumerate() {
            *slot = parse_num(Some(toks[1 + k]), ln, "pose value")?;
        }
        let camera_id = parse_num(Some(toks[8]), ln, "camera id")?;
        let (pln, pline) = lines.next().ok_or_else(|| {
            FormatError::new(format!(
                "line {ln}: image {id} has no POINTS2D line (it must be present, possibly empty)"
            ))
        })?;
        let toks: Vec<&str> = pline.split_whitespace().collect();
        if !toks.len().is_multiple_of(3) {
            return Err(FormatError::new(format!(
                "line {pln}: POINTS2D needs triples X Y POINT3D_ID, found {} values",
                toks.len()
            )));
        }
        let points2d = toks
            .chunks_exact(3)
            .map(|c| {
                let pid: i64 = parse_num(Some(c[2]), pln, "point3D id")?;
                Ok(Point2D {
                    x: parse_num(Some(c[0]), pln, "x")?,
                    y: parse_num(Some(c[1]), pln, "y")?,
                    point3d_id: if pid < 0 {
                        INVALID_POINT3D_ID
                    } else {
                        pid as u64
                    },
                })
            })
            .collect::<std::result::Result<_, FormatError>>()?;
        images.push(Image {
            id,
            qvec: [v[0], v[1], v[2], v[3]],
            tvec: [v[4], v[5], v[6]],
            camera_id,
            name: name.to_owned(),
            points2d,
        });
    }
    Ok(images)
}

/// Parses `points3D.txt`.
pub fn parse_points3d_txt(text: &str) -> std::result::Result<Vec<Point3D>, FormatError> {
    let mut points = Vec::new();
    for (ln, line) in data_lines(text, false) {
        let mut t = line.split_whitespace();
        let id = parse_num(t.next(), ln, "point id")?;
        let xyz = [
            parse_num(t.next(), ln, "x")?,
            parse_num(t.next(), ln, "y")?,
            parse_num(t.next(), ln, "z")?,
        ];
        let rgb = [
            parse_num(t.next(), ln, "r")?,
            parse_num(t.next(), ln, "g")?,
            parse_num(t.next(), ln, "b")?,
        ];
        let error = parse_num(t.next(), ln, "error")?;
        let rest: Vec<&str> = t.collect();
        if !rest.len().is_multiple_of(2) {
            return Err(FormatError::new(format!(
                "line {ln}: TRACK needs pairs IMAGE_ID POINT2D_IDX"
            )));
        }
        let track = rest
            .chunks_exact(2)
            .map(|c| {
                Ok((
                    parse_num(Some(c[0]), ln, "track image id")?,
                    parse_num(Some(c[1]), ln, "track point2D index")?,
                ))
            })
            .collect::<std::result::Result<_, FormatError>>()?;
        points.push(Point3D {
            id,
            xyz,
            rgb,
            error,
            track,
        });
    }
    Ok(points)
}

/// Serialises cameras as `cameras.txt` (shortest round-trip float formatting).
pub fn cameras_to_txt(cams: &[Camera]) -> String {
    let mut s = String::from(
        "# Camera list with one line of data per camera:\n#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n",
    );
    let _ = writeln!(s, "# Number of cameras: {}", cams.len());
    for c in cams {
        let _ = write!(s, "{} {} {} {}", c.id, c.model.name(), c.width, c.height);
        for p in &c.params {
            let _ = write!(s, " {p:?}");
        }
        s.push('\n');
    }
    s
}

/// Serialises images as `images.txt`.
pub fn images_to_txt(images: &[Image]) -> String {
    let total: usize = images.iter().map(|i| i.points2d.len()).sum();
    let mean = if images.is_empty() {
        0.0
    } else {
        total as f64 / images.len() as f64
    };
    let mut s = String::from(
        "# Image list with two lines of data per image:\n#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME\n#   POINTS2D[] as (X, Y, POINT3D_ID)\n",
    );
    let _ = writeln!(
        s,
        "# Number of images: {}, mean observations per image: {mean}",
        images.len()
    );
    for i in images {
        let _ = write!(s, "{}", i.id);
        for v in i.qvec.iter().chain(&i.tvec) {
            let _ = write!(s, " {v:?}");
        }
        let _ = writeln!(s, " {} {}", i.camera_id, i.name);
        let mut first = true;
        for p in &i.points2d {
            if !first {
                s.push(' ');
            }
            first = false;
            if p.point3d_id == INVALID_POINT3D_ID {
                let _ = write!(s, "{:?} {:?} -1", p.x, p.y);
            } else {
                let _ = write!(s, "{:?} {:?} {}", p.x, p.y, p.point3d_id);
            }
        }
        s.push('\n');
    }
    s
}

/// Serialises points as `points3D.txt`.
pub fn points3d_to_txt(points: &[Point3D]) -> String {
    let total: usize = points.iter().map(|p| p.track.len()).sum();
    let mean = if points.is_empty() {
        0.0
    } else {
        total as f64 / points.len() as f64
    };
    let mut s = String::from(
        "# 3D point list with one line of data per point:\n#   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)\n",
    );
    let _ = writeln!(
        s,
        "# Number of points: {}, mean track length: {mean}",
        points.len()
    );
    for p in points {
        let _ = write!(
            s,
            "{} {:?} {:?} {:?} {} {} {} {:?}",
            p.id, p.xyz[0], p.xyz[1], p.xyz[2], p.rgb[0], p.rgb[1], p.rgb[2], p.error
        );
        for (i, k) in &p.track {
            let _ = write!(s, " {i} {k}");
        }
        s.push('\n');
    }
    s
}

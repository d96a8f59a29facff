//! Full validation of an opened scene: what `gems info --check` prints and what `gems train`
//! runs before any long work.
//!
//! [`open_scene`](crate::open_scene) already parses the pose files and the SfM model in full and
//! reads image headers; [`check_scene`] adds everything that needs the whole data: it decodes every
//! image and sharp ground truth, checks sizes against the headers and each other, poses and
//! intrinsics for finiteness, reads the event stream (or bin tensor) in full, checks that every
//! event lies inside the sensor (the full-resolution image) and that every non-empty exposure window
//! holds events. Each problem is one [`Problem`] naming its file.

use std::fmt;
use std::path::{Path, PathBuf};

use rayon::prelude::*;

use crate::image::{image_dimensions, load_image};
use crate::scene::{Scene, View};
use gems_math::Pose;

/// One thing wrong with a scene.
#[derive(Debug, Clone, PartialEq)]
pub struct Problem {
    /// The file (or folder) at fault.
    pub path: PathBuf,
    /// What is wrong.
    pub msg: String,
}

impl fmt::Display for Problem {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}: {}", self.path.display(), self.msg)
    }
}

fn problem(path: &Path, msg: impl Into<String>) -> Problem {
    Problem {
        path: path.to_path_buf(),
        msg: msg.into(),
    }
}

fn pose_finite(p: &Pose) -> bool {
    p.is_finite()
}

/// Whether `path` is a JPEG cut short: a complete one ends with the end-of-image marker FF D9
/// (ITU-T T.81 B.2.1), which JPEG decoders do not insist on.
fn truncated_jpeg(path: &Path) -> bool {
    let is_jpeg = path
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| matches!(e.to_ascii_lowercase().as_str(), "jpg" | "jpeg"));
    is_jpeg
        && std::fs::read(path).is_ok_and(|b| {
            // Some writers pad after the marker; look at the last few bytes.
            let tail = &b[b.len().saturating_sub(16)..];
            !tail.windows(2).any(|w| w == [0xFF, 0xD9])
        })
}

/// Decodes `path` in full and checks it is `want` pixels.
fn check_image(path: &Path, want: (u32, u32), what: &str) -> Option<Problem> {
    if truncated_jpeg(path) {
        return Some(problem(
            path,
            format!("{what} is truncated (JPEG without its end-of-image marker)"),
        ));
    }
    match load_image(path) {
        Err(e) => Some(problem(
            path,
            format!("{what} does not decode: {}", inner(&e)),
        )),
        Ok(img) if (img.width, img.height) != want => Some(problem(
            path,
            format!(
                "{what} is {}x{} but {}x{} was expected",
                img.width, img.height, want.0, want.1
            ),
        )),
        Ok(img) if img.data.iter().any(|v| !v.is_finite()) => {
            Some(problem(path, format!("{what} holds non-finite values")))
        }
        Ok(_) => None,
    }
}

/// The message of a data error without its leading path (the problem line names the file).
fn inner(e: &crate::DataError) -> String {
    use std::error::Error;
    e.source().map_or_else(|| e.to_string(), |s| s.to_string())
}

fn check_view(v: &View, original: Option<PathBuf>) -> Vec<Problem> {
    let mut out = Vec::new();
    out.extend(check_image(&v.image, (v.width, v.height), "image"));
    // A view read from a downscaled copy: its full-resolution original must be sound too (the SfM
    // and EXIF read it).
    if let Some(o) = original
        && o != v.image
    {
        match image_dimensions(&o) {
            Ok(d) => out.extend(check_image(&o, d, "full-resolution image")),
            Err(e) => out.push(problem(&o, inner(&e))),
        }
    }
    if let Some(gt) = &v.sharp_gt
        && gt != &v.image
    {
        out.extend(check_image(gt, (v.width, v.height), "sharp ground truth"));
    }
    if let Some(p) = &v.pose
        && !pose_finite(p)
    {
        out.push(problem(
            &v.image,
            "starting pose has NaN or infinite values",
        ));
    }
    if let Some(p) = &v.gt_pose
        && !pose_finite(p)
    {
        out.push(problem(
            &v.image,
            "ground-truth pose has NaN or infinite values",
        ));
    }
    if v.gt_subframe_poses
        .as_ref()
        .is_some_and(|s| !s.iter().all(pose_finite))
    {
        out.push(problem(
            &v.image,
            "a ground-truth sub-frame pose is not finite",
        ));
    }
    if let Some(k) = &v.intrinsics {
        let ok = [k.fx, k.fy, k.cx, k.cy].iter().all(|x| x.is_finite()) && k.fx > 0.0 && k.fy > 0.0;
        if !ok {
            out.push(problem(
                &v.image,
                format!(
                    "intrinsics are not usable: fx {} fy {} cx {} cy {}",
                    k.fx, k.fy, k.cx, k.cy
                ),
            ));
        }
    }
    out
}

/// The full-resolution image size (the event sensor's), from the first view's original file.
fn sensor_size(scene: &Scene) -> Option<(u32, u32)> {
    let v = scene.views.first()?;
    if scene.downscale <= 1 {
        return Some((v.width, v.height));
    }
    [
        scene.root.join("images").join(&v.name),
        scene.root.join(&v.name),
    ]
    .iter()
    .find_map(|p| image_dimensions(p).ok())
}

fn check_events(scene: &Scene) -> Vec<Problem> {
    let mut out = Vec::new();
    let files = &scene.events;
    let sensor = sensor_size(scene);
    if let Some(p) = &files.stream {
        let ext = p
            .extension()
            .map(|e| e.to_string_lossy().to_ascii_lowercase())
            .unwrap_or_default();
        if ext == "pt" {
            out.push(problem(
                p,
                format!(
                    "torch file: gems cannot read it; convert once with: {}",
                    crate::events::PT_TO_NPY_HINT
                ),
            ));
        } else {
            match gems_events::read_events(p, &files.read_options(None)) {
                Err(e) => out.push(problem(p, e.to_string())),
                Ok(ev) => {
                    if let Some((w, h)) = sensor {
                        let mx = ev.x().iter().max().copied().unwrap_or(0);
                        let my = ev.y().iter().max().copied().unwrap_or(0);
                        if !ev.is_empty() && (u32::from(mx) >= w || u32::from(my) >= h) {
                            out.push(problem(
                                p,
                                format!(
                                    "events reach x = {mx}, y = {my}, outside the {w}x{h} sensor \
                                     (the full-resolution images)"
                                ),
                            ));
                        }
                    }
                    for v in &scene.views {
                        let Some(win) = v.exposure else { continue };
                        if win.end > win.start && ev.window(win.start, win.end).is_empty() {
                            out.push(problem(
                                files.exposure_dir.as_deref().unwrap_or(&scene.root),
                                format!(
                                    "view {}: exposure window [{}, {}] µs holds no events (the \
                                     stream spans {:?} µs; wrong time unit? see --time-unit)",
                                    v.name,
                                    win.start,
                                    win.end,
                                    ev.time_span()
                                ),
                            ));
                        }
                    }
                }
            }
        }
    }
    if let Some(p) = &files.bin_counts
        && p.extension().is_some_and(|e| e == "npy")
    {
        match gems_events::read_bin_counts(p, None) {
            Err(e) => out.push(problem(p, e.to_string())),
            Ok(c) => {
                if c.views != scene.views.len() {
                    out.push(problem(
                        p,
                        format!(
                            "{} views of bins but the scene has {}",
                            c.views,
                            scene.views.len()
                        ),
                    ));
                }
                if let Some((w, h)) = sensor
                    && (c.width as u32, c.height as u32) != (w, h)
                {
                    out.push(problem(
                        p,
                        format!(
                            "bins are {}x{} but the images are {w}x{h}",
                            c.width, c.height
                        ),
                    ));
                }
                if c.data.iter().any(|v| !v.is_finite()) {
                    out.push(problem(p, "bin counts hold non-finite values"));
                }
            }
        }
    }
    out
}

/// Every problem of `scene` (empty: the scene is fine), in view order, then events.
pub fn check_scene(scene: &Scene) -> Vec<Problem> {
    let mut out = Vec::new();
    if scene.views.is_empty() {
        out.push(problem(&scene.root, "no views"));
    }
    if scene.train_views().next().is_none() && !scene.views.is_empty() {
        out.push(problem(
            &scene.root,
            "no training views (check the hold= marker)",
        ));
    }
    let per_view: Vec<Vec<Problem>> = scene
        .views
        .par_iter()
        .map(|v| {
            let original = [
                scene.root.join("images").join(&v.name),
                scene.root.join(&v.name),
            ]
            .into_iter()
            .find(|p| p.is_file());
            check_view(v, original)
        })
        .collect();
    out.extend(per_view.into_iter().flatten());
    out.extend(check_events(scene));
    out
}

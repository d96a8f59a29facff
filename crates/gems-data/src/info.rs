//! A serialisable summary of a [`Scene`] (what `gems info` prints), with a human-readable
//! [`Display`](std::fmt::Display).

use std::fmt;
use std::path::{Path, PathBuf};

use serde::Serialize;

use crate::error::{DataError, Result};
use crate::events::PT_TO_NPY_HINT;
use crate::manifest::Manifest;
use crate::scene::{Layout, PoseSource, Scene, Split};
use gems_math::Intrinsics;

/// Summary of a scene. JSON keys `layout`, `views`, `train`, `eval_deblur`, `eval_nvs`, `width`,
/// `height`, `has_gt_poses`, `has_sfm`, `events` are stable.
#[derive(Debug, Clone, Serialize)]
pub struct SceneInfo {
    /// Scene folder.
    pub root: PathBuf,
    /// Detected layout.
    pub layout: Layout,
    /// The dataset the folder looks like.
    pub dataset: String,
    /// Which file is used for what.
    pub uses: Vec<crate::scene::FileUse>,
    /// Where the focal length for the SfM comes from, when the scene has no intrinsics yet.
    pub focal: Option<crate::exif::FocalSource>,
    /// Number of views.
    pub views: usize,
    /// Training views.
    pub train: usize,
    /// Training views with sharp ground truth (deblurring evaluation).
    pub eval_deblur: usize,
    /// Held-out views with sharp ground truth (novel-view evaluation).
    pub eval_nvs: usize,
    /// Image width of the first view (pixels, at `downscale`).
    pub width: Option<u32>,
    /// Image height of the first view.
    pub height: Option<u32>,
    /// Whether all views share that size.
    pub uniform_size: bool,
    /// Downscale factor.
    pub downscale: u32,
    /// Hold-out interval (`null`: none).
    pub hold: Option<i64>,
    /// Intrinsics of the first view with intrinsics.
    pub intrinsics: Option<Intrinsics>,
    /// Whether every view has intrinsics equal to `intrinsics`.
    pub shared_intrinsics: bool,
    /// Where the starting poses come from.
    pub pose_source: PoseSource,
    /// Views with a starting pose.
    pub posed_views: usize,
    /// Whether ground-truth mid-exposure poses exist.
    pub has_gt_poses: bool,
    /// Sub-frames per view of the ground-truth intra-exposure poses (`null`: none).
    pub subframes_per_view: Option<usize>,
    /// Views with ground-truth sub-frame poses.
    pub views_with_subframes: usize,
    /// Views with a sharp ground-truth image.
    pub sharp_gt: usize,
    /// Whether a COLMAP model was found.
    pub has_sfm: bool,
    /// The COLMAP model's size.
    pub sfm: Option<SfmSummary>,
    /// The scene manifest.
    pub manifest: Option<Manifest>,
    /// Event data (`null`: none).
    pub events: Option<EventsSummary>,
    /// Per-view details.
    pub view_list: Vec<ViewSummary>,
}

impl SceneInfo {
    /// Pretty-printed JSON (the machine-readable form of `gems info --json`).
    pub fn to_json_pretty(&self) -> String {
        serde_json::to_string_pretty(self).expect("SceneInfo contains only serialisable data")
    }
}

/// Size of the SfM model.
#[derive(Debug, Clone, Serialize)]
pub struct SfmSummary {
    /// Model folder.
    pub dir: PathBuf,
    /// Cameras.
    pub cameras: usize,
    /// Registered images.
    pub images: usize,
    /// 3D points.
    pub points: usize,
    /// How its images were matched to the views, and how many were.
    pub matched: Option<crate::colmap::NameMatch>,
}

/// What the event files hold.
#[derive(Debug, Clone, Default, Serialize)]
pub struct EventsSummary {
    /// Raw event stream file.
    pub stream: Option<PathBuf>,
    /// Number of events (when the stream was read).
    pub count: Option<usize>,
    /// First and last timestamp, µs.
    pub time_span_us: Option<(i64, i64)>,
    /// Sensor size `(width, height)`.
    pub sensor_size: Option<(u16, u16)>,
    /// Per-view bin-count tensor file.
    pub bin_counts: Option<PathBuf>,
    /// Its shape, from the `.npy` header.
    pub bin_counts_shape: Option<Vec<u64>>,
    /// Per-view exposure windows (µs) and the number of events inside each.
    pub windows: Vec<WindowSummary>,
    /// Things the reader could not do (unsupported formats, with the fix).
    pub notes: Vec<String>,
}

/// One view's exposure window.
#[derive(Debug, Clone, Serialize)]
pub struct WindowSummary {
    /// View name.
    pub view: String,
    /// Exposure start, µs.
    pub start_us: i64,
    /// Exposure end, µs.
    pub end_us: i64,
    /// Events in `[start, end]` (when the stream was read).
    pub events: Option<usize>,
}

/// Per-view summary.
#[derive(Debug, Clone, Serialize)]
pub struct ViewSummary {
    /// File name.
    pub name: String,
    /// Split.
    pub split: Split,
    /// Has a sharp ground truth.
    pub sharp_gt: bool,
    /// Has a starting pose.
    pub pose: bool,
    /// Has a ground-truth pose.
    pub gt_pose: bool,
    /// Number of ground-truth sub-frame poses.
    pub subframes: usize,
}

/// Summarises `scene`. With `read_events`, the event stream is loaded (through `gems_events`)
/// to count events overall and per exposure window; otherwise only the files are reported.
pub fn scene_info(scene: &Scene, read_events: bool) -> Result<SceneInfo> {
    let v = &scene.views;
    let first = v.first();
    let intrinsics = v.iter().find_map(|v| v.intrinsics);
    let subframes_per_view = v
        .iter()
        .find_map(|v| v.gt_subframe_poses.as_ref().map(Vec::len));
    let events = if scene.events.is_empty() {
        None
    } else {
        Some(events_summary(scene, read_events)?)
    };
    Ok(SceneInfo {
        root: scene.root.clone(),
        layout: scene.layout,
        dataset: scene.dataset.clone(),
        uses: scene.uses.clone(),
        focal: if intrinsics.is_none() {
            crate::exif::scene_focal(scene)
        } else {
            None
        },
        views: v.len(),
        train: scene.train_views().count(),
        eval_deblur: scene.deblur_eval_views().count(),
        eval_nvs: scene.nvs_eval_views().count(),
        width: first.map(|f| f.width),
        height: first.map(|f| f.height),
        uniform_size: first
            .is_some_and(|f| v.iter().all(|x| (x.width, x.height) == (f.width, f.height))),
        downscale: scene.downscale,
        hold: scene.hold,
        intrinsics,
        shared_intrinsics: intrinsics.is_some() && v.iter().all(|x| x.intrinsics == intrinsics),
        pose_source: scene.pose_source,
        posed_views: v.iter().filter(|x| x.pose.is_some()).count(),
        has_gt_poses: v.iter().any(|x| x.gt_pose.is_some()),
        subframes_per_view,
        views_with_subframes: v.iter().filter(|x| x.gt_subframe_poses.is_some()).count(),
        sharp_gt: v.iter().filter(|x| x.sharp_gt.is_some()).count(),
        has_sfm: scene.sfm.is_some(),
        sfm: scene.sfm.as_ref().map(|m| SfmSummary {
            dir: scene.sfm_dir.clone().unwrap_or_default(),
            cameras: m.cameras.len(),
            images: m.images.len(),
            points: m.points.len(),
            matched: scene.sfm_match,
        }),
        manifest: scene.manifest.clone(),
        events,
        view_list: v
            .iter()
            .map(|x| ViewSummary {
                name: x.name.clone(),
                split: x.split,
                sharp_gt: x.sharp_gt.is_some(),
                pose: x.pose.is_some(),
                gt_pose: x.gt_pose.is_some(),
                subframes: x.gt_subframe_poses.as_ref().map_or(0, Vec::len),
            })
            .collect(),
    })
}

fn ext_of(p: &Path) -> String {
    p.extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default()
}

fn events_summary(scene: &Scene, read_events: bool) -> Result<EventsSummary> {
    let files = &scene.events;
    let mut s = EventsSummary {
        stream: files.stream.clone(),
        bin_counts: files.bin_counts.clone(),
        ..EventsSummary::default()
    };
    let mut stream = None;
    if let Some(p) = &files.stream {
        match ext_of(p).as_str() {
            "h5" | "hdf5" => s.notes.push(format!(
                "{}: HDF5 is not read by this build; convert to .npz (see `gems_events::read_events` error text)",
                p.display()
            )),
            "pt" => s.notes.push(format!(
                "{}: torch file; convert the N×4 (x, y, t, p) tensor with: {}",
                p.display(),
                PT_TO_NPY_HINT
            )),
            _ if read_events => {
                let ev = gems_events::read_events(p, &files.read_options(None))
                    .map_err(DataError::Events)?;
                s.count = Some(ev.len());
                s.time_span_us = ev.time_span();
                s.sensor_size = Some((ev.width(), ev.height()));
                stream = Some(ev);
            }
            _ => {}
        }
    }
    if let Some(p) = &files.bin_counts {
        if ext_of(p) == "npy" {
            let f = std::fs::File::open(p).map_err(|e| DataError::io(p, e))?;
            let npy = npyz::NpyFile::new(std::io::BufReader::new(f))
                .map_err(|e| DataError::format(p, format!("not a valid .npy file: {e}")))?;
            s.bin_counts_shape = Some(npy.shape().to_vec());
        } else {
            s.notes.push(format!(
                "{}: torch file; convert once with: {}",
                p.display(),
                PT_TO_NPY_HINT
            ));
        }
    }
    for view in &scene.views {
        if let Some(w) = view.exposure {
            s.windows.push(WindowSummary {
                view: view.name.clone(),
                start_us: w.start,
                end_us: w.end,
                events: stream.as_ref().map(|ev| ev.window(w.start, w.end).len()),
            });
        }
    }
    Ok(s)
}

impl fmt::Display for SceneInfo {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(f, "scene      {}", self.root.display())?;
        writeln!(f, "layout     {}", self.layout.describe())?;
        writeln!(f, "dataset    {}", self.dataset)?;
        for u in &self.uses {
            writeln!(f, "uses       {}: {}", u.path.display(), u.role)?;
        }
        self.fmt_views(f)?;
        self.fmt_poses(f)?;
        self.fmt_events(f)
    }
}

impl SceneInfo {
    /// Views, splits, resolution and intrinsics.
    fn fmt_views(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let hold = self
            .hold
            .map_or("none".to_owned(), |h| format!("every {h}th view held out"));
        writeln!(
            f,
            "views      {} ({} train, {} deblur-eval, {} novel-view eval; hold: {hold})",
            self.views, self.train, self.eval_deblur, self.eval_nvs
        )?;
        match (self.width, self.height) {
            (Some(w), Some(h)) => writeln!(
                f,
                "resolution {w}x{h}{} (downscale {})",
                if self.uniform_size {
                    ""
                } else {
                    " (first view; sizes differ)"
                },
                self.downscale
            )?,
            _ => writeln!(f, "resolution -")?,
        }
        match &self.intrinsics {
            Some(k) => writeln!(
                f,
                "intrinsics fx {:.3} fy {:.3} cx {:.3} cy {:.3}{}",
                k.fx,
                k.fy,
                k.cx,
                k.cy,
                if self.shared_intrinsics {
                    " (shared)"
                } else {
                    " (first view; per-view)"
                }
            )?,
            None => match &self.focal {
                Some(fs) => writeln!(
                    f,
                    "intrinsics unknown; focal {:.1} px for the SfM from {} (override: --focal)",
                    fs.focal_px, fs.source
                )?,
                None => writeln!(
                    f,
                    "intrinsics unknown; focal estimated by the SfM (no EXIF; set one with --focal)"
                )?,
            },
        }
        Ok(())
    }

    /// Pose sources, ground truth, sharp images, the SfM model and the manifest.
    fn fmt_poses(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let src = match self.pose_source {
            PoseSource::None => "none (run `gems sfm` first)",
            PoseSource::Sfm => "SfM model",
            PoseSource::Llff => "poses_bounds.npy (estimated)",
            PoseSource::Nerfstudio if self.layout == Layout::Blender => {
                "transforms_<split>.json (rendered: exact)"
            }
            PoseSource::Nerfstudio => "transforms.json",
        };
        writeln!(
            f,
            "poses      {src}: {}/{} views",
            self.posed_views, self.views
        )?;
        writeln!(
            f,
            "gt poses   {}",
            match (self.has_gt_poses, self.layout) {
                (false, _) => "no",
                (true, Layout::Blender) => "yes (mid-exposure, the rendered scene's own poses)",
                (true, Layout::Llff) => {
                    "yes (mid-exposure, from poses_bounds.npy declared ground truth)"
                }
                (true, _) => "yes (mid-exposure)",
            }
        )?;
        match self.subframes_per_view {
            Some(s) => writeln!(
                f,
                "sub-frames {s} ground-truth poses per exposure ({} views)",
                self.views_with_subframes
            )?,
            None => writeln!(f, "sub-frames no")?,
        }
        writeln!(f, "sharp gt   {} views", self.sharp_gt)?;
        match &self.sfm {
            Some(m) => {
                writeln!(
                    f,
                    "sfm        {} ({} cameras, {} images, {} points)",
                    m.dir.display(),
                    m.cameras,
                    m.images,
                    m.points
                )?;
                if let Some(k) = &m.matched {
                    writeln!(
                        f,
                        "           {} of {} views posed by it, images matched {}",
                        k.matched,
                        k.views,
                        k.rule.describe()
                    )?;
                }
            }
            None => writeln!(f, "sfm        none")?,
        }
        if let Some(m) = &self.manifest {
            writeln!(
                f,
                "manifest   generator {:?}, poses {:?}",
                m.generator, m.poses
            )?;
        }
        Ok(())
    }

    /// Event stream, bins and exposure windows.
    fn fmt_events(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match &self.events {
            None => writeln!(f, "events     none")?,
            Some(e) => {
                if let Some(p) = &e.stream {
                    write!(f, "events     {}", p.display())?;
                    match (e.count, e.time_span_us, e.sensor_size) {
                        (Some(n), span, Some((w, h))) => {
                            write!(f, ": {n} events, sensor {w}x{h}")?;
                            if let Some((a, b)) = span {
                                write!(f, ", t {a}..{b} µs ({:.3} s)", (b - a) as f64 * 1e-6)?;
                            }
                            writeln!(f)?;
                        }
                        _ => writeln!(f, " (not read)")?,
                    }
                }
                if let Some(p) = &e.bin_counts {
                    write!(f, "event bins {}", p.display())?;
                    match &e.bin_counts_shape {
                        Some(s) => writeln!(f, " shape {s:?}")?,
                        None => writeln!(f)?,
                    }
                }
                if !e.windows.is_empty() {
                    writeln!(f, "exposures  {} windows", e.windows.len())?;
                    for w in &e.windows {
                        write!(
                            f,
                            "  {:<24} {}..{} µs ({} µs)",
                            w.view,
                            w.start_us,
                            w.end_us,
                            w.end_us - w.start_us
                        )?;
                        match w.events {
                            Some(n) => writeln!(f, " {n} events")?,
                            None => writeln!(f)?,
                        }
                    }
                }
                for n in &e.notes {
                    writeln!(f, "note       {n}")?;
                }
            }
        }
        Ok(())
    }
}

//! Writing a generated scene folder (GeMS layout) atomically, and the blur-level study.

use std::path::{Path, PathBuf};

use gems_data::colmap::{
    Camera, CameraModel, ModelFormat, Point2D, Point3D, SparseModel, write_model,
};
use gems_data::llff::{LlffRow, write_poses_bounds, write_subframes};
use gems_data::{Manifest, write_hold_marker, write_manifest};
use gems_events::{EventStream, write_events_npz};
use serde::Serialize;

use crate::SynthError;
use crate::camera::{CameraPose, mean_path_length_px};
use crate::config::SynthConfig;
use crate::render::Image;
use crate::scene::{SynthScene, ViewRender, probe_points};
use gems_math::Intrinsics;

/// What [`generate`] produced.
#[derive(Clone, Debug, Serialize)]
pub struct SynthSummary {
    /// The finished scene folder.
    pub out_dir: PathBuf,
    pub views: usize,
    pub width: u32,
    pub height: u32,
    pub intrinsics: Intrinsics,
    /// Requested blur (px).
    pub blur_px_requested: f64,
    /// Achieved blur per view (mean image-space path length over the exposure, px).
    pub blur_px: Vec<f64>,
    /// Blur sub-frames per view.
    pub subframes: usize,
    /// Total number of events written (0 without events).
    pub events: usize,
    /// Indices of the held-out novel views (i % hold == 0).
    pub nvs_views: Vec<usize>,
}

/// File name of view `i` in `images/` and `images_test/`; zero-padded so names sort like indices.
pub fn image_name(i: usize, views: usize) -> String {
    let digits = views.saturating_sub(1).to_string().len().max(3);
    format!("{i:0digits$}.png")
}

/// Generates the scene described by `config` into `out_dir`, which must not exist or be an empty
/// folder. Everything is written into a temporary sibling folder that is renamed into place at the
/// end, so `out_dir` never holds a half-written scene.
///
/// Layout: `images/` (blurry PNGs), `images_test/` (sharp mid-exposure PNGs, one per image),
/// `hold=<n>`, `gems_scene.json` (gems-data manifest declaring the poses ground truth),
/// `poses_bounds.npy` (N×17 ground-truth mid-exposure poses, LLFF convention),
/// `poses_bounds_subframes.npy` (N×S×17 sub-frame poses), `gt/sparse/0/` (binary COLMAP model
/// of the ground-truth cameras and surface points; deliberately *not* `sparse/0`, which SfM must
/// estimate), `synth.json` (config and summary) and, with events, `events.npz` (t µs, x, y, p ±1)
/// plus `exposure_start_ts.txt` / `exposure_end_ts.txt` (µs, one line per view).
pub fn generate(config: &SynthConfig, out_dir: &Path) -> Result<SynthSummary, SynthError> {
    generate_with_progress(config, out_dir, &mut |_, _| {})
}

/// [`generate`], calling `progress(done, total)` after each rendered view.
pub fn generate_with_progress(
    config: &SynthConfig,
    out_dir: &Path,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<SynthSummary, SynthError> {
    let scene = SynthScene::new(config)?;
    with_staging_dir(out_dir, |tmp| {
        let mut renders = Vec::with_capacity(scene.views.len());
        for v in 0..scene.views.len() {
            let r = scene.render_view(v)?;
            tracing::debug!(
                view = v,
                blur_px = scene.views[v].blur_px,
                events = r.events.as_ref().map_or(0, |e| e.len()),
                "rendered"
            );
            renders.push(r);
            progress(v + 1, scene.views.len());
        }
        let subframe_poses: Vec<Vec<CameraPose>> = (0..scene.views.len())
            .map(|v| scene.subframe_poses(v))
            .collect();
        let blur: Vec<f64> = scene.views.iter().map(|v| v.blur_px).collect();
        write_scene(&scene, &renders, &subframe_poses, &blur, tmp, out_dir)
    })
}

/// Blur levels of the paper's robustness study: averages of 1, 3, 5, 7, 9, 11 burst frames.
pub const BLUR_LEVELS: [usize; 6] = [1, 3, 5, 7, 9, 11];

/// The paper's blur-level study (GeMS §4.4): per viewpoint a burst of 11 sharp frames along the
/// exposure motion (`config.blur_px` = blur of the full 11-frame burst), and one scene folder per
/// level `blur_<n>` (n ∈ [`BLUR_LEVELS`]) whose blurry images average the n frames centred on the
/// middle frame (the sharp ground truth). `config.subframes` and `config.events` are ignored: the
/// study is RGB-only, so no events are written. All six folders appear atomically together.
pub fn generate_blur_levels(
    config: &SynthConfig,
    out_dir: &Path,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<Vec<SynthSummary>, SynthError> {
    const BURST: usize = 11;
    let burst_config = SynthConfig {
        subframes: BURST,
        events: None,
        ..config.clone()
    };
    let scene = SynthScene::new(&burst_config)?;
    with_staging_dir(out_dir, |tmp| {
        let n_views = scene.views.len();
        // levels[l][v] = render of view v at level l.
        let mut levels: Vec<Vec<ViewRender>> = (0..BLUR_LEVELS.len())
            .map(|_| Vec::with_capacity(n_views))
            .collect();
        let mut level_poses: Vec<Vec<Vec<CameraPose>>> =
            vec![Vec::with_capacity(n_views); BLUR_LEVELS.len()];
        let mut level_blur: Vec<Vec<f64>> = vec![Vec::with_capacity(n_views); BLUR_LEVELS.len()];
        let times = scene.subframe_times();
        let mid = BURST / 2;
        for v in 0..n_views {
            let frames: Vec<Image> = times.iter().map(|&u| scene.render_sharp(v, u)).collect();
            let poses = scene.subframe_poses(v);
            let probes = probe_points(&scene.world, &scene.intrinsics, &scene.views[v].mid);
            for (l, &n) in BLUR_LEVELS.iter().enumerate() {
                let range = mid - n / 2..=mid + n / 2;
                let mut blurry = Image::zeros(scene.intrinsics.width, scene.intrinsics.height);
                for f in &frames[range.clone()] {
                    blurry
                        .data
                        .iter_mut()
                        .zip(&f.data)
                        .for_each(|(b, x)| *b += x);
                }
                blurry.data.iter_mut().for_each(|b| *b /= n as f32);
                levels[l].push(ViewRender {
                    blurry,
                    sharp: frames[mid].clone(),
                    events: None,
                });
                // The level's blur: the part of the burst path its n frames span.
                level_blur[l].push(mean_path_length_px(
                    &probes,
                    &scene.intrinsics,
                    &poses[range.clone()],
                ));
                level_poses[l].push(poses[range].to_vec());
            }
            progress(v + 1, n_views);
        }
        let mut summaries = Vec::with_capacity(BLUR_LEVELS.len());
        for (l, &n) in BLUR_LEVELS.iter().enumerate() {
            let name = format!("blur_{n:02}");
            let level_dir = tmp.join(&name);
            std::fs::create_dir(&level_dir).map_err(|e| SynthError::io(&level_dir, e))?;
            summaries.push(write_scene(
                &scene,
                &levels[l],
                &level_poses[l],
                &level_blur[l],
                &level_dir,
                &out_dir.join(&name),
            )?);
        }
        Ok(summaries)
    })
}

/// Runs `fill` on a fresh temporary folder next to `out_dir`, then renames it to `out_dir`.
/// On any error the temporary folder is removed and `out_dir` is left untouched.
fn with_staging_dir<T>(
    out_dir: &Path,
    fill: impl FnOnce(&Path) -> Result<T, SynthError>,
) -> Result<T, SynthError> {
    if out_dir.exists() {
        let empty = std::fs::read_dir(out_dir)
            .map_err(|e| SynthError::io(out_dir, e))?
            .next()
            .is_none();
        if !empty {
            return Err(SynthError::OutputExists(out_dir.to_path_buf()));
        }
    }
    let parent = match out_dir.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    std::fs::create_dir_all(&parent).map_err(|e| SynthError::io(&parent, e))?;
    let name = out_dir
        .file_name()
        .ok_or_else(|| SynthError::Config(format!("{} is not a folder path", out_dir.display())))?;
    let tmp = parent.join(format!(
        ".{}.synth-tmp-{}",
        name.to_string_lossy(),
        std::process::id()
    ));
    if tmp.exists() {
        std::fs::remove_dir_all(&tmp).map_err(|e| SynthError::io(&tmp, e))?;
    }
    std::fs::create_dir(&tmp).map_err(|e| SynthError::io(&tmp, e))?;
    let result = fill(&tmp).and_then(|value| {
        if out_dir.exists() {
            std::fs::remove_dir(out_dir).map_err(|e| SynthError::io(out_dir, e))?;
        }
        std::fs::rename(&tmp, out_dir).map_err(|e| SynthError::io(out_dir, e))?;
        Ok(value)
    });
    if result.is_err() {
        let _ = std::fs::remove_dir_all(&tmp);
    }
    result
}

fn write_png(path: &Path, img: &Image) -> Result<(), SynthError> {
    image::save_buffer(
        path,
        &img.to_rgb8(),
        img.width,
        img.height,
        image::ExtendedColorType::Rgb8,
    )
    .map_err(|e| SynthError::Image {
        path: path.to_path_buf(),
        source: e,
    })
}

fn write_text(path: &Path, text: &str) -> Result<(), SynthError> {
    std::fs::write(path, text).map_err(|e| SynthError::io(path, e))
}

fn llff_row(pose: &CameraPose, k: &Intrinsics, near: f64, far: f64) -> LlffRow {
    LlffRow::from_pose(
        &pose.to_pose(),
        f64::from(k.height),
        f64::from(k.width),
        k.fx,
        near,
        far,
    )
}

/// Writes every file of one scene into `dir`; `final_dir` is where it will live (for the summary).
fn write_scene(
    scene: &SynthScene,
    renders: &[ViewRender],
    subframe_poses: &[Vec<CameraPose>],
    blur_px: &[f64],
    dir: &Path,
    final_dir: &Path,
) -> Result<SynthSummary, SynthError> {
    let cfg = &scene.config;
    let k = &scene.intrinsics;
    let n = scene.views.len();
    write_images(renders, dir)?;
    write_hold_marker(dir, i64::from(cfg.hold))?;
    let manifest = Manifest {
        description: Some(format!(
            "{}x{}, {n} views, {:.1} px mean blur, {} sub-frames, seed {}",
            k.width,
            k.height,
            blur_px.iter().sum::<f64>() / n as f64,
            subframe_poses.first().map_or(0, Vec::len),
            cfg.seed
        )),
        ..Manifest::ground_truth(concat!("gems synth ", env!("CARGO_PKG_VERSION")))
    };
    write_manifest(dir, &manifest)?;
    write_poses(scene, subframe_poses, dir)?;
    let gt_sparse = dir.join("gt").join("sparse").join("0");
    std::fs::create_dir_all(&gt_sparse).map_err(|e| SynthError::io(&gt_sparse, e))?;
    write_model(
        &gt_sparse,
        &ground_truth_model(scene, renders),
        ModelFormat::Binary,
    )?;
    let n_events = if cfg.events.is_some() {
        write_events(scene, renders, dir)?
    } else {
        0
    };

    let summary = SynthSummary {
        out_dir: final_dir.to_path_buf(),
        views: n,
        width: k.width,
        height: k.height,
        intrinsics: *k,
        blur_px_requested: cfg.blur_px,
        blur_px: blur_px.to_vec(),
        subframes: subframe_poses.first().map_or(0, Vec::len),
        events: n_events,
        nvs_views: if cfg.hold >= 1 {
            (0..n).step_by(cfg.hold as usize).collect()
        } else {
            Vec::new()
        },
    };
    let details = serde_json::json!({
        "generator": "gems synth",
        "poses": "ground truth",
        "pose_convention": "poses_bounds.npy: LLFF [down,right,back | centre | h,w,f] + near,far, mid-exposure",
        "blur_average": "mean of sRGB-encoded sub-frames (GeMS/BAD-Gaussians model)",
        "config": cfg,
        "summary": &summary,
    });
    let text =
        serde_json::to_string_pretty(&details).map_err(|e| SynthError::Config(e.to_string()))?;
    write_text(&dir.join("synth.json"), &text)?;
    tracing::debug!(
        "synth scene {}: {n} views {}x{}, {} events",
        final_dir.display(),
        k.width,
        k.height,
        n_events
    );
    Ok(summary)
}

/// The blurry images to `images/`, their sharp mid-exposure frames to `images_test/`.
fn write_images(renders: &[ViewRender], dir: &Path) -> Result<(), SynthError> {
    for sub in ["images", "images_test"] {
        let d = dir.join(sub);
        std::fs::create_dir_all(&d).map_err(|e| SynthError::io(&d, e))?;
    }
    for (i, r) in renders.iter().enumerate() {
        let name = image_name(i, renders.len());
        write_png(&dir.join("images").join(&name), &r.blurry)?;
        write_png(&dir.join("images_test").join(&name), &r.sharp)?;
    }
    Ok(())
}

/// Mid-exposure poses to `poses_bounds.npy`, the sub-frame poses to
/// `poses_bounds_subframes.npy` (ExBluRF's layout).
fn write_poses(
    scene: &SynthScene,
    subframe_poses: &[Vec<CameraPose>],
    dir: &Path,
) -> Result<(), SynthError> {
    let k = &scene.intrinsics;
    let rows: Vec<LlffRow> = scene
        .views
        .iter()
        .map(|v| llff_row(&v.mid, k, v.near, v.far))
        .collect();
    write_poses_bounds(&dir.join("poses_bounds.npy"), &rows)?;
    let sub_rows: Vec<Vec<LlffRow>> = scene
        .views
        .iter()
        .zip(subframe_poses)
        .map(|(v, poses)| {
            poses
                .iter()
                .map(|p| llff_row(p, k, v.near, v.far))
                .collect()
        })
        .collect();
    write_subframes(&dir.join("poses_bounds_subframes.npy"), &sub_rows)?;
    Ok(())
}

/// Every view's events as one stream (`events.npz`) and the exposure windows
/// (`exposure_start_ts.txt` / `exposure_end_ts.txt`, µs); returns the number of events.
fn write_events(
    scene: &SynthScene,
    renders: &[ViewRender],
    dir: &Path,
) -> Result<usize, SynthError> {
    let mut n_events = 0;
    let mut all: Option<EventStream> = None;
    for r in renders {
        if let Some(ev) = &r.events {
            match all.as_mut() {
                Some(a) => a.append(ev.clone())?,
                None => all = Some(ev.clone()),
            }
        }
    }
    if let Some(all) = all {
        n_events = all.len();
        write_events_npz(&dir.join("events.npz"), &all)?;
    }
    let (starts, ends): (Vec<String>, Vec<String>) = (0..scene.views.len())
        .map(|v| {
            let (s, e) = scene.exposure_window_us(v);
            (format!("{s}\n"), format!("{e}\n"))
        })
        .unzip();
    write_text(&dir.join("exposure_start_ts.txt"), &starts.concat())?;
    write_text(&dir.join("exposure_end_ts.txt"), &ends.concat())?;
    Ok(n_events)
}

/// Ground-truth COLMAP model: one PINHOLE camera, every view at its mid-exposure pose, and the
/// surface points hit by each view's probe grid, coloured from that view's sharp image, each with
/// a one-observation track in the view that saw it.
fn ground_truth_model(scene: &SynthScene, renders: &[ViewRender]) -> SparseModel {
    let k = &scene.intrinsics;
    let camera = Camera {
        id: 1,
        model: CameraModel::Pinhole,
        width: u64::from(k.width),
        height: u64::from(k.height),
        params: vec![k.fx, k.fy, k.cx, k.cy],
    };
    let n = scene.views.len();
    let mut images = Vec::with_capacity(n);
    let mut points = Vec::new();
    for (i, (view, render)) in scene.views.iter().zip(renders).enumerate() {
        let image_id = i as u32 + 1;
        let mut img = gems_data::colmap::Image::from_pose(
            image_id,
            1,
            &image_name(i, n),
            &view.mid.to_pose(),
        );
        for p in probe_points(&scene.world, k, &view.mid) {
            let Some(q) = view.mid.project(k, p) else {
                continue;
            };
            let (px, py) = (q[0].floor() as i64, q[1].floor() as i64);
            if px < 0 || py < 0 || px >= i64::from(k.width) || py >= i64::from(k.height) {
                continue;
            }
            let o = 3 * (py as usize * k.width as usize + px as usize);
            let rgb =
                [0, 1, 2].map(|c| (render.sharp.data[o + c].clamp(0.0, 1.0) * 255.0).round() as u8);
            let id = points.len() as u64 + 1;
            img.points2d.push(Point2D {
                x: q[0],
                y: q[1],
                point3d_id: id,
            });
            points.push(Point3D {
                id,
                xyz: p,
                rgb,
                error: 0.0,
                track: vec![(image_id, img.points2d.len() as u32 - 1)],
            });
        }
        images.push(img);
    }
    SparseModel {
        cameras: vec![camera],
        images,
        points,
    }
}

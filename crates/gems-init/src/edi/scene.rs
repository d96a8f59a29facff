//! EDI over a whole scene: `deblur_scene` (in memory) and `write_edi_scene` (a scene folder).

use std::path::{Path, PathBuf};

use gems_data::{ImageRgb, Scene};
use gems_events::EventStream;

use super::{
    EdiConfig, EdiError, EdiMode, Image, PixelEvents, Reference, Thresholds, edi_binned, edi_exact,
    estimate_thresholds, on_off_from_signed,
};

/// The EDI result of one view.
#[derive(Debug, Clone, PartialEq)]
pub struct EdiView {
    /// The view's image file name (as in `images/`).
    pub name: String,
    /// Deblurred frames: one for [`EdiMode::Exact`], `bins + 1` for [`EdiMode::Binned`].
    pub frames: Vec<ImageRgb>,
    /// Time of each frame in µs (bin boundaries are relative to the exposure start when the view
    /// came from count tensors without exposure times).
    pub times_us: Vec<i64>,
    /// Thresholds used.
    pub thresholds: Thresholds,
    /// Events inside the exposure (0 when deblurred from pre-binned counts).
    pub events: usize,
}

/// The EDI result of a scene.
#[derive(Debug, Clone, PartialEq)]
pub struct EdiScene {
    /// Deblurred views, in scene order.
    pub views: Vec<EdiView>,
    /// Names of views without an exposure window or count slice (left blurry).
    pub skipped: Vec<String>,
    /// The mode that produced the frames.
    pub mode: EdiMode,
}

fn to_image(img: &ImageRgb) -> Image {
    Image {
        width: img.width as usize,
        height: img.height as usize,
        channels: 3,
        data: img.data.clone(),
    }
}

fn to_rgb(img: Image) -> ImageRgb {
    let data = if img.channels == 3 {
        img.data
    } else {
        img.data.iter().flat_map(|&v| [v, v, v]).collect()
    };
    ImageRgb {
        width: img.width as u32,
        height: img.height as u32,
        data,
    }
}

/// Deblurs every view of `scene` that has events: with an event stream and per-view exposure
/// windows (`exposure_start_ts.txt`/`exposure_end_ts.txt`) the exact or binned EDI of `cfg.mode`;
/// otherwise with a pre-binned count tensor (`events_bins_<k>.npy`, view i = tensor row i) the
/// binned EDI (in [`EdiMode::Exact`] the boundary frame nearest the reference time is kept).
/// Images must be at the events' resolution (open the scene with downscale 1).
pub fn deblur_scene(scene: &Scene, cfg: &EdiConfig) -> Result<EdiScene, EdiError> {
    let first = scene.views.first().ok_or_else(|| {
        EdiError::Invalid(format!("{}: scene has no views", scene.root.display()))
    })?;
    let size = (first.width, first.height);
    if let Some(stream_path) = &scene.events.stream
        && scene.views.iter().any(|v| v.exposure.is_some())
    {
        let (w, h) = (u16::try_from(size.0), u16::try_from(size.1));
        let (Ok(w), Ok(h)) = (w, h) else {
            return Err(EdiError::Invalid(
                "image larger than an event sensor can be".into(),
            ));
        };
        let is_aedat = stream_path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("aedat4"));
        let opts = scene
            .events
            .read_options(if is_aedat { None } else { Some((w, h)) });
        let events = gems_events::read_events(stream_path, &opts)?;
        if (events.width(), events.height()) != (w, h) {
            return Err(EdiError::Invalid(format!(
                "{}: events are {}×{} but the images are {}×{} (EDI needs full-resolution images)",
                stream_path.display(),
                events.width(),
                events.height(),
                w,
                h
            )));
        }
        return deblur_with_stream(scene, &events, cfg);
    }
    if let Some(bins_path) = &scene.events.bin_counts {
        if bins_path.extension().is_some_and(|e| e == "pt") {
            return Err(EdiError::Invalid(format!(
                "{}: torch tensor; convert once with: {}",
                bins_path.display(),
                gems_data::events::PT_TO_NPY_HINT
            )));
        }
        let counts =
            gems_events::read_bin_counts(bins_path, Some((size.0 as usize, size.1 as usize)))?;
        return deblur_with_counts(scene, &counts, bins_path, cfg);
    }
    Err(EdiError::Invalid(format!(
        "{}: no events to deblur with (need events.* plus exposure_start_ts.txt/exposure_end_ts.txt, or events_bins_<k>.npy)",
        scene.root.display()
    )))
}

fn check_view_size(v: &gems_data::View, img: &ImageRgb, want: (u32, u32)) -> Result<(), EdiError> {
    if (img.width, img.height) != want {
        return Err(EdiError::Invalid(format!(
            "{}: image is {}×{}, events are {}×{}",
            v.image.display(),
            img.width,
            img.height,
            want.0,
            want.1
        )));
    }
    Ok(())
}

fn deblur_with_stream(
    scene: &Scene,
    events: &EventStream,
    cfg: &EdiConfig,
) -> Result<EdiScene, EdiError> {
    let want = (u32::from(events.width()), u32::from(events.height()));
    // (view index, blurry image, grouped events)
    let mut work = Vec::new();
    let mut skipped = Vec::new();
    for (i, v) in scene.views.iter().enumerate() {
        let Some(ex) = v.exposure else {
            skipped.push(v.name.clone());
            continue;
        };
        let img = gems_data::load_image(&v.image)?;
        check_view_size(v, &img, want)?;
        let pe = PixelEvents::new(events.as_slice(), ex.start, ex.end)
            .map_err(|e| EdiError::Invalid(format!("{}: {e}", v.name)))?;
        work.push((i, to_image(&img), pe));
    }
    let reference_time = |pe: &PixelEvents| {
        let (t0, t1) = pe.window();
        match cfg.reference {
            Reference::Mid => t0 + (t1 - t0) / 2,
            Reference::Start => t0,
        }
    };
    let global = match &cfg.search {
        Some(s) if !s.per_view => {
            // a few evenly spread views keep the search fast on large scenes
            let step = work.len().div_ceil(4).max(1);
            let sample: Vec<(&Image, &PixelEvents, i64)> = work
                .iter()
                .step_by(step)
                .map(|(_, img, pe)| (img, pe, reference_time(pe)))
                .collect();
            let th = estimate_thresholds(&sample, s, cfg);
            tracing::info!(
                c_pos = th.c_pos,
                c_neg = th.c_neg,
                "EDI thresholds estimated for the scene"
            );
            Some(th)
        }
        _ => None,
    };
    let mut views = Vec::with_capacity(work.len());
    for (i, img, pe) in &work {
        let v = &scene.views[*i];
        let th = match (&cfg.search, global) {
            (_, Some(th)) => th,
            (Some(s), None) => {
                let th = estimate_thresholds(&[(img, pe, reference_time(pe))], s, cfg);
                tracing::info!(view = %v.name, c_pos = th.c_pos, c_neg = th.c_neg, "EDI thresholds estimated");
                th
            }
            (None, None) => cfg.thresholds,
        };
        let (t0, t1) = pe.window();
        let (frames, times_us) = match cfg.mode {
            EdiMode::Exact => {
                let at = reference_time(pe);
                (vec![to_rgb(edi_exact(img, pe, at, th, cfg)?)], vec![at])
            }
            EdiMode::Binned { bins } => {
                let frames = edi_binned(img, &pe.bin_on_off(bins), bins, th, cfg)?;
                let times = (0..=bins as i64)
                    .map(|k| t0 + (t1 - t0) * k / bins as i64)
                    .collect();
                (frames.into_iter().map(to_rgb).collect(), times)
            }
        };
        tracing::debug!(view = %v.name, events = pe.len(), "EDI done");
        views.push(EdiView {
            name: v.name.clone(),
            frames,
            times_us,
            thresholds: th,
            events: pe.len(),
        });
    }
    Ok(EdiScene {
        views,
        skipped,
        mode: cfg.mode,
    })
}

fn deblur_with_counts(
    scene: &Scene,
    counts: &gems_events::BinCounts,
    path: &Path,
    cfg: &EdiConfig,
) -> Result<EdiScene, EdiError> {
    if cfg.search.is_some() {
        return Err(EdiError::Invalid(format!(
            "{}: threshold search needs event timestamps; give the thresholds for pre-binned counts",
            path.display()
        )));
    }
    if counts.views < scene.views.len() {
        return Err(EdiError::Invalid(format!(
            "{}: {} views of counts for {} images",
            path.display(),
            counts.views,
            scene.views.len()
        )));
    }
    let want = (counts.width as u32, counts.height as u32);
    let bins = counts.bins;
    let n = counts.width * counts.height;
    let th = cfg.thresholds;
    let mut views = Vec::new();
    for (i, v) in scene.views.iter().enumerate() {
        let img = gems_data::load_image(&v.image)?;
        check_view_size(v, &img, want)?;
        let signed = &counts.data[i * bins * n..(i + 1) * bins * n];
        let frames = edi_binned(
            &to_image(&img),
            &on_off_from_signed(signed, bins, n),
            bins,
            th,
            cfg,
        )?;
        let (t0, t1) = v.exposure.map_or((0, bins as i64), |e| (e.start, e.end));
        let mut times: Vec<i64> = (0..=bins as i64)
            .map(|k| t0 + (t1 - t0) * k / bins as i64)
            .collect();
        let mut frames: Vec<ImageRgb> = frames.into_iter().map(to_rgb).collect();
        if cfg.mode == EdiMode::Exact {
            let k = match cfg.reference {
                Reference::Start => 0,
                Reference::Mid => bins.div_ceil(2),
            };
            frames = vec![frames.swap_remove(k)];
            times = vec![times[k]];
        }
        views.push(EdiView {
            name: v.name.clone(),
            frames,
            times_us: times,
            thresholds: th,
            events: 0,
        });
    }
    Ok(EdiScene {
        views,
        skipped: Vec::new(),
        mode: cfg.mode,
    })
}

fn io_err(path: &Path) -> impl FnOnce(std::io::Error) -> EdiError + '_ {
    move |source| EdiError::Io {
        path: path.to_path_buf(),
        source,
    }
}

fn copy_dir(from: &Path, to: &Path) -> Result<(), EdiError> {
    std::fs::create_dir_all(to).map_err(io_err(to))?;
    for entry in std::fs::read_dir(from).map_err(io_err(from))? {
        let p = entry.map_err(io_err(from))?.path();
        let dest = to.join(p.file_name().expect("read_dir entries have names"));
        if p.is_dir() {
            copy_dir(&p, &dest)?;
        } else {
            std::fs::copy(&p, &dest).map_err(io_err(&p))?;
        }
    }
    Ok(())
}

/// Top-level entries of the input scene that are not carried into the EDI scene: the blurry
/// images (and their downscaled copies) are replaced, event data is not needed downstream.
fn skip_entry(name: &str) -> bool {
    (name == "images" || (name.starts_with("images_") && !name.starts_with("images_test")))
        || name == "events"
        || name.starts_with("events.")
        || name.starts_with("events_bins_")
        || name == "edi.json"
}

/// Writes the EDI result as a scene folder at `out` (which must not exist or be empty), built in a
/// temporary sibling folder and renamed into place, so a failure leaves nothing half-written.
///
/// [`EdiMode::Exact`]: the input scene with `images/` holding the EDI frames under the original
/// file names (views without events keep their blurry image); intrinsics, poses, `sparse/`,
/// `images_test/`, `hold=` and manifests are copied. [`EdiMode::Binned`]: `images/` holds
/// `<stem>_<kk>.png` (kk = 00…b) for every view and nothing else, since no pose file describes
/// those frames. An `edi.json` records thresholds and frame times.
pub fn write_edi_scene(scene: &Scene, edi: &EdiScene, out: &Path) -> Result<(), EdiError> {
    if out.exists()
        && std::fs::read_dir(out)
            .map_err(io_err(out))?
            .next()
            .is_some()
    {
        return Err(EdiError::Invalid(format!(
            "{}: output folder exists and is not empty",
            out.display()
        )));
    }
    let parent = out
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    std::fs::create_dir_all(parent).map_err(io_err(parent))?;
    let tmp: PathBuf = parent.join(format!(
        ".{}.tmp{}",
        out.file_name()
            .map_or("edi".into(), |n| n.to_string_lossy()),
        std::process::id()
    ));
    if tmp.exists() {
        std::fs::remove_dir_all(&tmp).map_err(io_err(&tmp))?;
    }
    let result = write_into(scene, edi, &tmp).and_then(|()| {
        if out.exists() {
            std::fs::remove_dir(out).map_err(io_err(out))?;
        }
        std::fs::rename(&tmp, out).map_err(io_err(out))
    });
    if result.is_err() {
        let _ = std::fs::remove_dir_all(&tmp);
    }
    result
}

fn write_into(scene: &Scene, edi: &EdiScene, dir: &Path) -> Result<(), EdiError> {
    let images = dir.join("images");
    std::fs::create_dir_all(&images).map_err(io_err(&images))?;
    match edi.mode {
        EdiMode::Exact => {
            for entry in std::fs::read_dir(&scene.root).map_err(io_err(&scene.root))? {
                let p = entry.map_err(io_err(&scene.root))?.path();
                let name = p
                    .file_name()
                    .map(|n| n.to_string_lossy().into_owned())
                    .unwrap_or_default();
                if skip_entry(&name) {
                    continue;
                }
                if p.is_dir() {
                    copy_dir(&p, &dir.join(&name))?;
                } else {
                    std::fs::copy(&p, dir.join(&name)).map_err(io_err(&p))?;
                }
            }
            for v in &scene.views {
                let dest = images.join(&v.name);
                match edi.views.iter().find(|e| e.name == v.name) {
                    Some(e) => gems_data::image::save_image_auto(&dest, &e.frames[0])?,
                    None => {
                        std::fs::copy(&v.image, &dest).map_err(io_err(&v.image))?;
                    }
                }
            }
        }
        EdiMode::Binned { .. } => {
            for e in &edi.views {
                let stem = Path::new(&e.name)
                    .file_stem()
                    .map_or(e.name.clone(), |s| s.to_string_lossy().into_owned());
                for (k, f) in e.frames.iter().enumerate() {
                    gems_data::save_png(&images.join(format!("{stem}_{k:02}.png")), f)?;
                }
            }
        }
    }
    let report = serde_json::json!({
        "mode": match edi.mode { EdiMode::Exact => "exact".to_owned(), EdiMode::Binned { bins } => format!("binned_{bins}") },
        "skipped": edi.skipped,
        "views": edi.views.iter().map(|v| serde_json::json!({
            "name": v.name,
            "c_pos": v.thresholds.c_pos,
            "c_neg": v.thresholds.c_neg,
            "events": v.events,
            "times_us": v.times_us,
        })).collect::<Vec<_>>(),
    });
    let path = dir.join("edi.json");
    let text =
        serde_json::to_string_pretty(&report).map_err(|e| EdiError::Invalid(e.to_string()))?;
    std::fs::write(&path, text).map_err(io_err(&path))?;
    Ok(())
}

//! `report.html`: metrics tables, loss/PSNR curves, a trajectory plot (estimated vs ground truth
//! when known) and a blurry | ours | ground-truth grid. The figures are PNGs drawn with plotters
//! into a pixel buffer without any text (no font needed); their axes are described in the HTML.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use gems_data::{ImageRgb, save_png};
use gems_math::{Matrix3, Vector3, umeyama};
use plotters::prelude::*;

use crate::EvalError;
use crate::metrics::{MetricsReport, SplitScores};

/// One row of the comparison grid; images `[H,W,3]`.
#[derive(Clone, Debug)]
pub struct GridRow {
    pub name: String,
    pub width: u32,
    pub height: u32,
    pub blurry: Vec<f32>,
    /// The EDI-deblurred image (GeMS-E initialisation input) when the run used events.
    pub edi: Option<Vec<f32>>,
    pub ours: Vec<f32>,
    pub gt: Option<Vec<f32>>,
}

/// What the report shows.
#[derive(Clone, Debug)]
pub struct ReportInput {
    pub title: String,
    pub metrics: MetricsReport,
    /// Per-step training loss and PSNR (of the synthesised blurry image vs the input).
    pub loss: Vec<f32>,
    pub psnr: Vec<f32>,
    /// Per view: the virtual camera centres in exposure order (input frame).
    pub trajectories: Vec<Vec<[f64; 3]>>,
    /// Per view: the ground-truth mid-exposure centre when known (input frame).
    pub gt_centres: Vec<Option<[f64; 3]>>,
    /// Per view: the ground-truth sub-frame centres in exposure order (input frame; empty when
    /// unknown), drawn beside the estimated paths.
    pub gt_paths: Vec<Vec<[f64; 3]>>,
    pub grid: Vec<GridRow>,
    /// The interactive 3D view (also written alone as `viewer.html`), when there is a scene.
    pub viewer: Option<crate::viewer::ViewerScene>,
    /// The SfM's registration of each photo, when the run's initialisation made one.
    pub registration: Option<Registration>,
}

/// The initialiser's account of each photo (the built-in SfM's `sfm_report.json`).
#[derive(Clone, Debug, Default, serde::Deserialize)]
pub struct Registration {
    pub views: Vec<RegisteredPhoto>,
    /// Plain sentences on dropped photos and what to try, and on a focal estimated under heavy
    /// blur (`gems_init::sfm::SfmStats::advice`).
    #[serde(default)]
    pub advice: Vec<String>,
    /// The focal was estimated under blur that barely determines it
    /// (`gems_init::sfm::SfmStats::focal_barely_determined`; false in reports written before
    /// the field existed).
    #[serde(default)]
    pub focal_barely_determined: bool,
}

/// The built-in SfM's per-photo registration of a run (`<dir>/sfm/sfm_report.json`, what
/// `gems train` writes when it runs the SfM on the user's photos), if it made one.
pub fn read_registration(dir: &Path) -> Option<Registration> {
    let text = std::fs::read_to_string(dir.join("sfm").join("sfm_report.json")).ok()?;
    serde_json::from_str(&text)
        .inspect_err(|e| tracing::warn!("sfm_report.json not read for the report: {e}"))
        .ok()
}

/// One photo of [`Registration`].
#[derive(Clone, Debug, serde::Deserialize)]
pub struct RegisteredPhoto {
    pub name: String,
    pub registered: bool,
    pub blur_px: f64,
    pub points: usize,
    pub reprojection_error_px: Option<f64>,
    pub why_not: Option<String>,
}

/// The photos' registration table and the advice, when there is one.
fn registration_section(html: &mut String, reg: &Option<Registration>) {
    let Some(reg) = reg else { return };
    let registered = reg.views.iter().filter(|v| v.registered).count();
    let _ = writeln!(
        html,
        "<h2>Registration</h2>\n<p>The SfM registered {registered} of {} photos.</p>",
        reg.views.len()
    );
    for line in &reg.advice {
        let _ = writeln!(html, "<p><b>{}</b></p>", esc(line));
    }
    html.push_str(
        "<table><tr><th>photo</th><th>registered</th><th>blur (px)</th><th>points seen</th>\
         <th>reprojection error (px)</th><th>why not</th></tr>\n",
    );
    for v in &reg.views {
        let _ = writeln!(
            html,
            "<tr><td>{}</td><td>{}</td><td>{:.1}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
            esc(&v.name),
            if v.registered { "yes" } else { "no" },
            v.blur_px,
            v.points,
            v.reprojection_error_px
                .map_or("—".to_owned(), |e| format!("{e:.2}")),
            esc(v.why_not.as_deref().unwrap_or(""))
        );
    }
    html.push_str("</table>\n");
}

const PLOT_W: u32 = 640;
const PLOT_H: u32 = 320;

fn plot_err(path: &Path, e: impl std::fmt::Display) -> EvalError {
    EvalError::Plot {
        path: path.to_path_buf(),
        reason: e.to_string(),
    }
}

fn save_rgb8(path: &Path, w: u32, h: u32, buf: &[u8]) -> Result<(), EvalError> {
    let img = ImageRgb {
        width: w,
        height: h,
        data: buf.iter().map(|&b| f32::from(b) / 255.0).collect(),
    };
    save_png(path, &img)?;
    Ok(())
}

fn finite_range(vals: impl Iterator<Item = f64>) -> Option<(f64, f64)> {
    let (lo, hi) = vals
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(v), b.max(v))
        });
    if lo > hi {
        return None;
    }
    let pad = ((hi - lo) * 0.05).max(1e-9);
    Some((lo - pad, hi + pad))
}

/// A curve (light raw values, dark 50-step moving average). Returns the y range drawn.
fn plot_curve(path: &Path, values: &[f32]) -> Result<Option<(f64, f64)>, EvalError> {
    let Some((y0, y1)) = finite_range(values.iter().map(|&v| f64::from(v))) else {
        return Ok(None);
    };
    let mut buf = vec![0u8; (PLOT_W * PLOT_H * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (PLOT_W, PLOT_H)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| plot_err(path, e))?;
        let x1 = values.len().max(2) as f64;
        let mut chart = ChartBuilder::on(&root)
            .margin(10)
            .build_cartesian_2d(0.0..x1, y0..y1)
            .map_err(|e| plot_err(path, e))?;
        let raw = values
            .iter()
            .enumerate()
            .filter(|(_, v)| v.is_finite())
            .map(|(i, &v)| (i as f64, f64::from(v)));
        chart
            .draw_series(LineSeries::new(raw, RGBColor(170, 190, 230)))
            .map_err(|e| plot_err(path, e))?;
        let win = 50usize;
        let mut avg = Vec::with_capacity(values.len());
        let mut sum = 0.0f64;
        let mut count = 0usize;
        for (i, &v) in values.iter().enumerate() {
            if v.is_finite() {
                sum += f64::from(v);
                count += 1;
            }
            if i >= win && values[i - win].is_finite() {
                sum -= f64::from(values[i - win]);
                count -= 1;
            }
            if count > 0 {
                avg.push((i as f64, sum / count as f64));
            }
        }
        chart
            .draw_series(LineSeries::new(avg, RGBColor(20, 60, 160).stroke_width(2)))
            .map_err(|e| plot_err(path, e))?;
        root.present().map_err(|e| plot_err(path, e))?;
    }
    save_rgb8(path, PLOT_W, PLOT_H, &buf)?;
    Ok(Some((y0, y1)))
}

/// Each view's estimated exposure path, Sim(3)-aligned (Umeyama) to the ground-truth
/// mid-exposure centres when at least three views have one.
fn aligned_paths(input: &ReportInput) -> Vec<Vec<[f64; 3]>> {
    let pairs: Vec<([f64; 3], [f64; 3])> = input
        .trajectories
        .iter()
        .zip(&input.gt_centres)
        .filter_map(|(t, g)| Some((*t.get(t.len() / 2)?, (*g)?)))
        .collect();
    let (est_m, gt_m): (Vec<_>, Vec<_>) = pairs.iter().copied().unzip();
    let align = if est_m.len() >= 3 {
        umeyama(&est_m, &gt_m, true).ok()
    } else {
        None
    };
    let map = |p: &[f64; 3]| align.map_or(*p, |s| s.act(p));
    input
        .trajectories
        .iter()
        .map(|t| t.iter().map(map).collect())
        .collect()
}

/// The mean of `points` and their two largest principal axes: the plane the top view shows.
fn principal_plane(points: &[Vector3<f64>]) -> (Vector3<f64>, Vector3<f64>, Vector3<f64>) {
    let mean = points.iter().sum::<Vector3<f64>>() / points.len() as f64;
    let cov = points.iter().fold(Matrix3::zeros(), |c, p| {
        c + (p - mean) * (p - mean).transpose()
    });
    let eig = cov.symmetric_eigen();
    let mut order = [0usize, 1, 2];
    order.sort_by(|&a, &b| eig.eigenvalues[b].total_cmp(&eig.eigenvalues[a]));
    (
        mean,
        eig.eigenvectors.column(order[0]).into_owned(),
        eig.eigenvectors.column(order[1]).into_owned(),
    )
}

/// Top view of the trajectories on the two principal axes of all centres. The estimate is
/// Sim(3)-aligned to the ground truth first when at least three views have it.
fn plot_trajectories(path: &Path, input: &ReportInput) -> Result<bool, EvalError> {
    let mids: Vec<[f64; 3]> = input
        .trajectories
        .iter()
        .filter_map(|t| t.get(t.len() / 2).copied())
        .collect();
    let est = aligned_paths(input);
    let gt: Vec<[f64; 3]> = input.gt_centres.iter().flatten().copied().collect();
    let gt_paths: Vec<&Vec<[f64; 3]>> = input.gt_paths.iter().filter(|p| p.len() > 1).collect();
    let all: Vec<Vector3<f64>> = est
        .iter()
        .flatten()
        .chain(&gt)
        .chain(gt_paths.iter().copied().flatten())
        .map(|p| Vector3::from(*p))
        .collect();
    if all.is_empty() || mids.is_empty() {
        return Ok(false);
    }
    let (mean, ax, ay) = principal_plane(&all);
    let proj = |p: &[f64; 3]| {
        let d = Vector3::from(*p) - mean;
        (d.dot(&ax), d.dot(&ay))
    };
    let pts: Vec<(f64, f64)> = all.iter().map(|p| proj(&[p.x, p.y, p.z])).collect();
    let (Some((x0, x1)), Some((y0, y1))) = (
        finite_range(pts.iter().map(|p| p.0)),
        finite_range(pts.iter().map(|p| p.1)),
    ) else {
        return Ok(false);
    };
    // Equal scale on both axes so the plot is not distorted.
    let (cx, cy) = ((x0 + x1) / 2.0, (y0 + y1) / 2.0);
    let half = ((x1 - x0) / 2.0).max((y1 - y0) / 2.0 * f64::from(PLOT_W) / f64::from(PLOT_H));
    let half_y = half * f64::from(PLOT_H) / f64::from(PLOT_W);
    let mut buf = vec![0u8; (PLOT_W * PLOT_H * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (PLOT_W, PLOT_H)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| plot_err(path, e))?;
        let mut chart = ChartBuilder::on(&root)
            .margin(10)
            .build_cartesian_2d(cx - half..cx + half, cy - half_y..cy + half_y)
            .map_err(|e| plot_err(path, e))?;
        for t in &gt_paths {
            chart
                .draw_series(LineSeries::new(
                    t.iter().map(proj),
                    RGBColor(20, 150, 60).stroke_width(2),
                ))
                .map_err(|e| plot_err(path, e))?;
        }
        for t in &est {
            chart
                .draw_series(LineSeries::new(
                    t.iter().map(proj),
                    RGBColor(220, 60, 40).stroke_width(2),
                ))
                .map_err(|e| plot_err(path, e))?;
            if let Some(m) = t.get(t.len() / 2) {
                chart
                    .draw_series(std::iter::once(Circle::new(
                        proj(m),
                        3,
                        RGBColor(220, 60, 40).filled(),
                    )))
                    .map_err(|e| plot_err(path, e))?;
            }
        }
        chart
            .draw_series(
                gt.iter()
                    .map(|g| Circle::new(proj(g), 4, RGBColor(20, 150, 60).stroke_width(2))),
            )
            .map_err(|e| plot_err(path, e))?;
        root.present().map_err(|e| plot_err(path, e))?;
    }
    save_rgb8(path, PLOT_W, PLOT_H, &buf)?;
    Ok(true)
}

/// Rows of blurry | EDI (when any row has one) | ours | ground truth separated by white gaps.
fn compose_grid(rows: &[GridRow]) -> Option<ImageRgb> {
    let gap = 4u32;
    let w = rows.iter().map(|r| r.width).max()?;
    let total_h: u32 = rows.iter().map(|r| r.height + gap).sum::<u32>() - gap;
    let with_edi = rows.iter().any(|r| r.edi.is_some());
    let columns = if with_edi { 4 } else { 3 };
    let total_w = columns * w + (columns - 1) * gap;
    let mut img = ImageRgb {
        width: total_w,
        height: total_h,
        data: vec![1.0; (total_w * total_h * 3) as usize],
    };
    let mut y0 = 0;
    for r in rows {
        let mut panels = vec![Some(&r.blurry)];
        if with_edi {
            panels.push(r.edi.as_ref());
        }
        panels.extend([Some(&r.ours), r.gt.as_ref()]);
        for (p, panel) in panels.iter().enumerate() {
            let Some(src) = panel else { continue };
            let x0 = p as u32 * (w + gap);
            for y in 0..r.height {
                let s = (y * r.width * 3) as usize;
                let d = (((y0 + y) * total_w + x0) * 3) as usize;
                let n = (r.width * 3) as usize;
                for (dv, sv) in img.data[d..d + n].iter_mut().zip(&src[s..s + n]) {
                    *dv = sv.clamp(0.0, 1.0);
                }
            }
        }
        y0 += r.height + gap;
    }
    Some(img)
}

fn esc(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

fn lpips_cell(v: Option<f64>) -> String {
    v.map_or_else(|| "—".to_owned(), |x| format!("{x:.4}"))
}

fn split_table(html: &mut String, title: &str, s: &Option<SplitScores>) {
    let _ = writeln!(html, "<h3>{}</h3>", esc(title));
    let Some(s) = s else {
        html.push_str("<p>No views with ground truth in this split.</p>\n");
        return;
    };
    let _ = writeln!(
        html,
        "<p>Mean over {} images: PSNR {:.2} dB, SSIM {:.4}, LPIPS {}</p>",
        s.per_image.len(),
        s.psnr,
        s.ssim,
        lpips_cell(s.lpips)
    );
    html.push_str("<table><tr><th>image</th><th>PSNR</th><th>SSIM</th><th>LPIPS</th></tr>\n");
    for im in &s.per_image {
        let _ = writeln!(
            html,
            "<tr><td>{}</td><td>{:.2}</td><td>{:.4}</td><td>{}</td></tr>",
            esc(&im.name),
            im.psnr,
            im.ssim,
            lpips_cell(im.lpips)
        );
    }
    html.push_str("</table>\n");
}

/// Writes `report.html` and its figures under `dir/report/`; returns the HTML path.
pub fn write_report(dir: &Path, input: &ReportInput) -> Result<PathBuf, EvalError> {
    let fig_dir = dir.join("report");
    let mut html = String::new();
    header_section(&mut html, input);
    viewer_section(&mut html, dir, input)?;
    metrics_section(&mut html, &input.metrics);
    registration_section(&mut html, &input.registration);
    curves_section(&mut html, &fig_dir, input)?;
    trajectory_section(&mut html, &fig_dir, input)?;
    grid_section(&mut html, &fig_dir, input)?;
    html.push_str("</body></html>\n");
    let path = dir.join("report.html");
    gems_fs::write_atomic(&path, html.as_bytes())?;
    Ok(path)
}

/// Title, style and the run's one-line summary.
fn header_section(html: &mut String, input: &ReportInput) {
    let m = &input.metrics;
    let _ = write!(
        html,
        "<!DOCTYPE html>\n<html><head><meta charset=\"utf-8\"><title>{t}</title><style>\
         body{{font-family:sans-serif;max-width:1100px;margin:2em auto}}\
         table{{border-collapse:collapse}}td,th{{border:1px solid #ccc;padding:2px 8px;text-align:right}}\
         img{{max-width:100%}}</style></head><body>\n<h1>{t}</h1>\n",
        t = esc(&input.title)
    );
    match &m.run {
        Some(r) => {
            let _ = writeln!(html, "<h2>What ran</h2>\n<table>");
            let hold = r
                .hold
                .map_or("none".to_owned(), |h| format!("every {h}th view held out"));
            let memory = r.peak_memory_bytes.map_or("—".to_owned(), |b| {
                format!("{:.2} GiB", b as f64 / (1u64 << 30) as f64)
            });
            let eval = m
                .eval_seconds
                .map_or(String::new(), |s| format!(", evaluation {s:.0} s"));
            for (k, v) in [
                (
                    "protocol",
                    r.protocol
                        .clone()
                        .unwrap_or_else(|| "none (gems defaults)".into()),
                ),
                ("scene", format!("{} ({})", r.scene.display(), r.dataset)),
                ("downscale", format!("×{}", r.downscale)),
                ("hold-out", hold),
                (
                    "views",
                    format!("{} training, {} held out", r.train_views, r.held_out_views),
                ),
                ("initialisation", r.init.clone()),
                (
                    "schedule",
                    match r.mean_virtual_views {
                        Some(mean) if mean < r.virtual_views as f64 => format!(
                            "{} steps, up to {} virtual views per exposure ({mean:.1} per step \
                             on average, from each photo's blur length)",
                            r.steps, r.virtual_views
                        ),
                        _ => format!(
                            "{} steps, {} virtual views per exposure",
                            r.steps, r.virtual_views
                        ),
                    },
                ),
                ("device", r.device.clone()),
                (
                    "wall time",
                    format!("{:.0} s initialisation and training{eval}", r.wall_seconds),
                ),
                ("peak memory", memory),
            ] {
                let _ = writeln!(
                    html,
                    "<tr><th style=\"text-align:left\">{k}</th><td style=\"text-align:left\">{}</td></tr>",
                    esc(&v)
                );
            }
            let _ = writeln!(
                html,
                "</table>\n<p>Trained from <b>{}</b>; {} Gaussians at the end.</p>",
                esc(&m.init),
                m.gaussians
            );
        }
        None => {
            let _ = writeln!(
                html,
                "<p>Initialisation: <b>{}</b>. {} steps, {:.1} s, {} Gaussians.</p>",
                esc(&m.init),
                m.steps,
                m.seconds,
                m.gaussians
            );
        }
    }
}

/// The interactive WebGL2 view (also written alone as `viewer.html`), when there is one.
fn viewer_section(html: &mut String, dir: &Path, input: &ReportInput) -> Result<(), EvalError> {
    if let Some(scene) = &input.viewer {
        for (rel, img) in &scene.image_files {
            save_png(&dir.join(rel), img)?;
        }
        let (frag, _) = crate::viewer::viewer_fragment(scene, false);
        html.push_str(
            "<h2>Interactive view</h2>\n<p>The trained Gaussians (WebGL2). Camera buttons jump to \
             each training view at its mid-exposure pose and each held-out view; at a view the \
             image buttons toggle the blurry input and the ground truth over the live render. Red \
             lines: estimated exposure trajectories. The same view fills the window in \
             <a href=\"viewer.html\">viewer.html</a> (<code>viewer.html#camera=&lt;image name&gt;</code> \
             opens at that camera).</p>\n",
        );
        html.push_str(&frag);
        gems_fs::write_atomic(
            &dir.join("viewer.html"),
            crate::viewer::viewer_page(scene, &input.title).as_bytes(),
        )?;
    }
    Ok(())
}

/// The metric tables of every split and APE.
fn metrics_section(html: &mut String, m: &MetricsReport) {
    if [&m.deblur, &m.deblur_refined, &m.nvs, &m.nvs_no_pose_opt]
        .iter()
        .any(|s| s.as_ref().is_some_and(|s| s.lpips.is_none()))
    {
        html.push_str("<p>LPIPS is absent (—): no LPIPS weights were given.</p>\n");
    }
    html.push_str("<h2>Metrics</h2>\n");
    if let Some(p) = &m.held_out_pose {
        let _ = writeln!(
            html,
            "<p>Held-out views are posed at {}.</p>",
            esc(&p.describe())
        );
    }
    for (key, label) in crate::metrics::split_labels() {
        let split = match key {
            "input" => &m.input,
            "deblur" => &m.deblur,
            "deblur_refined" => &m.deblur_refined,
            "nvs_no_pose_opt" => &m.nvs_no_pose_opt,
            _ => &m.nvs,
        };
        let mut label = label.to_owned();
        if let Some(first) = label.get_mut(0..1) {
            first.make_ascii_uppercase();
        }
        split_table(html, &label, split);
    }
    if let Some(c) = &m.camera_shift {
        let _ = writeln!(
            html,
            "<h3>How far training moved the cameras</h3><p>The {} trained mid-exposure cameras \
             against the held-out views' pose source's cameras of the same views, after the \
             similarity: centres {:.2} % of their extent (RMSE), rotations {:.3}° (RMSE). The \
             initial cameras: {:.2} %, {:.3}°.</p>",
            c.views, c.centre_pct, c.rotation_deg, c.initial_centre_pct, c.initial_rotation_deg
        );
    }
    match &m.ape {
        Some(a) => {
            let _ = writeln!(
                html,
                "<h3>APE (Sim(3)-aligned midpoint camera centres against the ground truth: explicit poses, \
                 else the mid sub-frame of the sub-frame poses; ground-truth units)</h3>\
                 <p>RMSE {:.5}, mean {:.5}, median {:.5}, std {:.5}, max {:.5}</p>",
                a.rmse, a.mean, a.median, a.std, a.max
            );
            if let Some(i) = &m.ape_init {
                let _ = writeln!(
                    html,
                    "<p>The initial poses (before training): RMSE {:.5}, mean {:.5}, max {:.5}.</p>",
                    i.rmse, i.mean, i.max
                );
            }
        }
        None => html.push_str("<h3>APE</h3><p>Not available (no ground-truth poses).</p>\n"),
    }
    if let Some(f) = &m.focal {
        let _ = writeln!(
            html,
            "<h3>Focal length (x, pixels at the training size)</h3><p>{}.</p>",
            esc(&f.describe())
        );
    }
    if let Some(r) = &m.rotation_error {
        let _ = writeln!(
            html,
            "<h3>Relative rotation error (every pair of training views: the estimated \
             camera-to-camera rotation against the ground truth's; degrees)</h3>\
             <p>Trajectory midpoints: RMSE {:.3}°, mean {:.3}°, median {:.3}°, max {:.3}°.</p>",
            r.rmse_deg, r.mean_deg, r.median_deg, r.max_deg
        );
        if let Some(i) = &m.rotation_error_init {
            let _ = writeln!(
                html,
                "<p>The initial poses (before training): RMSE {:.3}°, median {:.3}°, max {:.3}°.</p>",
                i.rmse_deg, i.median_deg, i.max_deg
            );
        }
    }
}

/// Loss and PSNR curves.
fn curves_section(html: &mut String, fig_dir: &Path, input: &ReportInput) -> Result<(), EvalError> {
    html.push_str("<h2>Training curves</h2>\n");
    for (file, label, values) in [
        ("loss.png", "Training loss", &input.loss),
        (
            "psnr.png",
            "PSNR of the re-blurred render vs the blurry input (dB)",
            &input.psnr,
        ),
    ] {
        if let Some((y0, y1)) = plot_curve(&fig_dir.join(file), values)? {
            let _ = writeln!(
                html,
                "<p>{label}: x = step 0…{}, y = {y0:.4}…{y1:.4} (light: per step, dark: 50-step mean).</p>\
                 <img src=\"report/{file}\">",
                values.len()
            );
        }
    }
    Ok(())
}

/// The top-view trajectory plot, when there is anything to plot.
fn trajectory_section(
    html: &mut String,
    fig_dir: &Path,
    input: &ReportInput,
) -> Result<(), EvalError> {
    if plot_trajectories(&fig_dir.join("trajectory.png"), input)? {
        html.push_str(
            "<h2>Trajectories</h2>\n<p>Top view on the two principal axes (equal scale). Red: estimated \
             exposure trajectories (dot = midpoint); green circles: ground-truth mid-exposure \
             centres, green lines: ground-truth sub-frame paths (estimate Sim(3)-aligned to the \
             centres when known).</p><img src=\"report/trajectory.png\">\n",
        );
    }
    Ok(())
}

/// The blurry | (EDI |) ours | ground-truth grid and its per-row PSNRs.
fn grid_section(html: &mut String, fig_dir: &Path, input: &ReportInput) -> Result<(), EvalError> {
    if let Some(grid) = compose_grid(&input.grid) {
        save_png(&fig_dir.join("grid.png"), &grid)?;
        let with_edi = input.grid.iter().any(|r| r.edi.is_some());
        let heading = if with_edi {
            "Blurry input | EDI from events (initialisation only) | ours (trajectory midpoint) | ground truth"
        } else {
            "Blurry input | ours (trajectory midpoint) | ground truth"
        };
        let _ = writeln!(
            html,
            "<h2>{heading}</h2>\n<img src=\"report/grid.png\">\n<table>\n<tr><th>row</th>\
             <th>blurry PSNR</th>{}<th>ours PSNR</th></tr>",
            if with_edi { "<th>EDI PSNR</th>" } else { "" }
        );
        for r in &input.grid {
            let gt = r.gt.as_ref();
            let (h, w) = (r.height as usize, r.width as usize);
            let cell = |img: Option<&Vec<f32>>| match (img, gt) {
                (Some(a), Some(b)) => gems_metrics::psnr(a, b, h, w)
                    .map_or_else(|_| "—".to_owned(), |p| format!("{p:.2} dB")),
                _ => "—".to_owned(),
            };
            let _ = writeln!(
                html,
                "<tr><td>{}</td><td>{}</td>{}<td>{}</td></tr>",
                esc(&r.name),
                cell(Some(&r.blurry)),
                if with_edi {
                    format!("<td>{}</td>", cell(r.edi.as_ref()))
                } else {
                    String::new()
                },
                cell(Some(&r.ours))
            );
        }
        html.push_str("</table>\n");
    }
    Ok(())
}

//! The interactive WebGL2 splat viewer: the scene quantised into the web `.splat` layout (plus
//! SH degree 1), base64 in a self-contained HTML page with the viewer's JavaScript
//! (`viewer/viewer.js`, embedded at build time), for `report.html` and `viewer.html`.
//!
//! `.splat` record (32 bytes, little endian; the layout of antimatter15/splat's
//! `convert.py`, which the common web splat viewers read): position f32×3, scale f32×3 (linear,
//! `exp(log_scale)`), colour RGBA u8×4 (`clamp(0.5 + C0·sh₀, 0, 1)·255`, `sigmoid(logit)·255`),
//! rotation u8×4 (unit quaternion w, x, y, z as `clamp(q·128 + 128, 0, 255)`). The viewer adds a
//! second array of 9 i8 per splat: the degree-1 SH coefficients `round(sh / s1 · 127)` with one
//! scale `s1` for the whole scene.

use std::fmt::Write as _;

use gems_splat::activation::sigmoid;
use gems_splat::sh::C0;
use gems_splat::{Camera, Gaussians};

/// What a camera button of the viewer is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CameraKind {
    /// A training view at its mid-exposure pose.
    Train,
    /// A held-out view at its (initial) pose.
    HeldOut,
}

/// One camera of the viewer.
#[derive(Clone, Debug)]
pub struct ViewerCamera {
    pub name: String,
    pub kind: CameraKind,
    pub camera: Camera,
    /// Virtual camera centres of the exposure, in exposure order (drawn as a polyline).
    pub trajectory: Vec<[f32; 3]>,
    /// Images to toggle with the live render at this camera: (label, relative URL).
    pub images: Vec<(String, String)>,
}

/// The viewer's scene: Gaussians and cameras in one frame, and the images the cameras' toggles
/// show (written next to the page at their relative URL).
#[derive(Clone, Debug, Default)]
pub struct ViewerScene {
    pub gaussians: Gaussians,
    pub cameras: Vec<ViewerCamera>,
    /// (relative URL, image) pairs referenced by [`ViewerCamera::images`].
    pub image_files: Vec<(String, gems_data::ImageRgb)>,
}

/// Bytes per splat in the page: the 32-byte `.splat` record plus 9 SH-1 bytes.
pub const PAGE_BYTES_PER_SPLAT: usize = 32 + 9;

/// The cap on embedded splats: base64 (4/3) of [`PAGE_BYTES_PER_SPLAT`] keeps the splat data
/// of a page under 29 MB (the 30 MB page budget, less the script and images).
pub const MAX_SPLATS: usize = 29_000_000 * 3 / 4 / PAGE_BYTES_PER_SPLAT;

const VIEWER_JS: &str = include_str!("../viewer/viewer.js");

/// How visible Gaussian `i` is: opacity × its largest projected area over the cameras (the two
/// largest scales over the squared depth), or opacity × the area of its two largest scales when
/// no camera sees it in front.
fn visibility(g: &Gaussians, i: usize, cams: &[Camera]) -> f32 {
    let mut s = g.log_scales[i].map(f32::exp);
    s.sort_by(|a, b| b.total_cmp(a));
    let area = s[0] * s[1];
    let m = g.means[i];
    let best = cams
        .iter()
        .filter_map(|c| {
            let r = &c.rotation;
            let z = r[2][0] * m[0] + r[2][1] * m[1] + r[2][2] * m[2] + c.translation[2];
            (z > 0.01).then(|| c.fx * c.fy * area / (z * z))
        })
        .fold(None, |acc: Option<f32>, v| {
            Some(acc.map_or(v, |a| a.max(v)))
        });
    let v = sigmoid(g.opacity_logits[i]) * best.unwrap_or(area);
    if v.is_finite() { v } else { 0.0 }
}

/// Indices of the at most `max` most visible Gaussians (finite ones only), most visible first.
pub fn select_splats(g: &Gaussians, cams: &[Camera], max: usize) -> Vec<usize> {
    let finite = |i: &usize| {
        g.means[*i].iter().all(|v| v.is_finite())
            && g.log_scales[*i].iter().all(|v| v.is_finite())
            && g.opacity_logits[*i].is_finite()
    };
    let mut idx: Vec<(f32, usize)> = (0..g.len())
        .filter(finite)
        .map(|i| (visibility(g, i, cams), i))
        .collect();
    idx.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
    idx.truncate(max);
    idx.into_iter().map(|(_, i)| i).collect()
}

/// One `.splat` record of Gaussian `i`.
pub fn splat_record(g: &Gaussians, i: usize, out: &mut Vec<u8>) {
    for v in g.means[i] {
        out.extend_from_slice(&v.to_le_bytes());
    }
    for v in g.log_scales[i] {
        out.extend_from_slice(&v.exp().to_le_bytes());
    }
    let u8c = |v: f32| (v.clamp(0.0, 1.0) * 255.0).round() as u8;
    for c in 0..3 {
        out.push(u8c(0.5 + C0 as f32 * g.sh[i][0][c]));
    }
    out.push(u8c(sigmoid(g.opacity_logits[i])));
    let q = g.quats[i];
    let n = q.iter().map(|v| v * v).sum::<f32>().sqrt();
    let q = if n > 1e-12 && n.is_finite() {
        q.map(|v| v / n)
    } else {
        [1.0, 0.0, 0.0, 0.0]
    };
    for v in q {
        out.push((v * 128.0 + 128.0).round().clamp(0.0, 255.0) as u8);
    }
}

/// The `.splat` file of `g` (all finite Gaussians, most visible first; no cameras needed).
pub fn splat_file(g: &Gaussians) -> Vec<u8> {
    let order = select_splats(g, &[], usize::MAX);
    let mut out = Vec::with_capacity(order.len() * 32);
    for i in order {
        splat_record(g, i, &mut out);
    }
    out
}

/// Standard base64 (RFC 4648, with padding).
pub fn base64(bytes: &[u8]) -> String {
    const A: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut s = String::with_capacity(bytes.len().div_ceil(3) * 4);
    for c in bytes.chunks(3) {
        let b = [c[0], *c.get(1).unwrap_or(&0), *c.get(2).unwrap_or(&0)];
        let n = (u32::from(b[0]) << 16) | (u32::from(b[1]) << 8) | u32::from(b[2]);
        for k in 0..4 {
            if k <= c.len() {
                s.push(A[((n >> (18 - 6 * k)) & 63) as usize] as char);
            } else {
                s.push('=');
            }
        }
    }
    s
}

fn json_str(s: &str) -> String {
    // serde_json escapes quotes and control characters; `<` is escaped too so that no
    // `</script>` can end the script element early.
    serde_json::to_string(s)
        .expect("a string serialises")
        .replace('<', "\\u003c")
}

/// The page fragment (a container `div` and its scripts) showing `scene`; `full_window` makes
/// the canvas fill the window (`viewer.html`) instead of a 16:9 box in the report. Returns the
/// fragment and how many splats were kept.
pub fn viewer_fragment(scene: &ViewerScene, full_window: bool) -> (String, usize) {
    let g = &scene.gaussians;
    let cams: Vec<Camera> = scene.cameras.iter().map(|c| c.camera).collect();
    let kept = select_splats(g, &cams, MAX_SPLATS);
    let mut splats = Vec::with_capacity(kept.len() * 32);
    let shdeg = g.sh_degree.min(1);
    let s1 = if shdeg >= 1 {
        kept.iter()
            .flat_map(|&i| g.sh[i][1..4].iter().flatten())
            .fold(
                0.0f32,
                |m, v| if v.is_finite() { m.max(v.abs()) } else { m },
            )
    } else {
        0.0
    };
    let mut sh1 = Vec::with_capacity(kept.len() * 9);
    for &i in &kept {
        splat_record(g, i, &mut splats);
        for k in 1..4 {
            for c in 0..3 {
                let q = if s1 > 0.0 {
                    (g.sh[i][k][c] / s1 * 127.0).round().clamp(-127.0, 127.0)
                } else {
                    0.0
                };
                sh1.push(q as i8 as u8);
            }
        }
    }
    let mut cams_json = String::from("[");
    for (n, c) in scene.cameras.iter().enumerate() {
        let k = &c.camera;
        let r: Vec<f32> = k.rotation.iter().flatten().copied().collect();
        let traj: Vec<String> = c
            .trajectory
            .iter()
            .map(|p| format!("[{},{},{}]", p[0], p[1], p[2]))
            .collect();
        let imgs: Vec<String> = c
            .images
            .iter()
            .map(|(l, u)| format!("[{},{}]", json_str(l), json_str(u)))
            .collect();
        let _ = write!(
            cams_json,
            "{}{{\"name\":{},\"kind\":\"{}\",\"fx\":{},\"fy\":{},\"cx\":{},\"cy\":{},\"w\":{},\"h\":{},\
             \"R\":{:?},\"t\":{:?},\"traj\":[{}],\"images\":[{}]}}",
            if n > 0 { "," } else { "" },
            json_str(&c.name),
            match c.kind {
                CameraKind::Train => "train",
                CameraKind::HeldOut => "held-out",
            },
            k.fx,
            k.fy,
            k.cx,
            k.cy,
            k.width,
            k.height,
            r,
            k.translation,
            traj.join(","),
            imgs.join(",")
        );
    }
    cams_json.push(']');
    let total = g.len();
    let note = if kept.len() < total {
        format!(
            "{} of {} Gaussians shown (the most visible by opacity × projected area; the page is capped at {} splats).",
            kept.len(),
            total,
            MAX_SPLATS
        )
    } else {
        format!("All {} Gaussians shown.", kept.len())
    };
    let mut html = String::new();
    let _ = write!(
        html,
        "<div id=\"gems-viewer\" class=\"{cls}\"></div>\n\
         <script>window.GEMS_SCENE={{\"count\":{count},\"total\":{total},\"shDegree\":{shdeg},\"sh1Scale\":{s1},\
         \"note\":{note},\"cameras\":{cams_json},\n\"splats\":\"{splats}\",\n\"sh1\":\"{sh1}\"}};</script>\n\
         <script>\n{VIEWER_JS}\n</script>\n",
        cls = if full_window { "gems-full" } else { "gems-box" },
        count = kept.len(),
        note = json_str(&note),
        splats = base64(&splats),
        sh1 = base64(&sh1),
    );
    (html, kept.len())
}

/// The standalone `viewer.html`: the viewer filling the window.
pub fn viewer_page(scene: &ViewerScene, title: &str) -> String {
    let (frag, _) = viewer_fragment(scene, true);
    format!(
        "<!DOCTYPE html>\n<html><head><meta charset=\"utf-8\"><title>{}</title>\
         <style>html,body{{margin:0;height:100%;overflow:hidden;background:#000}}</style></head><body>\n{frag}</body></html>\n",
        title.replace('&', "&amp;").replace('<', "&lt;")
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_matches_rfc4648_vectors() {
        for (i, o) in [
            ("", ""),
            ("f", "Zg=="),
            ("fo", "Zm8="),
            ("foo", "Zm9v"),
            ("foob", "Zm9vYg=="),
            ("fooba", "Zm9vYmE="),
            ("foobar", "Zm9vYmFy"),
        ] {
            assert_eq!(base64(i.as_bytes()), o);
        }
    }

    #[test]
    fn splat_record_layout() {
        let mut g = Gaussians::with_degree(0);
        let mut sh = [[0.0f32; 3]; 16];
        sh[0] = [0.0, 1.0, -10.0];
        g.push(
            [1.0, 2.0, 3.0],
            [2.0, 0.0, 0.0, 0.0],
            [0.0, 1.0, -1.0],
            0.0,
            sh,
        );
        let mut out = Vec::new();
        splat_record(&g, 0, &mut out);
        assert_eq!(out.len(), 32);
        let f = |k: usize| f32::from_le_bytes(out[4 * k..4 * k + 4].try_into().unwrap());
        assert_eq!([f(0), f(1), f(2)], [1.0, 2.0, 3.0]);
        assert_eq!(f(3), 1.0);
        assert!((f(4) - 1f32.exp()).abs() < 1e-6 && (f(5) - (-1f32).exp()).abs() < 1e-6);
        // 0.5 + C0 = 0.782 → 199; sigmoid(0) = 0.5 → 128; unit quaternion (1,0,0,0) → 255,128,128,128.
        assert_eq!(&out[24..32], &[128, 199, 0, 128, 255, 128, 128, 128]);
    }

    #[test]
    fn selection_keeps_the_most_visible() {
        let mut g = Gaussians::with_degree(0);
        let sh = [[0.0f32; 3]; 16];
        // Same size and depth; opacity decides. A non-finite one is never kept.
        for (k, logit) in [-3.0f32, 2.0, 0.0, f32::NAN].iter().enumerate() {
            g.push(
                [k as f32 * 0.1, 0.0, 5.0],
                [1.0, 0.0, 0.0, 0.0],
                [-2.0; 3],
                *logit,
                sh,
            );
        }
        let cam = Camera {
            fx: 100.0,
            fy: 100.0,
            cx: 50.0,
            cy: 50.0,
            width: 100,
            height: 100,
            rotation: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            translation: [0.0; 3],
        };
        assert_eq!(select_splats(&g, &[cam], 2), vec![1, 2]);
        assert_eq!(select_splats(&g, &[cam], 10), vec![1, 2, 0]);
    }
}

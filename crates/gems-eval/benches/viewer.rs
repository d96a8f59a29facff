//! The interactive viewer's page size and load time for 100k splats (the figure):
//! builds a page of 100k random anisotropic SH-1 Gaussians, then opens it three times in headless
//! Chromium (SwiftShader WebGL2) and reads the time from navigation start to the first drawn
//! frame, which the viewer leaves in the DOM (`data-first-frame-ms`). Not a divan bench: the
//! measured work happens in the browser. `cargo bench -p gems-eval --bench viewer`.

use std::time::Instant;

use gems_eval::browser;
use gems_eval::viewer::{CameraKind, ViewerCamera, ViewerScene, viewer_page};
use gems_splat::{Camera, Gaussians};

fn main() {
    let n = 100_000;
    let mut state = 1u64;
    let mut rnd = || {
        // SplitMix64 → [0, 1).
        state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 40) as f32 / (1u64 << 24) as f32
    };
    let mut g = Gaussians::with_degree(1);
    for _ in 0..n {
        let mean = [(rnd() - 0.5) * 4.0, (rnd() - 0.5) * 3.0, 4.0 + rnd() * 4.0];
        let quat = [rnd() - 0.5, rnd() - 0.5, rnd() - 0.5, rnd() - 0.5];
        let ls = [-4.5 + rnd() * 1.5, -4.5 + rnd() * 1.5, -5.0 + rnd()];
        let mut sh = [[0.0f32; 3]; 16];
        sh[0] = [0; 3].map(|_: i32| (rnd() - 0.5) * 3.0);
        for coeffs in &mut sh[1..4] {
            *coeffs = [0; 3].map(|_: i32| (rnd() - 0.5) * 0.5);
        }
        g.push(mean, quat, ls, (rnd() - 0.3) * 6.0, sh);
    }
    let cam = Camera::look_at(
        &gems_math::Intrinsics {
            fx: 700.0,
            fy: 700.0,
            cx: 400.0,
            cy: 300.0,
            width: 800,
            height: 600,
        },
        [0.0; 3],
        [0.0, 0.0, 6.0],
        [0.0, -1.0, 0.0],
    )
    .expect("camera");
    let scene = ViewerScene {
        gaussians: g,
        cameras: vec![ViewerCamera {
            name: "view".into(),
            kind: CameraKind::Train,
            camera: cam,
            trajectory: Vec::new(),
            images: Vec::new(),
        }],
        image_files: Vec::new(),
    };
    let t = Instant::now();
    let page = viewer_page(&scene, "bench");
    let build = t.elapsed().as_secs_f64();
    let dir = tempfile::tempdir().expect("temporary folder");
    let path = dir.path().join("viewer.html");
    std::fs::write(&path, &page).expect("writing the page");
    println!(
        "{n} splats: page {:.2} MB ({} bytes), built in {:.2} s",
        page.len() as f64 / 1e6,
        page.len(),
        build
    );
    let url = browser::file_url(&path, "camera=view").expect("page URL");
    for run in 0..3 {
        let t = Instant::now();
        let dom = browser::dump_dom(&url, 800, 600, dir.path()).expect("headless Chromium");
        let wall = t.elapsed().as_secs_f64();
        let ms = dom
            .split("data-first-frame-ms=\"")
            .nth(1)
            .and_then(|s| s.split('"').next())
            .unwrap_or("(not drawn)");
        println!(
            "run {run}: first frame at {ms} ms after navigation start (browser process {wall:.2} s)"
        );
    }
}

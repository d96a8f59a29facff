//! How well the SfM's blur estimate ([`gems_init::sfm::estimate_blur_px`]) reads the blur of
//! `gems synth` scenes, whose `synth.json` holds each view's true blur (the mean image-path length
//! of the scene's probe points over the exposure, full-resolution px). Not part of CI.
//!
//! Usage: blur_eval <scene_dir>...
//! Prints per scene: the median true blur, the median estimate (what orders the SfM's working
//! sizes), the median of estimate / truth over views with truth ≥ 2 px, and the views whose
//! estimate is over 8 px when their truth is under 2 px (sharp photos read as blurred).

use gems_init::sfm::{estimate_blur_px, load_images};
use std::path::Path;

fn median(mut v: Vec<f64>) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() {
    let dirs: Vec<String> = std::env::args().skip(1).collect();
    if dirs.is_empty() {
        eprintln!("usage: blur_eval <scene_dir>...");
        std::process::exit(2);
    }
    println!("scene\ttruth_median\testimate_median\tratio_median\tsharp_read_blurred");
    for dir in dirs {
        let dir = Path::new(&dir);
        let text = std::fs::read_to_string(dir.join("synth.json")).expect("synth.json");
        let json: serde_json::Value = serde_json::from_str(&text).expect("synth.json is JSON");
        let truth: Vec<f64> = json["summary"]["blur_px"]
            .as_array()
            .expect("summary.blur_px")
            .iter()
            .map(|v| v.as_f64().expect("a number"))
            .collect();
        let images = load_images(&dir.join("images")).expect("images/");
        assert_eq!(images.len(), truth.len(), "one true blur per image");
        let est = estimate_blur_px(&images);
        let ratios: Vec<f64> = est
            .iter()
            .zip(&truth)
            .filter(|(_, t)| **t >= 2.0)
            .map(|(e, t)| e / t)
            .collect();
        let false_blur = est
            .iter()
            .zip(&truth)
            .filter(|(e, t)| **t < 2.0 && **e > 8.0)
            .count();
        for (i, (e, t)) in est.iter().zip(&truth).enumerate() {
            eprintln!("{}\t{i}\t{t:.1}\t{e:.1}", dir.display());
        }
        println!(
            "{}\t{:.1}\t{:.1}\t{:.2}\t{false_blur}",
            dir.display(),
            median(truth),
            median(est),
            median(ratios)
        );
    }
}

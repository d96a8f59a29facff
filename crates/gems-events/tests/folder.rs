//! `simulate_folder`: the three accepted layouts give the same events as feeding the simulator
//! directly with the decoded frames.

use std::path::Path;

use gems_events::{
    FrameEncoding, SimConfig, Simulator, list_frames, read_luminance, simulate_folder,
};

fn write_frames(dir: &Path, names: &[String]) {
    for (k, name) in names.iter().enumerate() {
        let img = image::GrayImage::from_fn(24, 12, |x, y| {
            image::Luma([(30 + ((x + 3 * k as u32 + y) % 8) * 28) as u8])
        });
        img.save(dir.join(name)).unwrap();
    }
}

fn direct(
    dir: &Path,
    names: &[String],
    times: &[i64],
    cfg: &SimConfig,
) -> gems_events::EventStream {
    let mut sim = Simulator::new(cfg.clone(), 24, 12).unwrap();
    for (n, &t) in names.iter().zip(times) {
        let (_, _, luma) = read_luminance(&dir.join(n), FrameEncoding::Srgb).unwrap();
        sim.feed_luma(&luma, t).unwrap();
    }
    sim.finish()
}

#[test]
fn all_layouts_match_direct_simulation() {
    let cfg = SimConfig::default();
    let times = [0i64, 1500, 3000, 4500];

    // 1. frames named by µs
    let a = tempfile::tempdir().unwrap();
    let names: Vec<String> = times.iter().map(|t| format!("{t:06}.png")).collect();
    write_frames(a.path(), &names);
    let want = direct(a.path(), &names, &times, &cfg);
    assert!(want.len() > 100);
    assert_eq!(
        simulate_folder(a.path(), &cfg, FrameEncoding::Srgb, None).unwrap(),
        want
    );

    // 2. timestamps.txt in seconds, arbitrary names
    let b = tempfile::tempdir().unwrap();
    let names_b: Vec<String> = (0..4).map(|k| format!("frame_{k}.png")).collect();
    write_frames(b.path(), &names_b);
    std::fs::write(
        b.path().join("timestamps.txt"),
        "# t name\n0.0 frame_0.png\n0.0015 frame_1.png\n0.003 frame_2.png\n0.0045 frame_3.png\n",
    )
    .unwrap();
    assert_eq!(
        simulate_folder(b.path(), &cfg, FrameEncoding::Srgb, None).unwrap(),
        want
    );

    // 3. ESIM images.csv in ns
    let c = tempfile::tempdir().unwrap();
    write_frames(c.path(), &names_b);
    std::fs::write(
        c.path().join("images.csv"),
        "0, frame_0.png\n1500000, frame_1.png\n3000000, frame_2.png\n4500000, frame_3.png\n",
    )
    .unwrap();
    assert_eq!(
        simulate_folder(c.path(), &cfg, FrameEncoding::Srgb, None).unwrap(),
        want
    );

    // timestamps.txt in µs: 1.5 ms or 1.5 s steps, and neither is its convention (s): ambiguous,
    // until the unit is given.
    std::fs::write(
        b.path().join("timestamps.txt"),
        "0 frame_0.png\n1500 frame_1.png\n3000 frame_2.png\n4500 frame_3.png\n",
    )
    .unwrap();
    let e = simulate_folder(b.path(), &cfg, FrameEncoding::Srgb, None)
        .unwrap_err()
        .to_string();
    assert!(e.contains("ambiguous") && e.contains("--time-unit"), "{e}");
    assert_eq!(
        simulate_folder(
            b.path(),
            &cfg,
            FrameEncoding::Srgb,
            Some(gems_events::TimeUnit::Microseconds)
        )
        .unwrap(),
        want
    );

    // linear decoding differs from sRGB decoding
    assert_ne!(
        simulate_folder(a.path(), &cfg, FrameEncoding::Linear, None).unwrap(),
        want
    );
}

#[test]
fn bad_folders_are_clear_errors() {
    let d = tempfile::tempdir().unwrap();
    let e = simulate_folder(d.path(), &SimConfig::default(), FrameEncoding::Srgb, None)
        .unwrap_err()
        .to_string();
    assert!(e.contains("at least 2"), "{e}");
    std::fs::write(d.path().join("timestamps.txt"), "0.0 a.png\nzero b.png\n").unwrap();
    let e = list_frames(d.path(), None).unwrap_err().to_string();
    assert!(e.contains("timestamps.txt") && e.contains("line 2"), "{e}");
    std::fs::write(
        d.path().join("timestamps.txt"),
        "0.0 a.png\n0.1 missing.png\n",
    )
    .unwrap();
    write_frames(d.path(), &["a.png".to_owned()]);
    let e = simulate_folder(d.path(), &SimConfig::default(), FrameEncoding::Srgb, None)
        .unwrap_err()
        .to_string();
    assert!(e.contains("missing.png"), "{e}");
}

//! EDI on a `gems synth` scene end to end: deblur_scene → PSNR against the sharp mid-exposure
//! ground truth → write_edi_scene → the output opens as a scene with the same views and poses.

use gems_init::edi::*;

fn psnr(a: &[f32], b: &[f32]) -> f64 {
    let mse: f64 = a
        .iter()
        .zip(b)
        .map(|(&x, &y)| f64::from(x - y).powi(2))
        .sum::<f64>()
        / a.len() as f64;
    -10.0 * mse.log10()
}

#[test]
fn synth_scene_exact_edi_beats_blurry_and_writes_a_readable_scene() {
    let dir = tempfile::tempdir().unwrap();
    let src = dir.path().join("scene");
    let synth = gems_synth::SynthConfig::tiny();
    let c = synth.events.as_ref().unwrap().threshold_pos;
    gems_synth::generate(&synth, &src).unwrap();
    let scene = gems_data::open_scene(&src, &gems_data::OpenOptions::default()).unwrap();
    // synth averages sRGB-encoded sub-frames: EDI on the stored values with exponent c/2.2
    let cfg = EdiConfig {
        thresholds: Thresholds::equal(c),
        linearisation: Linearisation::EncodedAverage(2.2),
        ..EdiConfig::default()
    };
    let edi = deblur_scene(&scene, &cfg).unwrap();
    assert_eq!(edi.views.len(), scene.views.len());
    let luma = |d: &[f32]| {
        d.chunks_exact(3)
            .map(|c| (c[0] + c[1] + c[2]) / 3.0)
            .collect::<Vec<f32>>()
    };
    let (mut p_blur, mut p_edi, mut g_blur, mut g_edi, mut n) = (0.0, 0.0, 0.0, 0.0, 0);
    for (v, e) in scene.views.iter().zip(&edi.views) {
        let Some(gt) = &v.sharp_gt else { continue };
        let gt = gems_data::load_image(gt).unwrap();
        let blurry = gems_data::load_image(&v.image).unwrap();
        p_blur += psnr(&blurry.data, &gt.data);
        p_edi += psnr(&e.frames[0].data, &gt.data);
        g_blur += psnr(&luma(&blurry.data), &luma(&gt.data));
        g_edi += psnr(&luma(&e.frames[0].data), &luma(&gt.data));
        n += 1;
    }
    let (p_blur, p_edi) = (p_blur / n as f64, p_edi / n as f64);
    let (g_blur, g_edi) = (g_blur / n as f64, g_edi / n as f64);
    eprintln!(
        "synth tiny ({n} views): RGB blurry {p_blur:.2} dB → EDI {p_edi:.2} dB ({:+.2}); gray {g_blur:.2} → {g_edi:.2} ({:+.2})",
        p_edi - p_blur,
        g_edi - g_blur
    );
    // Measured: RGB +1.3 dB, gray +2.6 dB. Far below the 8 dB hoped for: with c = 0.2 the synth
    // scene's low-contrast texture fires no events and stays blurred, and one gray exponent per
    // pixel cannot follow coloured texture (see the EDI note in the report).
    assert!(p_edi - p_blur >= 1.0, "RGB gain {:.2} dB", p_edi - p_blur);
    assert!(g_edi - g_blur >= 2.0, "gray gain {:.2} dB", g_edi - g_blur);

    let out = dir.path().join("edi");
    write_edi_scene(&scene, &edi, &out).unwrap();
    let back = gems_data::open_scene(&out, &gems_data::OpenOptions::default()).unwrap();
    assert_eq!(back.views.len(), scene.views.len());
    for (a, b) in back.views.iter().zip(&scene.views) {
        assert_eq!(a.name, b.name);
        assert_eq!(a.split, b.split);
        assert_eq!(a.pose.is_some(), b.pose.is_some());
        assert_eq!(a.sharp_gt.is_some(), b.sharp_gt.is_some());
    }
    assert!(
        back.events.stream.is_none(),
        "event data is not carried into the EDI scene"
    );
    let first = gems_data::load_image(&back.views[0].image).unwrap();
    let ours = &edi.views[0].frames[0];
    let max_err = first
        .data
        .iter()
        .zip(&ours.data)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f32::max);
    assert!(
        max_err <= 0.5 / 255.0 + 1e-6,
        "written image is the EDI frame (8-bit): {max_err}"
    );
    // never overwrites
    assert!(write_edi_scene(&scene, &edi, &out).is_err());

    // binned mode: 14 frames per view, images only
    let binned = deblur_scene(
        &scene,
        &EdiConfig {
            mode: EdiMode::Binned { bins: 13 },
            ..cfg
        },
    )
    .unwrap();
    assert!(
        binned
            .views
            .iter()
            .all(|v| v.frames.len() == 14 && v.times_us.len() == 14)
    );
    let out14 = dir.path().join("edi14");
    write_edi_scene(&scene, &binned, &out14).unwrap();
    let n_images = std::fs::read_dir(out14.join("images")).unwrap().count();
    assert_eq!(n_images, 14 * scene.views.len());
}

//! The whole pipeline through the library API on a tiny generated scene: what a library user
//! (a benchmark, another program) calls instead of the `gems` command line.

use gems_gpu::Engine;
use gems_pipeline::{Init, InitRequest, PipelineError, TrainRequest, train_scene};
use gems_train::TrainConfig;

fn request(scene: &std::path::Path, output: &std::path::Path, init: InitRequest) -> TrainRequest {
    TrainRequest {
        scene: scene.to_path_buf(),
        output: output.to_path_buf(),
        init,
        cfg: TrainConfig {
            steps: 20,
            seed: 5,
            ..TrainConfig::default()
        },
        open: gems_data::OpenOptions::default(),
        resume: false,
        evaluate: true,
        lpips: Vec::new(),
        engine: Engine::cpu(),
        progress: false,
    }
}

#[test]
fn tiny_scene_end_to_end_from_rust() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("scene");
    gems_synth::generate(&gems_synth::SynthConfig::tiny(), &scene).unwrap();
    let out = dir.path().join("run");
    let run = train_scene(request(&scene, &out, InitRequest::new(Init::Gt))).unwrap();

    assert_eq!(run.point_cloud, out.join("point_cloud.ply"));
    let g = gems_splat::ply::read_ply(&run.point_cloud).unwrap();
    assert!(!g.is_empty(), "the trained Gaussians are exported");
    assert!(out.join("model.json").is_file() && out.join("config.toml").is_file());
    let report = run.report.expect("an evaluated run writes a report");
    assert_eq!(report, out.join("report.html"));
    assert!(report.is_file());
    let metrics = run.metrics.expect("an evaluated run returns its metrics");
    assert_eq!(
        metrics,
        gems_eval::read_metrics_json(&out.join("metrics.json")).unwrap(),
        "the returned metrics are the ones written"
    );
    let deblur = metrics
        .deblur
        .expect("a generated scene has sharp ground truth");
    assert!(
        deblur.psnr.is_finite() && deblur.psnr > 5.0,
        "{}",
        deblur.psnr
    );
    assert!(metrics.ape.is_some(), "ground-truth poses give an APE");
    // Trained from the ground-truth poses: the initial poses are the truth.
    assert!(
        metrics.ape_init.unwrap().rmse < 1e-9,
        "{:?}",
        metrics.ape_init
    );
}

#[test]
fn events_with_an_initialiser_that_reads_no_images_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("scene");
    gems_synth::generate(&gems_synth::SynthConfig::tiny(), &scene).unwrap();
    let init = InitRequest {
        events: Some(gems_pipeline::EventInit {
            threshold: 0.2,
            linearisation: gems_init::edi::Linearisation::SrgbEncodedAverage,
            time_unit: None,
        }),
        ..InitRequest::new(Init::Gt)
    };
    let err = train_scene(request(&scene, &dir.path().join("run"), init)).unwrap_err();
    assert!(matches!(err, PipelineError::EventsNeedImageInit), "{err}");
    assert!(!dir.path().join("run").join("point_cloud.ply").exists());
}

#[test]
fn a_missing_scene_is_one_error_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("no-such-scene");
    let err = train_scene(request(
        &missing,
        &dir.path().join("run"),
        InitRequest::new(Init::Sfm),
    ))
    .unwrap_err();
    assert!(matches!(err, PipelineError::OpenScene { .. }), "{err}");
    assert!(err.to_string().contains("no-such-scene"), "{err}");
}

//! The one error type of a pipeline run.

use std::path::PathBuf;

/// Why a pipeline run stopped.
#[derive(Debug, thiserror::Error)]
pub enum PipelineError {
    /// The scene folder could not be opened.
    #[error("opening scene {}", path.display())]
    OpenScene {
        path: PathBuf,
        #[source]
        source: gems_data::DataError,
    },
    /// A folder could not be created.
    #[error("creating {}", path.display())]
    CreateDir {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// The scene failed validation (one line per problem, as `gems info --check` prints them).
    #[error("the scene has {} problem(s) (see `gems info --check`):\n{}", problems.len(), problems.join("\n"))]
    SceneProblems { problems: Vec<String> },
    /// The training configuration is invalid.
    #[error("invalid configuration: {0}")]
    Config(String),
    /// Events were asked for with an initialiser that does not read images.
    #[error(
        "--events deblurs the images for an initialiser that reads them: use it with --init sfm \
         (the default) or --init colmap-cli"
    )]
    EventsNeedImageInit,
    /// Events were asked for but the scene has none.
    #[error("--events: {} has no event stream or event bins", scene.display())]
    NoEvents { scene: PathBuf },
    /// The model COLMAP reconstructed could not be written.
    #[error("writing the imported COLMAP model")]
    WriteColmapModel(#[source] gems_data::DataError),
    /// `sfm_rerun/choice.json`, written by an earlier run, could not be read.
    #[error("reading {}", path.display())]
    ReadChoice {
        path: PathBuf,
        #[source]
        source: serde_json::Error,
    },
    #[error(transparent)]
    Fs(#[from] gems_fs::FsError),
    #[error(transparent)]
    Data(#[from] gems_data::DataError),
    #[error(transparent)]
    Sfm(#[from] gems_init::sfm::SfmError),
    #[error(transparent)]
    Edi(#[from] gems_init::edi::EdiError),
    #[error(transparent)]
    Train(#[from] gems_train::TrainError),
    #[error(transparent)]
    Splat(#[from] gems_splat::SplatError),
    #[error(transparent)]
    Engine(#[from] gems_gpu::GpuError),
    #[error(transparent)]
    Eval(#[from] gems_eval::EvalError),
    #[error(transparent)]
    Lpips(#[from] gems_metrics::LpipsError),
    #[error(transparent)]
    Video(#[from] gems_data::video::VideoError),
}

//! One module per subcommand; each exposes `Args` (clap) and `run`.
pub mod bench_quality;
pub mod demo;
pub mod edi;
pub mod eval;
pub mod events;
pub mod export;
pub mod info;
pub mod pipeline;
pub mod render;
pub mod sfm;
pub mod synth;
pub mod train;

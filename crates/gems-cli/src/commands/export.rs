//! `gems export`: a trained output folder, in the input frame, for other tools: its Gaussians as
//! an Inria-layout PLY or a web `.splat` file (the 32-byte record of
//! [`gems_eval::viewer::splat_record`], most visible first, as the web splat viewers expect), or
//! its trained cameras as a COLMAP model or a nerfstudio `transforms.json` ([`gems_eval::export`]).

use std::path::PathBuf;

use anyhow::Context;

/// File format of `gems export`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Format {
    /// Inria-layout Gaussian-splat PLY (SH up to the trained degree).
    Ply,
    /// antimatter15/splat `.splat`: 32 bytes per Gaussian, colour from SH degree 0.
    Splat,
    /// A COLMAP model (`sparse/0`, binary) of the trained mid-exposure cameras with the
    /// Gaussians' centres as points, and `trajectories/` (each photo's exposure, TUM).
    Colmap,
    /// nerfstudio `transforms.json` of the same cameras with the sharp mid-exposure renders as
    /// its images (`images/`), and `trajectories/`.
    Nerfstudio,
}

/// Arguments of `gems export`.
#[derive(clap::Args)]
pub struct Args {
    /// Output folder of `gems train` / `gems demo` (holds model.json + model.safetensors).
    pub output: PathBuf,
    /// File format.
    #[arg(long, value_enum)]
    pub format: Format,
    /// File (ply, splat) or folder (colmap, nerfstudio) to write; default
    /// `<output>/export.ply`, `<output>/export.splat`, `<output>/export_colmap/`,
    /// `<output>/export_nerfstudio/`.
    #[arg(short = 'o', long = "out")]
    pub file: Option<PathBuf>,
    /// Where the nerfstudio export's renders run (see `gems train --device`).
    #[arg(long, default_value = "auto")]
    pub device: gems_gpu::DeviceChoice,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let output = gems_train::TrainOutput::load(&args.output).with_context(|| {
        format!(
            "cannot read the trained result in {}",
            args.output.display()
        )
    })?;
    let file = args.file.clone().unwrap_or_else(|| {
        args.output.join(match args.format {
            Format::Ply => "export.ply",
            Format::Splat => "export.splat",
            Format::Colmap => "export_colmap",
            Format::Nerfstudio => "export_nerfstudio",
        })
    });
    match args.format {
        Format::Ply | Format::Splat => {
            let g = output
                .normalization
                .gaussians_to_input_frame(&output.gaussians);
            if args.format == Format::Ply {
                gems_splat::ply::write_ply(&file, &g)?;
            } else {
                gems_fs::write_atomic(&file, &gems_eval::viewer::splat_file(&g))
                    .with_context(|| format!("writing {}", file.display()))?;
            }
            tracing::info!(gaussians = g.len(), "wrote {}", file.display());
        }
        Format::Colmap => {
            let m = gems_eval::export::write_colmap_export(&file, &output)?;
            println!(
                "COLMAP model: {} ({} cameras, {} images, {} points)",
                file.join("sparse/0").display(),
                m.cameras.len(),
                m.images.len(),
                m.points.len()
            );
        }
        Format::Nerfstudio => {
            let mut engine = super::open_engine(args.device)?;
            let t = gems_eval::export::write_nerfstudio_export(&file, &mut engine, &output)?;
            println!(
                "nerfstudio: {} ({} frames)",
                file.join("transforms.json").display(),
                t.frames.len()
            );
        }
    }
    Ok(())
}

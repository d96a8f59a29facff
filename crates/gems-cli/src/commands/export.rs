//! `gems export`: a trained output folder's Gaussians, in the input frame, as an Inria-layout
//! PLY or a web `.splat` file (the 32-byte record of [`gems_eval::viewer::splat_record`], most
//! visible first, as the web splat viewers expect) for other viewers.

use std::path::PathBuf;

use anyhow::Context;

/// File format of `gems export`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Format {
    /// Inria-layout Gaussian-splat PLY (SH up to the trained degree).
    Ply,
    /// antimatter15/splat `.splat`: 32 bytes per Gaussian, colour from SH degree 0.
    Splat,
}

/// Arguments of `gems export`.
#[derive(clap::Args)]
pub struct Args {
    /// Output folder of `gems train` / `gems demo` (holds model.json + model.safetensors).
    pub output: PathBuf,
    /// File format.
    #[arg(long, value_enum)]
    pub format: Format,
    /// File to write (default: `<output>/export.ply` or `<output>/export.splat`).
    #[arg(short = 'o', long = "out")]
    pub file: Option<PathBuf>,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let output = gems_train::TrainOutput::load(&args.output).with_context(|| {
        format!(
            "cannot read the trained result in {}",
            args.output.display()
        )
    })?;
    let g = output
        .normalization
        .gaussians_to_input_frame(&output.gaussians);
    let file = args.file.unwrap_or_else(|| {
        args.output.join(match args.format {
            Format::Ply => "export.ply",
            Format::Splat => "export.splat",
        })
    });
    match args.format {
        Format::Ply => gems_splat::ply::write_ply(&file, &g)?,
        Format::Splat => gems_fs::write_atomic(&file, &gems_eval::viewer::splat_file(&g))
            .with_context(|| format!("writing {}", file.display()))?,
    }
    tracing::info!(gaussians = g.len(), "wrote {}", file.display());
    Ok(())
}

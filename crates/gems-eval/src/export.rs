//! Cameras out: a trained result as a COLMAP model or a nerfstudio `transforms.json`, so that it
//! goes on to gsplat, nerfstudio, Brush or a mesh tool. Both are in the scene's input frame and
//! units (the frame of the poses training started from) and hold the trained **mid-exposure**
//! camera of every training photo; the whole exposure of each photo is written beside them as
//! TUM trajectories ([`crate::write_trajectories`]).
//!
//! - [`colmap_model`]: one PINHOLE camera per distinct intrinsics, one image per training view
//!   (its name the photo's), and the trained Gaussians' centres as points (colour from SH degree
//!   0, no tracks: they were never triangulated), written with gems-data's one model writer.
//! - [`nerfstudio_transforms`]: the same cameras with OpenGL axes and per-frame intrinsics, the
//!   images being the sharp mid-exposure renders (`images/<stem>.png`).

use std::path::Path;

use gems_data::colmap::{Camera, CameraModel, Image, ModelFormat, Point3D, SparseModel};
use gems_data::nerfstudio::{CameraSpec, Frame, Transforms};
use gems_gpu::Engine;
use gems_math::{Intrinsics, Pose, Se3};
use gems_splat::sh::C0;
use gems_train::TrainOutput;

use crate::EvalError;
use crate::protocol::{file_stem, render_mid_exposure, to_input_frame};

/// The trained mid-exposure camera of every training view, in the input frame (world-to-camera)
/// with its intrinsics.
pub fn trained_cameras(output: &TrainOutput) -> Vec<(String, Intrinsics, Pose)> {
    output
        .views
        .iter()
        .map(|v| {
            let c2w = to_input_frame(output, &Se3::from(&v.mid_c2w));
            (v.name.clone(), v.intrinsics, Pose::from(&c2w.inverse()))
        })
        .collect()
}

/// The trained result as a COLMAP model (see the module docs).
pub fn colmap_model(output: &TrainOutput) -> SparseModel {
    let mut model = SparseModel::default();
    for (i, (name, k, pose)) in trained_cameras(output).into_iter().enumerate() {
        let params = vec![k.fx, k.fy, k.cx, k.cy];
        let camera_id = match model.cameras.iter().find(|c| {
            c.params == params && (c.width, c.height) == (u64::from(k.width), u64::from(k.height))
        }) {
            Some(c) => c.id,
            None => {
                let id = model.cameras.len() as u32 + 1;
                model.cameras.push(Camera {
                    id,
                    model: CameraModel::Pinhole,
                    width: u64::from(k.width),
                    height: u64::from(k.height),
                    params,
                });
                id
            }
        };
        model
            .images
            .push(Image::from_pose(i as u32 + 1, camera_id, &name, &pose));
    }
    let g = output
        .normalization
        .gaussians_to_input_frame(&output.gaussians);
    let u8c = |v: f64| (v.clamp(0.0, 1.0) * 255.0).round() as u8;
    model.points = g
        .means
        .iter()
        .zip(&g.sh)
        .filter(|(m, _)| m.iter().all(|v| v.is_finite()))
        .enumerate()
        .map(|(i, (m, sh))| Point3D {
            id: i as u64 + 1,
            xyz: m.map(f64::from),
            rgb: std::array::from_fn(|c| u8c(0.5 + C0 * f64::from(sh[0][c]))),
            error: -1.0,
            track: Vec::new(),
        })
        .collect();
    model
}

/// Writes [`colmap_model`] to `<dir>/sparse/0` (binary) and the exposure trajectories to
/// `<dir>/trajectories/`; returns the model.
pub fn write_colmap_export(dir: &Path, output: &TrainOutput) -> Result<SparseModel, EvalError> {
    let model = colmap_model(output);
    gems_data::colmap::write_model(&dir.join("sparse").join("0"), &model, ModelFormat::Binary)?;
    crate::write_trajectories(dir, output)?;
    Ok(model)
}

/// The trained cameras as nerfstudio frames whose images are `images/<stem>.png` (see the
/// module docs).
pub fn nerfstudio_transforms(output: &TrainOutput) -> Transforms {
    Transforms {
        frames: trained_cameras(output)
            .into_iter()
            .map(|(name, k, pose)| Frame {
                file_path: format!("images/{}.png", file_stem(&name)),
                pose,
                subframe_poses: Vec::new(),
                camera: CameraSpec::Pinhole(k),
                split: None,
            })
            .collect(),
    }
}

/// Writes `<dir>/transforms.json`, the sharp mid-exposure renders it names (rendered with
/// `engine`) and the exposure trajectories; returns the transforms.
pub fn write_nerfstudio_export(
    dir: &Path,
    engine: &mut Engine,
    output: &TrainOutput,
) -> Result<Transforms, EvalError> {
    let transforms = nerfstudio_transforms(output);
    let renders = render_mid_exposure(engine, output, &|_| None)?;
    for (frame, (_, image)) in transforms.frames.iter().zip(&renders) {
        gems_data::save_png(&dir.join(&frame.file_path), image)?;
    }
    gems_data::nerfstudio::write_transforms(&dir.join("transforms.json"), &transforms)?;
    crate::write_trajectories(dir, output)?;
    Ok(transforms)
}

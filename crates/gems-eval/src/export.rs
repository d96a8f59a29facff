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

/// The sharp renders of one training photo's exposure: its n virtual cameras in time order, the
/// mid-exposure camera, and their mean, the re-blurred photo the training fitted (the blur model
/// of `gems_train::render_blurred`).
pub struct ExposureBurst {
    pub intrinsics: Intrinsics,
    /// `[H,W,3]` per virtual camera, exposure start to end.
    pub frames: Vec<Vec<f32>>,
    pub mid: Vec<f32>,
    pub reblurred: Vec<f32>,
}

/// Renders [`ExposureBurst`] of training view `v` (black background, not clamped).
pub fn render_exposure_burst(
    engine: &mut Engine,
    output: &TrainOutput,
    v: usize,
) -> Result<ExposureBurst, EvalError> {
    let view = &output.views[v];
    let k = view.intrinsics;
    let cams: Vec<_> = view
        .virtual_c2w
        .iter()
        .chain(std::iter::once(&view.mid_c2w))
        .map(|p| gems_splat::Camera::from_c2w(&k, &Se3::from(p)))
        .collect();
    let out = engine.forward(
        &output.gaussians,
        &cams,
        &vec![[0.0; 3]; cams.len()],
        &gems_splat::RenderSettings::default(),
    )?;
    let px = (k.width * k.height * 3) as usize;
    let mut frames: Vec<Vec<f32>> = out.rgb.chunks_exact(px).map(<[f32]>::to_vec).collect();
    let mid = frames.pop().expect("the mid-exposure camera was rendered");
    let inv_n = 1.0 / frames.len().max(1) as f32;
    let mut reblurred = vec![0.0f32; px];
    for f in &frames {
        for (acc, x) in reblurred.iter_mut().zip(f) {
            *acc += x * inv_n;
        }
    }
    Ok(ExposureBurst {
        intrinsics: k,
        frames,
        mid,
        reblurred,
    })
}

/// For every training photo, its exposure as a burst of sharp frames: `<dir>/<stem>/<k>.png`
/// (k = 00 … n−1, exposure start to end), an animated preview `<dir>/<stem>.gif` (the burst
/// forward then back, 12 frames per second), and `<dir>/<stem>_mid.png`. Returns the number of
/// photos written.
pub fn write_bursts(
    dir: &Path,
    engine: &mut Engine,
    output: &TrainOutput,
    on_view: &mut dyn FnMut(&str),
) -> Result<usize, EvalError> {
    for (v, view) in output.views.iter().enumerate() {
        let burst = render_exposure_burst(engine, output, v)?;
        let stem = file_stem(&view.name);
        let k = burst.intrinsics;
        let image = |data: &[f32]| gems_data::ImageRgb {
            width: k.width,
            height: k.height,
            data: data.to_vec(),
        };
        for (i, f) in burst.frames.iter().enumerate() {
            gems_data::save_png(&dir.join(&stem).join(format!("{i:02}.png")), &image(f))?;
        }
        gems_data::save_png(&dir.join(format!("{stem}_mid.png")), &image(&burst.mid))?;
        let gif = dir.join(format!("{stem}.gif"));
        gems_fs::write_atomic(&gif, &animated_gif(&burst.frames, k.width, k.height, &gif)?)?;
        on_view(&view.name);
    }
    Ok(output.views.len())
}

/// A looping GIF of `frames` (`[H,W,3]` in [0, 1]) played forward then back.
fn animated_gif(
    frames: &[Vec<f32>],
    width: u32,
    height: u32,
    path: &Path,
) -> Result<Vec<u8>, EvalError> {
    use image::codecs::gif::{GifEncoder, Repeat};
    let err = |e: image::ImageError| EvalError::Format {
        path: path.to_path_buf(),
        reason: format!("encoding the GIF: {e}"),
    };
    let mut bytes = Vec::new();
    {
        let mut enc = GifEncoder::new_with_speed(&mut bytes, 10);
        enc.set_repeat(Repeat::Infinite).map_err(err)?;
        let order = (0..frames.len()).chain((1..frames.len().saturating_sub(1)).rev());
        for i in order {
            let rgba: Vec<u8> = frames[i]
                .chunks_exact(3)
                .flat_map(|p| {
                    let c = |v: f32| (v.clamp(0.0, 1.0) * 255.0).round() as u8;
                    [c(p[0]), c(p[1]), c(p[2]), 255]
                })
                .collect();
            let buf = image::RgbaImage::from_raw(width, height, rgba)
                .expect("the frame holds width × height pixels");
            let delay = image::Delay::from_numer_denom_ms(1000, 12);
            enc.encode_frame(image::Frame::from_parts(buf, 0, 0, delay))
                .map_err(err)?;
        }
    }
    Ok(bytes)
}

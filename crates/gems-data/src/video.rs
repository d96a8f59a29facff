//! Video in and out through a user-installed `ffmpeg` (and its `ffprobe`) run as a subprocess,
//! as `--init colmap-cli` runs COLMAP: gems links no codec. One module for both directions:
//! [`Ffmpeg::extract_frames`] turns a clip into a folder of numbered PNG frames with their
//! timestamps (a scene of ordered photos), [`Ffmpeg::encode`] turns numbered PNG frames into an
//! H.264 MP4. [`VideoError::Missing`] names the binary that could not be started.

use std::path::{Path, PathBuf};
use std::process::Command;

use serde::{Deserialize, Serialize};

/// File name of the frame list [`Ffmpeg::extract_frames`] writes beside the frames; a folder
/// with it holds ordered frames of one clip.
pub const FRAMES_FILE: &str = "frames.json";

/// Extensions read as video.
pub const VIDEO_EXTENSIONS: &[&str] = &["mp4", "mov", "m4v", "mkv", "avi", "webm", "mts"];

/// Whether `path` names a video file (by extension).
pub fn is_video(path: &Path) -> bool {
    path.is_file()
        && path
            .extension()
            .and_then(|e| e.to_str())
            .is_some_and(|e| VIDEO_EXTENSIONS.contains(&e.to_ascii_lowercase().as_str()))
}

/// What can go wrong with a video.
#[derive(Debug, thiserror::Error)]
pub enum VideoError {
    #[error(
        "could not start `{binary}` ({source}); install ffmpeg (e.g. `apt-get install ffmpeg`, \
         which brings ffprobe too) or pass its path with --ffmpeg"
    )]
    Missing {
        binary: PathBuf,
        source: std::io::Error,
    },
    #[error("`{binary} {step}` failed ({status}): {tail}")]
    Failed {
        binary: PathBuf,
        step: String,
        status: String,
        tail: String,
    },
    #[error("{path}: {reason}")]
    Input { path: PathBuf, reason: String },
    #[error("writing {path}: {source}")]
    Write {
        path: PathBuf,
        source: gems_fs::FsError,
    },
}

/// What ffprobe says of a clip's first video stream.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct VideoInfo {
    pub width: u32,
    pub height: u32,
    /// Frames per second of the stream.
    pub fps: f64,
    /// Duration in seconds.
    pub duration_s: f64,
}

/// One extracted frame.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FrameStamp {
    /// File name in the frames folder.
    pub name: String,
    /// Time in the clip, seconds.
    pub time_s: f64,
}

/// The frame list written beside extracted frames ([`FRAMES_FILE`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FrameList {
    /// The clip the frames come from.
    pub video: PathBuf,
    pub info: VideoInfo,
    /// Frames taken per second of the clip.
    pub rate: f64,
    /// Frames in time order (also their names' order).
    pub frames: Vec<FrameStamp>,
}

/// Reads a frames folder's [`FRAMES_FILE`], if it has one.
pub fn read_frame_list(dir: &Path) -> Option<FrameList> {
    let text = std::fs::read_to_string(dir.join(FRAMES_FILE)).ok()?;
    serde_json::from_str(&text).ok()
}

/// Views a clip gives by default: GeMS trains on 20–40 blurry photos per scene.
pub const DEFAULT_FRAMES: f64 = 40.0;

/// The frame rate that takes about [`DEFAULT_FRAMES`] frames from a clip of `info` (never more
/// than the clip has).
pub fn default_rate(info: &VideoInfo) -> f64 {
    (DEFAULT_FRAMES / info.duration_s.max(1e-3)).min(info.fps)
}

/// A user-installed ffmpeg.
#[derive(Debug, Clone)]
pub struct Ffmpeg {
    /// The `ffmpeg` executable (looked up on PATH when not absolute); `ffprobe` is taken from
    /// beside it.
    pub binary: PathBuf,
}

impl Default for Ffmpeg {
    fn default() -> Self {
        Ffmpeg {
            binary: PathBuf::from("ffmpeg"),
        }
    }
}

impl Ffmpeg {
    fn ffprobe(&self) -> PathBuf {
        self.binary.with_file_name(match self.binary.extension() {
            Some(e) => format!("ffprobe.{}", e.to_string_lossy()),
            None => "ffprobe".into(),
        })
    }

    fn run(
        &self,
        binary: &Path,
        step: &str,
        args: &[&std::ffi::OsStr],
    ) -> Result<Vec<u8>, VideoError> {
        let out =
            Command::new(binary)
                .args(args)
                .output()
                .map_err(|source| VideoError::Missing {
                    binary: binary.to_path_buf(),
                    source,
                })?;
        if !out.status.success() {
            let stderr = String::from_utf8_lossy(&out.stderr);
            let lines: Vec<&str> = stderr.lines().collect();
            return Err(VideoError::Failed {
                binary: binary.to_path_buf(),
                step: step.to_owned(),
                status: out.status.to_string(),
                tail: lines[lines.len().saturating_sub(3)..].join(" | "),
            });
        }
        Ok(out.stdout)
    }

    /// Size, frame rate and duration of the clip's first video stream.
    pub fn probe(&self, video: &Path) -> Result<VideoInfo, VideoError> {
        let input = |reason: String| VideoError::Input {
            path: video.to_path_buf(),
            reason,
        };
        let out = self
            .run(
                &self.ffprobe(),
                "(probe)",
                &[
                    "-v".as_ref(),
                    "error".as_ref(),
                    "-select_streams".as_ref(),
                    "v:0".as_ref(),
                    "-show_entries".as_ref(),
                    "stream=width,height,avg_frame_rate:format=duration".as_ref(),
                    "-of".as_ref(),
                    "json".as_ref(),
                    video.as_os_str(),
                ],
            )
            .map_err(|e| match e {
                VideoError::Failed { tail, .. } => {
                    input(format!("not a video ffprobe can read: {tail}"))
                }
                e => e,
            })?;
        let v: serde_json::Value = serde_json::from_slice(&out)
            .map_err(|e| input(format!("ffprobe's answer is not JSON: {e}")))?;
        let stream = v["streams"]
            .get(0)
            .ok_or_else(|| input("holds no video stream".into()))?;
        let rate = stream["avg_frame_rate"].as_str().unwrap_or("0/0");
        let fps = match rate.split_once('/') {
            Some((n, d)) => n.parse::<f64>().unwrap_or(0.0) / d.parse::<f64>().unwrap_or(0.0),
            None => rate.parse().unwrap_or(0.0),
        };
        let duration_s: f64 = v["format"]["duration"]
            .as_str()
            .and_then(|d| d.parse().ok())
            .unwrap_or(0.0);
        let info = VideoInfo {
            width: stream["width"].as_u64().unwrap_or(0) as u32,
            height: stream["height"].as_u64().unwrap_or(0) as u32,
            fps,
            duration_s,
        };
        if !(info.fps.is_finite() && info.fps > 0.0) || info.width == 0 || info.height == 0 {
            return Err(input(format!(
                "no frame rate or size in its video stream: {info:?}"
            )));
        }
        if !(info.duration_s.is_finite() && info.duration_s > 0.0) {
            return Err(input("the clip has no duration (zero-length clip)".into()));
        }
        Ok(info)
    }

    /// Extracts frames of `video` at `rate` frames per second (default [`default_rate`]) into
    /// `dir` as `0000.png`, `0001.png`, … in time order, and writes [`FRAMES_FILE`] with each
    /// frame's time (ffmpeg's `fps` filter takes the frame nearest to t = k / rate). Nothing is
    /// written beside the video.
    pub fn extract_frames(
        &self,
        video: &Path,
        dir: &Path,
        rate: Option<f64>,
    ) -> Result<FrameList, VideoError> {
        let info = self.probe(video)?;
        let rate = rate.unwrap_or_else(|| default_rate(&info));
        if !(rate.is_finite() && rate > 0.0) {
            return Err(VideoError::Input {
                path: video.to_path_buf(),
                reason: format!("frame rate {rate} must be positive"),
            });
        }
        std::fs::create_dir_all(dir).map_err(|source| VideoError::Write {
            path: dir.to_path_buf(),
            source: gems_fs::FsError {
                path: dir.to_path_buf(),
                source,
            },
        })?;
        let filter = format!("fps={rate}");
        let pattern = dir.join("%04d.png");
        self.run(
            &self.binary,
            "(extract frames)",
            &[
                "-v".as_ref(),
                "error".as_ref(),
                "-y".as_ref(),
                "-i".as_ref(),
                video.as_os_str(),
                "-vf".as_ref(),
                filter.as_ref(),
                "-start_number".as_ref(),
                "0".as_ref(),
                pattern.as_os_str(),
            ],
        )?;
        let mut names: Vec<String> = std::fs::read_dir(dir)
            .map_err(|e| VideoError::Input {
                path: dir.to_path_buf(),
                reason: e.to_string(),
            })?
            .filter_map(|e| e.ok()?.file_name().into_string().ok())
            .filter(|n| n.ends_with(".png"))
            .collect();
        names.sort();
        if names.len() < 2 {
            return Err(VideoError::Input {
                path: video.to_path_buf(),
                reason: format!(
                    "{} frame(s) at {rate:.3} per second; a scene needs two or more (pass a \
                     higher --fps)",
                    names.len()
                ),
            });
        }
        let list = FrameList {
            video: video.to_path_buf(),
            info,
            rate,
            frames: names
                .into_iter()
                .enumerate()
                .map(|(k, name)| FrameStamp {
                    name,
                    time_s: k as f64 / rate,
                })
                .collect(),
        };
        let path = dir.join(FRAMES_FILE);
        let json = serde_json::to_vec_pretty(&list).expect("the frame list serialises");
        gems_fs::write_atomic(&path, &json).map_err(|source| VideoError::Write { path, source })?;
        Ok(list)
    }

    /// Encodes `dir/%04d.png` (from 0000) at `fps` into the H.264 MP4 `out` (yuv420p, which
    /// every player reads; odd sizes are padded by one pixel), written atomically.
    pub fn encode(&self, dir: &Path, fps: f64, out: &Path) -> Result<(), VideoError> {
        let pattern = dir.join("%04d.png");
        let rate = format!("{fps}");
        let tmp = out.with_extension("partial.mp4");
        self.run(
            &self.binary,
            "(encode)",
            &[
                "-v".as_ref(),
                "error".as_ref(),
                "-y".as_ref(),
                "-framerate".as_ref(),
                rate.as_ref(),
                "-start_number".as_ref(),
                "0".as_ref(),
                "-i".as_ref(),
                pattern.as_os_str(),
                "-vf".as_ref(),
                "pad=ceil(iw/2)*2:ceil(ih/2)*2".as_ref(),
                "-c:v".as_ref(),
                "libx264".as_ref(),
                "-pix_fmt".as_ref(),
                "yuv420p".as_ref(),
                tmp.as_os_str(),
            ],
        )?;
        std::fs::rename(&tmp, out).map_err(|source| VideoError::Write {
            path: out.to_path_buf(),
            source: gems_fs::FsError {
                path: out.to_path_buf(),
                source,
            },
        })
    }
}

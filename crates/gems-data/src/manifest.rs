//! Scene markers written by generators and read by [`crate::open_scene`]:
//!
//! - `gems_scene.json` ([`Manifest`]): says what the pose files of a scene folder mean. A scene
//!   generator (e.g. `gems synth`) writes `{"format_version": 1, "generator": "...",
//!   "poses": "ground_truth"}` to declare that `poses_bounds.npy` holds **ground-truth**
//!   mid-exposure poses and `poses_bounds_subframes.npy` ground-truth sub-frame poses. Without a
//!   manifest, `poses_bounds.npy` is treated as estimated poses (as in BAD-Gaussians/LLFF data).
//! - `hold=<n>`: an empty file whose *name* carries the hold-out interval (BAD-Gaussians/PRISM3D
//!   convention): view `i` (sorted by file name) with `i % n == 0` is a novel-view test view;
//!   `n < 1` means no hold-out.

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::error::{DataError, Result};
use crate::fsutil::read_text;

/// File name of the scene manifest.
pub const MANIFEST_FILE: &str = "gems_scene.json";

/// The current manifest format version.
pub const MANIFEST_VERSION: u32 = 1;

/// What the LLFF pose files of a scene hold.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ManifestPoses {
    /// Exact poses of the generator (synthetic scenes): usable as ground truth for APE.
    GroundTruth,
    /// Poses estimated by some tool (COLMAP, VGGSfM, ...).
    Estimated,
}

/// Contents of `gems_scene.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Manifest {
    /// Must be [`MANIFEST_VERSION`].
    pub format_version: u32,
    /// Free text naming the tool that wrote the scene (e.g. `"gems synth 0.1.0"`).
    pub generator: String,
    /// Meaning of `poses_bounds.npy` / `poses_bounds_subframes.npy`.
    pub poses: ManifestPoses,
    /// Optional free-form description (preset, seed, blur strength ...).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub description: Option<String>,
}

impl Manifest {
    /// A manifest declaring ground-truth poses, written by scene generators.
    pub fn ground_truth(generator: impl Into<String>) -> Manifest {
        Manifest {
            format_version: MANIFEST_VERSION,
            generator: generator.into(),
            poses: ManifestPoses::GroundTruth,
            description: None,
        }
    }
}

/// Writes `dir/gems_scene.json` atomically.
pub fn write_manifest(dir: &Path, manifest: &Manifest) -> Result<()> {
    let path = dir.join(MANIFEST_FILE);
    let mut text = serde_json::to_string_pretty(manifest)
        .map_err(|e| DataError::format(&path, e.to_string()))?;
    text.push('\n');
    Ok(gems_fs::write_atomic(&path, text.as_bytes())?)
}

/// Reads `dir/gems_scene.json` if it exists.
pub fn read_manifest(dir: &Path) -> Result<Option<Manifest>> {
    let path = dir.join(MANIFEST_FILE);
    if !path.is_file() {
        return Ok(None);
    }
    let m: Manifest = serde_json::from_str(&read_text(&path)?)
        .map_err(|e| DataError::format(&path, e.to_string()))?;
    if m.format_version != MANIFEST_VERSION {
        return Err(DataError::Unsupported {
            path,
            msg: format!(
                "manifest format_version {} (this build reads {MANIFEST_VERSION})",
                m.format_version
            ),
        });
    }
    Ok(Some(m))
}

/// Creates the marker file `dir/hold=<n>`, removing any other `hold=*` marker first so the
/// folder never holds two conflicting values.
pub fn write_hold_marker(dir: &Path, hold: i64) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(|e| DataError::io(dir, e))?;
    for (path, _) in hold_markers(dir)? {
        if path.file_name() != Some(std::ffi::OsStr::new(&format!("hold={hold}"))) {
            std::fs::remove_file(&path).map_err(|e| DataError::io(&path, e))?;
        }
    }
    Ok(gems_fs::write_atomic(
        &dir.join(format!("hold={hold}")),
        b"",
    )?)
}

/// The value of the `hold=<n>` marker in `dir`, if there is one.
pub fn read_hold_marker(dir: &Path) -> Result<Option<i64>> {
    let markers = hold_markers(dir)?;
    match markers.as_slice() {
        [] => Ok(None),
        [(path, value)] => value.map(Some).ok_or_else(|| {
            DataError::format(
                path,
                "hold marker must be named hold=<integer>, e.g. hold=8",
            )
        }),
        [(a, _), (b, _), ..] => Err(DataError::format(
            dir,
            format!(
                "two hold markers ({} and {}); keep one",
                a.display(),
                b.display()
            ),
        )),
    }
}

fn hold_markers(dir: &Path) -> Result<Vec<(std::path::PathBuf, Option<i64>)>> {
    let rd = std::fs::read_dir(dir).map_err(|e| DataError::io(dir, e))?;
    let mut out = Vec::new();
    for entry in rd {
        let entry = entry.map_err(|e| DataError::io(dir, e))?;
        let name = entry.file_name();
        if let Some(v) = name.to_str().and_then(|n| n.strip_prefix("hold=")) {
            out.push((entry.path(), v.trim().parse().ok()));
        }
    }
    out.sort();
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn manifest_and_hold_round_trip() {
        let dir = tempfile::tempdir().unwrap();
        assert_eq!(read_manifest(dir.path()).unwrap(), None);
        let mut m = Manifest::ground_truth("test");
        m.description = Some("seed 3".into());
        write_manifest(dir.path(), &m).unwrap();
        assert_eq!(read_manifest(dir.path()).unwrap(), Some(m));
        let text = std::fs::read_to_string(dir.path().join(MANIFEST_FILE)).unwrap();
        assert!(text.contains("\"poses\": \"ground_truth\""), "{text}");

        assert_eq!(read_hold_marker(dir.path()).unwrap(), None);
        write_hold_marker(dir.path(), 8).unwrap();
        assert_eq!(read_hold_marker(dir.path()).unwrap(), Some(8));
        write_hold_marker(dir.path(), 0).unwrap();
        assert_eq!(read_hold_marker(dir.path()).unwrap(), Some(0));
        std::fs::write(dir.path().join("hold=5"), b"").unwrap();
        let e = read_hold_marker(dir.path()).unwrap_err().to_string();
        assert!(e.contains("two hold markers"), "{e}");
    }

    #[test]
    fn bad_manifests_name_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join(MANIFEST_FILE);
        std::fs::write(
            &p,
            "{\"format_version\": 1, \"generator\": \"x\", \"poses\": \"guess\"}",
        )
        .unwrap();
        let e = read_manifest(dir.path()).unwrap_err().to_string();
        assert!(e.contains(MANIFEST_FILE) && e.contains("guess"), "{e}");
        std::fs::write(
            &p,
            "{\"format_version\": 9, \"generator\": \"x\", \"poses\": \"estimated\"}",
        )
        .unwrap();
        let e = read_manifest(dir.path()).unwrap_err().to_string();
        assert!(e.contains("format_version 9"), "{e}");
        std::fs::remove_file(&p).unwrap();
        std::fs::write(dir.path().join("hold=x"), b"").unwrap();
        let e = read_hold_marker(dir.path()).unwrap_err().to_string();
        assert!(e.contains("hold=x"), "{e}");
    }
}

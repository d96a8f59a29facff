//! The published evaluation protocols by name (`--protocol`): the image scale, hold-out, steps,
//! initialisation and held-out posing each dataset's tables were made with, so that a gems
//! figure can stand beside them. Facts and sources: Deblur-NeRF's configs
//! (`limacv/Deblur-NeRF:configs/`), ExBluRF's (`taekkii/ExBluRF`), E2NeRF's loaders
//! (`iCVTEAM/E2NeRF`) and the GeMS/PRISM3D training script (`GopiRajuMatta/PRISM3D:train.sh`).
//!
//! Every protocol's evaluation reports held-out views both ways: at the dataset's pose carried
//! into the result's initial frame (what the NeRF-era tables do: they render at the COLMAP
//! poses) and
//! after test-time pose refinement (BAD-Gaussians, GeMS). [`Protocol::headline`] says which of
//! the two the protocol's own table prints.

use std::path::Path;

use crate::init::Init;

/// A published protocol.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
pub enum Protocol {
    /// Deblur-NeRF's real camera-motion scenes: ×4 (`images_4/`, 600×400), every 7th view held
    /// out (per scene: 6–8), poses from the dataset's COLMAP run (which included the sharp test
    /// views), test views rendered at those poses.
    DeblurNerfReal,
    /// Deblur-NeRF's synthetic scenes: full size (600×400), every 8th view held out, the
    /// dataset's poses, test views at their given poses.
    DeblurNerfSynthetic,
    /// ExBluRF: ×2, the per-scene hold (bench 7, camellia 7, dragon 8, jars 7, jars2 5, postbox
    /// 6, stone_lantern 9, sunflowers 9; its synthetic scenes 8), the dataset's poses; its test
    /// views are registered into the learned frame, which refinement stands for here.
    Exblurf,
    /// E2NeRF: full size, the dataset's split (synthetic: its test frames) and poses, test views
    /// at their given poses.
    E2nerf,
    /// GeMS / PRISM3D: ×2 (about 400×270 on ExBluRF), the scene's `hold=` (else 8), poses from
    /// the blurry photos themselves (here the built-in SfM), held-out views after 100 steps of
    /// test-time pose refinement.
    Gems,
}

/// Which held-out figure a protocol's own table prints.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Headline {
    /// At the dataset's pose, carried into the result's initial frame, no refinement.
    DatasetPose,
    /// After test-time pose refinement.
    Refined,
}

/// What a protocol sets. Anything the user gives explicitly wins.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ProtocolSettings {
    pub downscale: u32,
    /// Hold-out interval; `None`: the scene decides (its `hold=` marker or its split files).
    pub hold: Option<i64>,
    pub steps: usize,
    pub init: Init,
    pub headline: Headline,
}

/// Deblur-NeRF's real scenes' `llffhold` (`limacv/Deblur-NeRF:configs/demo_blur*.txt`).
const DEBLUR_NERF_REAL_HOLDS: &[(&str, i64)] = &[
    ("ball", 7),
    ("basket", 7),
    ("buick", 7),
    ("coffee", 6),
    ("decoration", 6),
    ("girl", 7),
    ("heron", 8),
    ("parterre", 6),
    ("puppet", 6),
    ("stair", 6),
];

/// ExBluRF's per-scene `llffhold` (`taekkii/ExBluRF:configs/`).
const EXBLURF_HOLDS: &[(&str, i64)] = &[
    ("bench", 7),
    ("camellia", 7),
    ("dragon", 8),
    ("jars", 7),
    ("jars2", 5),
    ("postbox", 6),
    ("stone_lantern", 9),
    ("sunflowers", 9),
];

/// GeMS trains 7000 steps (paper §4; `PRISM3D:train.sh`); the other protocols' methods train
/// their own schedules, and gems runs its own at the paper's length.
const PAPER_STEPS: usize = 7000;

impl Protocol {
    /// The name `--protocol` takes.
    pub fn name(self) -> &'static str {
        match self {
            Protocol::DeblurNerfReal => "deblur-nerf-real",
            Protocol::DeblurNerfSynthetic => "deblur-nerf-synthetic",
            Protocol::Exblurf => "exblurf",
            Protocol::E2nerf => "e2nerf",
            Protocol::Gems => "gems",
        }
    }

    /// The protocol's settings for the scene in `root`: a scene's own `hold=` marker is the
    /// dataset's value and wins over the tables here, which name the scenes by folder (a
    /// `blur` prefix, as in `blurball`, is ignored).
    pub fn settings(self, root: &Path) -> ProtocolSettings {
        let has_marker = gems_data::manifest::read_hold_marker(root)
            .ok()
            .flatten()
            .is_some();
        let folder = root
            .file_name()
            .map(|n| n.to_string_lossy().to_ascii_lowercase())
            .unwrap_or_default();
        let scene = folder.strip_prefix("blur").unwrap_or(&folder);
        let table = |t: &[(&str, i64)], default: i64| {
            (!has_marker).then(|| {
                t.iter()
                    .find(|(n, _)| *n == scene)
                    .map_or(default, |(_, h)| *h)
            })
        };
        let (downscale, hold, init, headline) = match self {
            Protocol::DeblurNerfReal => (
                4,
                table(DEBLUR_NERF_REAL_HOLDS, 7),
                Init::Colmap,
                Headline::DatasetPose,
            ),
            Protocol::DeblurNerfSynthetic => (
                1,
                (!has_marker).then_some(8),
                Init::Colmap,
                Headline::DatasetPose,
            ),
            Protocol::Exblurf => (2, table(EXBLURF_HOLDS, 8), Init::Colmap, Headline::Refined),
            Protocol::E2nerf => (1, None, Init::Colmap, Headline::DatasetPose),
            Protocol::Gems => (2, None, Init::Sfm, Headline::Refined),
        };
        ProtocolSettings {
            downscale,
            hold,
            steps: PAPER_STEPS,
            init,
            headline,
        }
    }
}

impl std::fmt::Display for Protocol {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn holds_come_from_the_scene_marker_else_the_per_scene_tables() {
        let dir = tempfile::tempdir().unwrap();
        let ball = dir.path().join("blurball");
        let girl = dir.path().join("girl");
        let unknown = dir.path().join("mine");
        for d in [&ball, &girl, &unknown] {
            std::fs::create_dir_all(d).unwrap();
        }
        let s = Protocol::DeblurNerfReal.settings(&ball);
        assert_eq!((s.downscale, s.hold, s.init), (4, Some(7), Init::Colmap));
        assert_eq!(s.headline, Headline::DatasetPose);
        assert_eq!(Protocol::DeblurNerfReal.settings(&unknown).hold, Some(7));
        let jars2 = dir.path().join("jars2");
        std::fs::create_dir_all(&jars2).unwrap();
        let s = Protocol::Exblurf.settings(&jars2);
        assert_eq!(
            (s.downscale, s.hold, s.headline),
            (2, Some(5), Headline::Refined)
        );
        // The scene's own marker wins (gems-data reads it).
        gems_data::write_hold_marker(&girl, 3).unwrap();
        assert_eq!(Protocol::DeblurNerfReal.settings(&girl).hold, None);
        let s = Protocol::Gems.settings(&unknown);
        assert_eq!(
            (s.downscale, s.hold, s.init, s.steps),
            (2, None, Init::Sfm, 7000)
        );
        assert_eq!(
            Protocol::DeblurNerfSynthetic.settings(&unknown).hold,
            Some(8)
        );
    }
}

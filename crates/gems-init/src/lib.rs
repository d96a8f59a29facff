//! Initialisation: camera poses and sparse points from blurry images (built-in structure from
//! motion), and event-based double-integral (EDI) deblurring that feeds it.
//!
//! The SfM entry points are [`sfm::run_sfm`] (images → [`sfm::SfmResult`]),
//! [`sfm::write_outputs`] (COLMAP `sparse/0`, `sfm_report.json`, top-view PNG) and
//! [`sfm::run_colmap_cli`] (a user-installed COLMAP as a subprocess, for `--init colmap-cli`).

pub mod edi;
pub mod sfm;

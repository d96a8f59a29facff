//! The scene data layer of gems: views, splits, intrinsics, poses and sparse models read from the
//! layouts our users hold (GeMS/BAD-Gaussians/PRISM3D, COLMAP, LLFF, ExBluRF, nerfstudio).

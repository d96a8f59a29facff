//! Differentiable 3D Gaussian splatting on the CPU.
//!
//! Scene types (structure of arrays), pinhole cameras (OpenCV, world-to-camera), a batched
//! forward renderer and its backward pass including gradients for each camera pose, a slow f64
//! reference renderer that the fast path is tested against, and Inria-layout PLY.

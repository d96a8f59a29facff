//! SE(3)/SO(3)/Sim(3) maths and camera trajectories for gems.
//!
//! Poses are world-to-camera or camera-to-world as each function says; the camera frame is OpenCV
//! (x right, y down, z forward). Tangent vectors in se(3) are ordered translation first, then rotation.

//! Initialisation: camera poses and sparse points from blurry images (built-in structure from
//! motion), and event-based double-integral (EDI) deblurring that feeds it.

//! Evaluation and export: deblurring and novel-view metrics, test-time pose refinement, APE,
//! trajectories and the HTML report.

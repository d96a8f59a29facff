//! GeMS training: per-image exposure trajectories, the physical blur model, losses, Adam and
//! 3DGS-MCMC densification, jointly optimised.

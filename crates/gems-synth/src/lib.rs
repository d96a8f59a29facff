//! `gems synth`: procedural extreme-blur scenes with perfect ground truth.

//! Event-camera streams: one columnar type, readers for the common file formats, and an
//! ESIM-style simulator that turns timestamped sharp frames into events.

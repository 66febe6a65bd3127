//! # spiv-firmware-sim — the spike camera, simulated, and its files
//!
//! | module | owns |
//! |---|---|
//! | [`scene`] | the scene in front of the camera: flows, particles, glare, ground truth |
//! | [`sensor`] | the integrate-and-fire spike sensor and the frame camera |
//! | [`simulation`] | one scene through both cameras, in memory or as files (`spiv simulate`) |
//! | [`formats`] | the camera's files: `.dat`, `.npz`, `scene.json`, images, CSVs, and the size limits of every reader |
//! | [`firmware`] | the sidecar firmware loop around `spiv-core`, its links and fault injection |
//! | [`buffers`] | owned buffers for the core on the host |
//! | [`cli`] | what the two binaries share on the command line |
//!
//! So every test of spiv runs without hardware. Data flows one way: scene →
//! light → sensor → packed spike planes → `spiv-core`.
#![warn(missing_docs)]

pub mod buffers;
pub mod cli;
pub mod firmware;
pub mod formats;
pub mod scene;
pub mod sensor;
pub mod simulation;

//! # spiv-firmware-sim — the spike camera, simulated, and its files
//!
//! The scene in front of the camera ([`scene`]: flows, particles, glare), the
//! sensors that look at it ([`sensor`]: the integrate-and-fire spike sensor
//! and the frame camera), and the camera's files ([`formats`]), so every
//! test of spiv runs without hardware. Data flows one way: scene → light →
//! sensor → packed spike planes → `spiv-core`.
#![warn(missing_docs)]

pub mod buffers;
pub mod cli;
pub mod firmware;
pub mod formats;
pub mod scene;
pub mod sensor;
pub mod simulation;

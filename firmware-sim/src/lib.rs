//! # spiv-firmware-sim — the spike camera, simulated
//!
//! The scene in front of the camera ([`scene`]: flow, particles, glare), the
//! sensors that look at it ([`sensor`]: the integrate-and-fire spike sensor),
//! so every test of spiv runs without hardware. Data flows one way: scene →
//! light → sensor → packed spike planes → `spiv-core`.
#![warn(missing_docs)]

pub mod scene;
pub mod sensor;

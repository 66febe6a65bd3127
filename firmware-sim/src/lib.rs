//! # spiv-firmware-sim — the spike camera and its sidecar, simulated
//!
//! | module | owns |
//! |---|---|
//! | [`scene`] | the scene in front of the camera: flows, particles, glare, ground truth |
//! | [`sensor`] | the integrate-and-fire spike sensor and the frame camera |
//! | [`simulation`] | one scene through both cameras, in memory or as files (`spiv simulate`) |
//! | [`meta`] | `scene.json` of a simulated recording: the layout (`spiv_formats::capture`) and the scene that made it |
//! | [`downlink`] | the host's control bytes, read on a thread with faults injected, heard between planes; optional pacing |
//! | [`firmware`] | the simulated sidecar: the core's loop (`spiv_core::sidecar`) over owned buffers, its links, fault injection and drivers |
//! | [`ladder`] | the simulated sidecar's live loop of the time ladder: pairs as the asks heard say, up the link |
//! | [`error`] | the crate's one error type, [`Error`] |
//! | [`cli`] | what the two binaries share on the command line |
//!
//! So every test of spiv runs without hardware. Data flows one way: scene →
//! light → sensor → packed spike planes → `spiv-core`.
#![warn(missing_docs)]

pub mod downlink;
pub mod drive;
pub mod error;
pub mod firmware;
pub mod ladder;
pub mod meta;
pub mod scene;
pub mod sensor;
pub mod simulation;

pub use error::Error;

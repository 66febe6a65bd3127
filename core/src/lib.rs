//! # spiv-core — the sidecar half of spike-camera PIV
//!
//! `#![no_std]`, no allocator, no panics on any input. Everything a sidecar MCU or
//! FPGA next to a spike sensor must do to turn 1-bit spike planes into particle
//! frames that suit PIV (Li et al. 2025, read as `docs/spec.md` §5 fixes it):
//!
//! | module | owns |
//! |---|---|
//! | [`plane`] | zero-copy view of one bit-packed Vidar spike plane |
//! | [`history`] | the ingest: a ring of the last `depth` planes of a band of rows |
//! | [`window`] | centred windows, bit-parallel window counts, TFP and TFI |
//! | [`method`] | how a frame is made: adaptive, TFP, TFI, and its wire code |
//! | [`motion`] | motion compensation: counting along a predicted path, refining the prediction by contrast maximisation |
//! | [`light`] | each pixel's static light predicted from its own spikes, and the innovation events it did not predict |
//! | [`warp`] | frames of warped events: each event added where a steady flow carries it at the frame's time |
//! | [`rungs`] | what a pair of the time ladder needs: the last ticks' events in a ring, and the rung frames warped along the host's flow |
//! | [`particle`] | the particle test against the local background, exact, with per-frame tables |
//! | [`slices`] | bit-sliced window counts: 64 pixels' counters as eight bit planes |
//! | [`segment`] | saturation time `t_bgmax` and particle/background segmentation |
//! | [`label`] | 8-connected region labelling with a bounded region table |
//! | [`region`] | one particle region: size, bounding box, ring, adaptive window |
//! | [`integrate`] | per-region SNR(n) and the optimal window n* |
//! | [`suppress`] | background suppression `alpha = beta / t_bgmax` |
//! | [`frame`] | one adaptive frame at any tick, in row strips |
//! | `context` | what every strip of one frame shares (crate-private) |
//! | [`gray`] | the output pixel type: 8- or 16-bit gray levels |
//! | [`downlink`] | the host's control messages heard, checked, held and applied per pair |
//! | [`sidecar`] | the sidecar loop over borrowed memory: planes in, scheduled frames out through the sender; the dwell cap |
//! | `buffers` | owned buffers of the history, the workspace and the loop (`std` feature) |
//! | `pairs` | the live loop's sidecar state over owned buffers: light model, event ring, the asks heard, each pair made or sent (`std` feature; `spiv flow` and the simulated sidecar run it) |
//! | `training` | the light the static-light model is trained on before a recording's first plane: slow particles trained on their background (`std` feature) |
//! | [`state`] | the caller-owned per-pixel working memory |
//! | [`q`] | the fixed-point formats, in one place |
//! | [`wire`] | the sidecar link: message header, COBS framing, CRC, stream decoder, tile codecs (`wire::codec`), the sender (`wire::sender`) |
//!
//! Units: time in **ticks** (one spike plane), space in **pixels** of the
//! camera's stored row order (the Vidar layout stores image rows bottom-up: the
//! core never flips, file readers do), counts in **spikes**, output in **gray
//! levels** of an 8- or 16-bit frame.
//!
//! Memory is bounded by the caller: the spike history and the per-pixel state
//! are slices the caller provides (static arrays on a sidecar, `Vec`s on a
//! host), sized by [`history::History::words_needed`] and
//! [`state::WorkspaceSizes`].
#![cfg_attr(not(any(test, feature = "std")), no_std)]
#![warn(missing_docs)]
#[cfg(feature = "std")]
extern crate std;

#[cfg(feature = "std")]
pub mod buffers;
mod context;
pub mod downlink;
pub mod error;
pub mod frame;
pub mod gray;
pub mod history;
pub mod integrate;
pub mod label;
pub mod light;
pub mod method;
pub mod motion;
#[cfg(feature = "std")]
pub mod pairs;
pub mod params;
pub mod particle;
pub mod plane;
pub mod q;
pub mod region;
pub mod rungs;
pub mod segment;
pub mod sidecar;
pub mod slices;
pub mod state;
pub mod suppress;
#[cfg(test)]
mod testing;
#[cfg(feature = "std")]
pub mod training;
pub mod warp;
pub mod window;
pub mod wire;

pub use error::Error;
pub use frame::{reconstruct_adaptive, reconstruct_compensated, reconstruct_rows, FrameStats};
pub use gray::Gray;
pub use history::History;
pub use method::Method;
pub use params::Params;
pub use plane::PlaneView;
pub use state::{Workspace, WorkspaceSizes};

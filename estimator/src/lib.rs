//! # spiv-estimator — a pair's flow from the spikes around it
//!
//! The estimator behind `spiv flow`, over what the sidecar's core makes of
//! a stream of spike planes (`spiv_core::pairs`): its innovation events
//! and the rung frames it warps along the flow known so far.
//!
//! | module | owns |
//! |---|---|
//! | [`events`] | the spikes as the core's innovation events — spikes less what each pixel's own static light predicts — and the frames the core's warp makes of them |
//! | [`compensate`] | the flows frames follow: per pixel ([`Velocity`], px per tick) and on the core's node grid ([`WarpFlow`]) |
//! | [`ladder`] | the time ladder: disjoint compensated frames at growing separations, PIV on each, the most certain vector per node |
//! | [`ensemble`] | where window PIV cannot start the ladder, the dense stage's one flow fitted to every pair of consecutive short frames, each pair's disagreement with it the uncertainty |
//! | [`joint`] | a pair's dense flow refined by one steady flow fitted to every short frame around it at once, along its own paths |
//! | [`units`] | ticks, px per tick and px per pair as types: [`units::Ticks`], [`units::PerTick`], [`units::PerPair`] |
//! | [`error`] | the crate's one error type, [`Error`] |
//! | [`control`] | the loop between pairs: what the next pair is made with (the ask), from what the estimator measured |
//!
//! Units: time in ticks (one spike plane), space in pixels of the upright
//! image (x right, y down the rows); at the boundary they are types
//! ([`units`]): a [`ladder::measure`] takes its `dt` as [`units::Ticks`]
//! and reports a [`units::PerPair`], and the flow a pair follows is a
//! [`units::PerTick`]; a [`Velocity`] is in px per tick. Errors: one
//! type, [`Error`] (the PIV engine's, or an ask the wire cannot carry).
#![warn(missing_docs)]

pub mod compensate;
pub mod control;
pub mod ensemble;
pub mod error;
pub mod events;
pub mod joint;
pub mod ladder;
pub mod units;

pub use compensate::{Velocity, WarpFlow};
pub use error::Error;
pub use events::Events;
pub use ladder::{measure, LadderSettings, Measurement, PairInput};

//! The flow estimator on the host: a pair's 2-D flow measured from the spikes
//! themselves, over as many planes as the recording holds around it. The
//! estimator is the `spiv-estimator` crate, re-exported here; `make` and
//! `uplink` feed it the core's pairs from a recording or a wire.
//!
//! - [`events`]: the spikes as the core's innovation events — spikes less
//!   what each pixel's own static light predicts — and the frames the
//!   core's warp makes of them;
//! - [`compensate`]: the flows frames follow, per pixel and on the core's
//!   node grid;
//! - [`make`]: what the core makes of a stream of planes, in process —
//!   the sidecar's static-light model and event ring, and each pair's
//!   input as the estimator asked;
//! - [`ladder`]: disjoint compensated frames at growing separations, PIV
//!   on each, the most certain vector per node;
//! - [`control`]: the loop between pairs — what the next pair is made
//!   with, from what the estimator measured;
//! - [`uplink`]: what a pair's frames and events cost on the wire;
//! - [`ensemble`]: where window PIV cannot start the ladder, the dense
//!   stage's one flow fitted to every pair of consecutive short frames,
//!   each pair's disagreement with it the uncertainty;
//! - [`joint`]: a pair's dense flow refined by one steady flow fitted to
//!   every short frame around it at once, along its own paths.

pub use spiv_estimator::{compensate, control, ensemble, events, joint, ladder, units};
pub mod make;
pub mod uplink;

pub use spiv_estimator::{
    measure, Events, LadderSettings, Measurement, PairInput, Velocity, WarpFlow,
};

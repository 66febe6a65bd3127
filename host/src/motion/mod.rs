//! The host's motion estimate: a pair's 2-D flow measured from the spikes
//! themselves, over as many planes as the recording holds around it.
//!
//! - [`spikes`]: the spikes as each pixel's innovation — spikes less what
//!   its own static light predicts;
//! - [`compensate`]: innovation summed along predicted paths;
//! - [`ladder`]: disjoint compensated frames at growing separations, PIV
//!   on each, the most certain vector per node;
//! - [`ensemble`]: where window PIV cannot start the ladder, the dense
//!   stage's one flow fitted to every pair of consecutive short frames,
//!   each pair's disagreement with it the uncertainty.

pub mod compensate;
pub mod ensemble;
pub mod ladder;
pub mod spikes;

pub use compensate::{compensated, Velocity};
pub use ladder::{measure, measure_from, LadderSettings, Measurement};
pub use spikes::Innovation;

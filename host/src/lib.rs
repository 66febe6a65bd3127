//! # spiv-host — the host half of spiv
//!
//! | module | owns |
//! |---|---|
//! | [`receive`] | byte sources (USB, TCP, pipe, file), the stream decoder, frame reassembly within a size limit, pairing, loss counts |
//! | [`downlink`] | the host's end of the control link: each received pair's PIV as the next pair's predicted motion |
//! | [`link`] | the sidecar link in process: the firmware loop's messages through the receiver |
//! | [`reconstruct`] | frames from spike files (`.dat`, `.npz`) through the core: TFP, TFI, adaptive |
//! | [`reference`](mod@reference) | the `f64` reference of the core's algorithm, and its tolerance |
//! | [`baseline`] | the wide baseline: a second compensated pair several pair separations apart, centred on the pair, kept per vector where the flow allows |
//! | [`piv`] | the PIV engine (the `spiv-piv` crate, usable alone), stage by stage: `filter`, `resample`, `deform`, `correlate`, `peak`, `validate` |
//! | [`dwell`] | the dwell cap: window limits per band from a predicted field, and the banded adaptive frame |
//! | [`flow`] | the main job on any spike recording (`spiv flow`): each pair measured by the time ladder ([`estimator`]) or, by `--method`, from plain frames through the core; the mean field, glare, outputs' orientation |
//! | [`estimator`] | the flow estimator (the `spiv-estimator` crate, re-exported: the time ladder and the dense ensemble) and what feeds it the core's pairs from a recording or a wire |
//! | [`live`] | the live closed loop: frames from a sidecar, PIV on each pair, the motion sent back |
//! | [`simulate`] | a simulation as a user asks for it, its sizes bounded |
//! | [`error`] | the crate's one error type, [`Error`] |
//! | [`units`] | a recording's calibration: px per pair to m/s |
//! | [`predict`] | the prediction of motion-compensated frames: a field as row velocities, refined in the core, and the compensated frame |
//! | [`pipeline`] | the main job (`spiv run`): scene → both cameras → sidecar → PIV → metrics |
//! | [`metrics`] | the paper's row-profile RMAE / RMSE and confidence intervals |
//! | [`report`] | what a run tells its user: tables, `summary.json`, plots |
//! | [`bench`](mod@bench) | the benchmarks' experiments: speed against error, the sidecar link |
//!
//! `link`, `simulate`, `pipeline` and `bench`, and the run report's
//! `report::summary` and `report::table`, run the simulated camera: they
//! and the `spiv` binary need the `sim` feature (on by default). `usb`
//! (on by default) adds the USB receiver. Without them the library is the
//! receivers, `spiv flow`'s estimator, PIV and the flow reports — what the
//! Python package builds.
//!
//! The `spiv` binary's subcommands live in `cli`, one file each.
#![warn(missing_docs)]

pub mod baseline;
#[cfg(feature = "sim")]
pub mod bench;
pub mod downlink;
pub mod dwell;
pub mod error;
pub mod estimator;
pub mod flow;
#[cfg(feature = "sim")]
pub mod link;
pub mod live;
pub mod metrics;
#[cfg(feature = "sim")]
pub mod pipeline;
pub use spiv_piv as piv;
pub mod predict;
pub mod receive;
pub mod reconstruct;
pub mod reference;
pub mod report;
#[cfg(feature = "sim")]
pub mod simulate;
pub mod units;

pub use error::Error;

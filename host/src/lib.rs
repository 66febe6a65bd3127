//! # spiv-host — the host half of spiv
//!
//! Frames from spike files through the core ([`reconstruct`]), owned buffers
//! for the no_std core ([`core_run`]), and the `f64` reference of the core's
//! algorithm ([`reference`]). The `spiv` binary's subcommands live in `cli`.
#![warn(missing_docs)]

pub mod core_run;
pub mod link;
pub mod metrics;
pub mod pipeline;
pub mod piv;
pub mod plot;
pub mod receive;
pub mod reconstruct;
pub mod reference;

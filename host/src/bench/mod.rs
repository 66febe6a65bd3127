//! The benchmarks' experiments (`spiv bench speed`, `spiv bench link`):
//! each returns its rows; the CLI prints them.

pub mod link;
pub mod speed;
pub mod turbulence;

//! The benchmarks' experiments (`spiv bench paper`, `blasius`, `speed`,
//! `link`, `turbulence`, `flows`, `live`):
//! each returns its rows; the CLI prints them.

pub mod flows;
pub mod link;
pub mod live;
pub mod paper;
pub mod speed;
pub mod turbulence;

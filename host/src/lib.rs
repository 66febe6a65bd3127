//! spiv-host: the host half of spiv.
pub mod reference;

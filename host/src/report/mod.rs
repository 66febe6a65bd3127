//! What a run tells its user: the tables it prints ([`table`]), its
//! `summary.json` ([`summary`]) and its plots ([`plot`]); a flow run's
//! files ([`flow`], with [`netcdf`]).

pub mod flow;
pub mod movie;
pub mod netcdf;
pub mod plot;
#[cfg(feature = "sim")]
pub mod summary;
#[cfg(feature = "sim")]
pub mod table;

use std::path::Path;

/// What a flow run was asked, for `summary.json` and `flow.nc`.
#[derive(Debug, Clone, Copy)]
pub struct RunInfo<'a> {
    /// The recording's path as given.
    pub input: &'a Path,
    /// Planes in the recording.
    pub planes: u64,
    /// Wall time of the run, s.
    pub seconds: f64,
    /// The command line that made the run (netCDF `history`).
    pub command: &'a str,
}

//! What a run tells its user: the tables it prints ([`table`]), its
//! `summary.json` ([`summary`]) and its plots ([`plot`]); a flow run's
//! files ([`flow`], with [`netcdf`]).

pub mod flow;
pub mod netcdf;
pub mod plot;
pub mod summary;
pub mod table;

//! What a run tells its user: the tables it prints ([`table`]), its
//! `summary.json` ([`summary`]) and its plots ([`plot`]); a flow run's
//! files ([`flow`]).

pub mod flow;
pub mod plot;
pub mod summary;
pub mod table;

//! The `spiv` command line: one file per subcommand.

pub mod bench;
pub mod bench_link;
pub mod piv;
pub mod receive;
pub mod reconstruct;
pub mod run;
pub mod simulate;

/// An error the CLI prints as one line before exiting non-zero.
#[derive(Debug, thiserror::Error)]
pub enum CliError {
    /// Reading or writing a file.
    #[error(transparent)]
    Format(#[from] spiv_firmware_sim::formats::FormatError),
    /// Making a frame.
    #[error(transparent)]
    Reconstruct(#[from] spiv_host::reconstruct::ReconstructError),
    /// PIV.
    #[error(transparent)]
    Piv(#[from] spiv_host::piv::PivError),
    /// The main job.
    #[error(transparent)]
    Job(#[from] spiv_host::pipeline::JobError),
    /// Receiving from a sidecar.
    #[error(transparent)]
    Source(#[from] spiv_host::receive::SourceError),
    /// A bad option value.
    #[error("{0}")]
    Usage(String),
}

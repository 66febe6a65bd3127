//! The `spiv` command line: one file per subcommand.

pub mod piv;
pub mod reconstruct;
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
    /// A bad option value.
    #[error("{0}")]
    Usage(String),
}

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
    Format(#[from] spiv_formats::FormatError),
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

/// A progress bar for long work: `what`, the bar, position/length, time.
fn bar(len: u64, what: &str) -> indicatif::ProgressBar {
    let b = indicatif::ProgressBar::new(len);
    b.set_style(
        indicatif::ProgressStyle::with_template(&format!(
            "{what} {{bar:30}} {{pos}}/{{len}} {{elapsed}}"
        ))
        .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    b
}

//! The `spiv` command line: one file per subcommand, each thin argument
//! parsing over library calls; the option parsers they share live here.

use spiv_firmware_sim::scene::{SceneKind, SceneParams};

pub mod bench;
pub mod bench_link;
pub mod flow;
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
    /// PIV.
    #[error(transparent)]
    Piv(#[from] spiv_host::piv::PivError),
    /// The host library: a frame, a flow, the main job, a source, the
    /// live loop.
    #[error(transparent)]
    Host(#[from] spiv_host::Error),
    /// The simulated camera or sidecar.
    #[error(transparent)]
    Sim(#[from] spiv_firmware_sim::Error),
    /// A bad option value.
    #[error("{0}")]
    Usage(String),
    /// Stopped by Ctrl-C (exit status 130); what was done is said.
    #[error("{0}")]
    Interrupted(String),
}

/// A flag Ctrl-C sets (SIGINT, and SIGTERM, on the first press; the
/// second press ends the process at once): long jobs poll it between
/// pairs, keep what they measured and stop.
pub fn interrupt() -> Result<&'static std::sync::atomic::AtomicBool, CliError> {
    use std::sync::atomic::{AtomicBool, Ordering};
    static STOP: AtomicBool = AtomicBool::new(false);
    static SET: std::sync::Once = std::sync::Once::new();
    let mut failed = None;
    SET.call_once(|| {
        if let Err(e) = ctrlc::set_handler(|| {
            if STOP.swap(true, Ordering::SeqCst) {
                std::process::exit(130);
            }
        }) {
            failed = Some(e.to_string());
        }
    });
    match failed {
        Some(e) => Err(CliError::Usage(format!("cannot catch Ctrl-C: {e}"))),
        None => Ok(&STOP),
    }
}

/// Parses `--encoding`.
pub fn parse_encoding(v: &str) -> Result<spiv_core::wire::Encoding, CliError> {
    spiv_core::wire::Encoding::from_name(v).ok_or_else(|| {
        CliError::Usage(format!(
            "--encoding {v}: expected rice, context, sparse, sparse-context or raw"
        ))
    })
}

/// Parses `--dwell-cap`: px, or "off".
pub fn parse_dwell_cap(v: &str) -> Result<Option<f64>, CliError> {
    if v == "off" {
        return Ok(None);
    }
    match v.parse::<f64>() {
        Ok(c) if c.is_finite() && c > 0.0 && c <= 1000.0 => Ok(Some(c)),
        _ => Err(CliError::Usage(format!(
            "--dwell-cap {v}: expected px in (0, 1000] or off"
        ))),
    }
}

/// Parses a scene name into its defaults.
pub fn scene_params(name: &str) -> Result<SceneParams, CliError> {
    let kind = SceneKind::parse(name).map_err(|e| CliError::Usage(e.to_string()))?;
    Ok(SceneParams::new(kind))
}

/// A progress bar for long work: `what`, the bar, position/length, time.
fn bar(len: u64, what: &str) -> indicatif::ProgressBar {
    let b = indicatif::ProgressBar::new(len);
    b.set_style(
        indicatif::ProgressStyle::with_template(&format!(
            "{what} {{bar:30}} {{pos}}/{{len}} {{elapsed}}, {{eta}} left"
        ))
        .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    b
}

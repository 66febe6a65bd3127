//! `spiv`: particle image velocimetry with spike cameras.

mod cli;

use clap::{Parser, Subcommand};

#[derive(Debug, Parser)]
#[command(
    name = "spiv",
    version,
    about = "Particle image velocimetry with spike cameras"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Simulate a scene through the spike sensor and the frame camera.
    Simulate(cli::simulate::SimulateArgs),
    /// Make one frame from a spike file at any tick (adaptive, TFP or TFI).
    Reconstruct(cli::reconstruct::ReconstructArgs),
    /// PIV on an image pair: multi-pass FFT correlation with deformation.
    Piv(cli::piv::PivArgs),
}

fn main() {
    let cli = Cli::parse();
    let result = match &cli.command {
        Command::Simulate(a) => cli::simulate::run(a),
        Command::Reconstruct(a) => cli::reconstruct::run(a),
        Command::Piv(a) => cli::piv::run(a),
    };
    if let Err(e) = result {
        eprintln!("spiv: error: {e}");
        std::process::exit(1);
    }
}

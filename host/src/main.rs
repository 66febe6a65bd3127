//! `spiv`: particle image velocimetry with spike cameras.

mod cli;

/// mimalloc instead of the system allocator: PIV, the simulator and the
/// receiver allocate image-sized buffers per pair, and glibc hands those
/// back to the kernel on free, so every pair paid fresh page faults (8 % of
/// a 400×250 PIV run on one thread); mimalloc keeps and reuses its pages.
#[global_allocator]
static GLOBAL: mimalloc::MiMalloc = mimalloc::MiMalloc;

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
    /// The main job: a scene through both cameras, the core and PIV; the
    /// paper's table, images, vectors, plots and summary.json.
    Run(cli::run::RunArgs),
    /// Benchmarks: the paper's tables over seeds, Blasius, speed against error.
    Bench(cli::bench::BenchArgs),
    /// Simulate a scene through the spike sensor and the frame camera.
    Simulate(cli::simulate::SimulateArgs),
    /// The main job on any spike recording (.dat, .npz): each pair's flow
    /// measured from the spikes around it (motion-compensated frames over
    /// growing separations, PIV on each), vectors with uncertainties, plots.
    Flow(cli::flow::FlowArgs),
    /// Make one frame from a spike file at any tick (adaptive, TFP or TFI).
    Reconstruct(cli::reconstruct::ReconstructArgs),
    /// PIV on an image pair: multi-pass FFT correlation with deformation.
    Piv(cli::piv::PivArgs),
    /// Receive frames from a sidecar (USB, TCP, pipe or file); write them, run PIV.
    Receive(cli::receive::ReceiveArgs),
}

fn main() {
    let cli: Cli = spiv_args::parse_or_exit("spiv");
    let result = match &cli.command {
        Command::Run(a) => cli::run::run(a),
        Command::Simulate(a) => cli::simulate::run(a),
        Command::Bench(a) => cli::bench::run(a),
        Command::Reconstruct(a) => cli::reconstruct::run(a),
        Command::Flow(a) => cli::flow::run(a),
        Command::Piv(a) => cli::piv::run(a),
        Command::Receive(a) => cli::receive::run(a),
    };
    match result {
        Ok(()) => {}
        Err(e @ cli::CliError::Interrupted(_)) => {
            eprintln!("spiv: {e}");
            std::process::exit(130);
        }
        Err(e) => {
            eprintln!("spiv: error: {e}");
            std::process::exit(1);
        }
    }
}

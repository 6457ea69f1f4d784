//! `simbench`: the command-line harness of the shape-from-heat-conduction suite.
//!
//! It parses arguments, loads scene files, calls `heatsim` / `heatrecon`, and writes results.
//! No numerics live here. All quantities are SI (metres, seconds, kelvin, watts).

mod cmd;

use clap::{Parser, Subcommand};
use std::process::ExitCode;

#[derive(Parser)]
#[command(
    name = "simbench",
    version,
    about = "Simulator and benchmark for shape from heat conduction (SI units throughout)"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Time the volumetric solver's phases (assembly, factorisation, substitution, one step)
    /// in one run and print their ratios.
    BenchSolver(cmd::bench_solver::Args),
    /// Mesh a scene's object with TetGen: writes mesh.vtu, surface.obj, visible.obj and
    /// mesh_stats.json to --out, and prints the statistics as JSON.
    Mesh(cmd::mesh::Args),
    /// Simulate a scene: node temperatures at every frame, the visible surface's temperatures,
    /// a ParaView time series and a metadata JSON with timings and the energy balance.
    Simulate(cmd::simulate::Args),
    /// Print the JSON Schema of scene files (for editor completion).
    Schema(cmd::schema::Args),
    /// Run a solver side by side with an independent peer (scikit-fem + SciPy) on the same
    /// mesh: prints both times, the speedup and the largest difference as JSON; fails when
    /// the temperatures differ by more than 1e-6 of the temperature rise.
    Peer(cmd::peer::Args),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::BenchSolver(a) => cmd::bench_solver::run(a),
        Command::Mesh(a) => cmd::mesh::run(a),
        Command::Schema(a) => cmd::schema::run(a),
        Command::Simulate(a) => cmd::simulate::run(a),
        Command::Peer(a) => cmd::peer::run(a),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

//! `simbench`: the command-line harness of the shape-from-heat-conduction suite.
//!
//! It parses arguments, loads scene files, calls `heatsim` / `heatrecon`, and writes results:
//! meshing, simulation, reconstruction, scoring, sweeps, result tables and the frozen benchmark
//! suite, one subcommand each (`docs/reference/cli.md` lists them all). No numerics live here.
//! All quantities are SI (metres, seconds, kelvin, watts).
//!
//! ```text
//! simbench simulate scenes/tour.json --out tour/data
//! simbench reconstruct tour/data/left tour/data/right --out tour/paper --diffusivity material
//! simbench eval --recon tour/paper/recon_world.obj --gt tour/data/left/gt_mesh.obj
//! ```

mod cmd;
mod docs;
mod figure;
mod suite;
mod sweep;
mod table;

use clap::{CommandFactory, Parser, Subcommand};
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
    /// Time the whole reconstruction per stage and pyramid level at several camera sizes of one
    /// scene (filmed with the surface solver), with the time per vertex and frame.
    BenchRecon(cmd::bench_recon::Args),
    /// Time the surface solver (paper Eq. 6) on a camera-sized pixel-grid surface: one step
    /// against one substitution, and a whole 15 s run at 6 fps.
    BenchSurface(cmd::bench_surface::Args),
    /// Mesh a scene's object with TetGen: writes mesh.vtu, surface.obj, visible.obj and
    /// mesh_stats.json to --out, and prints the statistics as JSON.
    Mesh(cmd::mesh::Args),
    /// Simulate a scene on our TetGen mesh and on an independent fTetWild mesh of the same
    /// solid: prints the video and volume differences as JSON; fails above 1 % of the mean
    /// temperature rise or 0.5 % of the volume.
    MeshIndependence(cmd::mesh_independence::Args),
    /// Simulate a scene: node temperatures at every frame, the visible surface's temperatures,
    /// a ParaView time series and a metadata JSON with timings and the energy balance.
    Simulate(cmd::simulate::Args),
    /// Score a reconstruction against a ground-truth surface: JSON with the mean closest-point
    /// distance (mae_mm, the paper's metric), the reverse and symmetric means, RMSE, 95th
    /// percentile, normal error and the ICP alignment.
    Eval(cmd::eval::Args),
    /// Reconstruct the shape from thermal videos (paper Sec. 5 and 6; `--stage 1`: the
    /// Laplacian, fluxes, C and h only), configured by a preset, a config file and `--set`:
    /// writes the shape (recon.obj, recon_world.obj, depth.npy, normals.npy), stage 1's files
    /// and config.json to --out; --check compares with simulated ground truth.
    Reconstruct(Box<cmd::reconstruct::Args>),
    /// Print the JSON Schema of scene files (for editor completion), or with `dataset` of a
    /// dataset directory's JSON files.
    Schema(cmd::schema::Args),
    /// Run a solver side by side with an independent peer (scikit-fem + SciPy) on the same
    /// mesh: prints both times, the speedup and the largest difference as JSON; fails when
    /// the temperatures differ by more than 1e-6 of the temperature rise.
    Peer(cmd::peer::Args),
    /// Parameter sweeps; `sweep thickness` reproduces the paper's Fig. 2 (CSVs, plots,
    /// summary.md in --out, one JSON per cell, resumable and shardable).
    Sweep(cmd::sweep::Args),
    /// Join the outputs of `sweep ... --shard K/N` runs and write the tables, plots and summary.
    Merge(cmd::merge::Args),
    /// Result tables; `table shape-error RUN` writes the paper's Table 2 and Fig. 4 from a suite
    /// run (CSV, Markdown).
    Table(cmd::table::Args),
    /// The frozen benchmark suite: `build` it once, `verify` it, `run` any method on it.
    Suite(cmd::suite::Args),
    /// Write the generated reference (command line, scene and dataset formats, the
    /// reconstruction's configuration) as Markdown to --out (default docs/reference).
    Docs(cmd::docs::Args),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::BenchSolver(a) => cmd::bench_solver::run(a),
        Command::BenchSurface(a) => cmd::bench_surface::run(a),
        Command::BenchRecon(a) => cmd::bench_recon::run(a),
        Command::Eval(a) => cmd::eval::run(a),
        Command::Mesh(a) => cmd::mesh::run(a),
        Command::MeshIndependence(a) => cmd::mesh_independence::run(a),
        Command::Reconstruct(a) => cmd::reconstruct::run(*a),
        Command::Schema(a) => cmd::schema::run(a),
        Command::Simulate(a) => cmd::simulate::run(a),
        Command::Peer(a) => cmd::peer::run(a),
        Command::Sweep(a) => cmd::sweep::run(a),
        Command::Merge(a) => cmd::merge::run(a),
        Command::Table(a) => cmd::table::run(a),
        Command::Suite(a) => cmd::suite::run(a),
        Command::Docs(a) => cmd::docs::run(a, Cli::command()),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

//! `simbench schema [scene|recon-config]`: the JSON Schema of scene files (the default) or of
//! the reconstruction's configuration (`heatrecon::ReconConfig`).

use anyhow::Context;
use std::path::PathBuf;

/// Which file format's schema.
#[derive(Clone, Copy, clap::ValueEnum)]
pub enum What {
    /// Scene files (`scenes/*.json`).
    Scene,
    /// The reconstruction's configuration (`simbench reconstruct --config`, a run's config.json).
    ReconConfig,
}

#[derive(clap::Args)]
pub struct Args {
    /// The format.
    #[arg(value_enum, default_value = "scene")]
    what: What,
    /// Write the schema to this file instead of standard output.
    #[arg(long)]
    out: Option<PathBuf>,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let schema = match args.what {
        What::Scene => heatsim::scene::json_schema(),
        What::ReconConfig => heatrecon::config::json_schema(),
    };
    let text = serde_json::to_string_pretty(&schema)? + "\n";
    match args.out {
        Some(path) => {
            heatsim::io::write_atomic(&path, text.as_bytes()).with_context(|| format!("writing {}", path.display()))
        }
        None => {
            print!("{text}");
            Ok(())
        }
    }
}

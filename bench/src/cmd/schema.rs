//! `simbench schema [scene|dataset|recon-config]`: the JSON Schema of scene files (the default),
//! of a dataset directory's JSON files, or of the reconstruction's configuration
//! (`heatrecon::ReconConfig`).

use anyhow::Context;
use std::path::PathBuf;

/// Which files the schema describes.
#[derive(Clone, Copy, Default, clap::ValueEnum)]
pub enum What {
    /// Scene files (`scenes/*.json`, the input of `simulate`).
    #[default]
    Scene,
    /// The JSON files of a dataset directory (`camera.json`, `lamps.json`, `environment.json`,
    /// `material.json`, `meta.json`), as one object keyed by file name.
    Dataset,
    /// The reconstruction's configuration (`simbench reconstruct --config`, a run's config.json).
    ReconConfig,
}

#[derive(clap::Args)]
pub struct Args {
    /// What to describe.
    #[arg(value_enum, default_value_t = What::Scene)]
    what: What,
    /// Write the schema to this file instead of standard output.
    #[arg(long)]
    out: Option<PathBuf>,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let schema = match args.what {
        What::Scene => heatsim::scene::json_schema(),
        What::Dataset => heatsim::dataset_format::json_schema(),
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

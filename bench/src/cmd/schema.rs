//! `simbench schema`: the JSON Schema of scene files.

use anyhow::Context;
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct Args {
    /// Write the schema to this file instead of standard output.
    #[arg(long)]
    out: Option<PathBuf>,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let text = serde_json::to_string_pretty(&heatsim::scene::json_schema())? + "\n";
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

//! `simbench merge DIR... --out DIR`: joins the outputs of `simbench sweep thickness --shard`
//! runs and writes the tables, plots and summary (see [`crate::sweep::merge`]).

use std::path::PathBuf;

#[derive(clap::Args)]
pub struct Args {
    /// Output directories of the shards (each with plan.json and cells/).
    #[arg(required = true)]
    dirs: Vec<PathBuf>,
    /// Where the joined cells, CSVs, plots and summary go (may be one of the shards).
    #[arg(long)]
    out: PathBuf,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    crate::sweep::merge::merge(&args.dirs, &args.out)?;
    println!("merge: tables, plots and summary.md in {}", args.out.display());
    Ok(())
}

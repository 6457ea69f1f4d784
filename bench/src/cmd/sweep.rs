//! `simbench sweep thickness`: the paper's Fig. 2 (see [`crate::sweep`]).

use std::path::PathBuf;

use anyhow::Context;

use crate::sweep::cells::{Plan, Shape, MATERIALS};
use crate::sweep::run::{run_sweep, RunOptions, Shard};

#[derive(clap::Args)]
pub struct Args {
    #[command(subcommand)]
    kind: Kind,
}

#[derive(clap::Subcommand)]
enum Kind {
    /// Thickness sweep (paper Fig. 2): the volumetric video against thickness (part 1) and the
    /// surface approximation against the volumetric truth (part 2). Writes one JSON per cell
    /// to DIR/cells, then the CSVs, plots (PNG, SVG) and summary.md.
    Thickness(ThicknessArgs),
}

#[derive(clap::Args)]
pub struct ThicknessArgs {
    /// Fewer thicknesses, coarser meshes, same code paths (about a minute).
    #[arg(long)]
    quick: bool,
    /// Output directory.
    #[arg(long, default_value = "results/thickness")]
    out: PathBuf,
    /// Skip cells whose result exists with the same configuration hash.
    #[arg(long)]
    resume: bool,
    /// Cells run in parallel (default: the number of cores).
    #[arg(long)]
    jobs: Option<usize>,
    /// Run only the K-th of N deterministic parts of the cell list (cluster job arrays);
    /// join the parts with `simbench merge`.
    #[arg(long, default_value = "1/1")]
    shard: Shard,
    /// Materials, comma-separated (default: polystyrene,steel,glass,brick).
    #[arg(long, value_delimiter = ',')]
    materials: Option<Vec<String>>,
    /// Shapes of part 2, comma-separated (default: cuboid,hemisphere,bunny).
    #[arg(long, value_delimiter = ',', value_enum)]
    shapes: Option<Vec<Shape>>,
    /// Cache of meshes and reference videos (default: DIR/cache).
    #[arg(long)]
    cache: Option<PathBuf>,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let Kind::Thickness(a) = args.kind;
    let materials = a.materials.unwrap_or_else(|| MATERIALS.iter().map(|s| s.to_string()).collect());
    let shapes = a.shapes.unwrap_or_else(|| Shape::ALL.to_vec());
    let plan = Plan::new(a.quick, materials, shapes)?;
    let jobs = match a.jobs {
        Some(0) => anyhow::bail!("--jobs: must be at least 1, got 0"),
        Some(j) => j,
        None => std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1),
    };
    let cache = a.cache.unwrap_or_else(|| a.out.join(crate::sweep::CACHE_DIR));
    let opts = RunOptions { plan, out: a.out.clone(), cache, resume: a.resume, jobs, shard: a.shard };
    let report = run_sweep(&opts)?;
    println!(
        "sweep: ran {} cells, skipped {} (already done), {:.1} s wall",
        report.ran, report.skipped, report.wall_seconds
    );
    if a.shard.n == 1 {
        crate::sweep::merge::finalize(&a.out).with_context(|| format!("summarising {}", a.out.display()))?;
        println!("sweep: tables, plots and summary.md in {}", a.out.display());
    } else {
        println!(
            "sweep: shard {}/{} done; join the shards with `simbench merge DIR... --out DIR`",
            a.shard.k, a.shard.n
        );
    }
    Ok(())
}

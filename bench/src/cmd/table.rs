//! `simbench table shape-error [--quick] [--out DIR] [--resume] [--jobs N]`: the shape-error
//! table (paper Table 2 and Fig. 4; see `crate::table`), and `simbench table objects --out DIR`:
//! the generated objects as OBJ with their analytic volumes.

use std::path::PathBuf;

use anyhow::Context;
use serde_json::json;

use crate::table::objects::Revolved;
use crate::table::report;

#[derive(clap::Args)]
pub struct Args {
    #[command(subcommand)]
    which: Which,
}

#[derive(clap::Subcommand)]
enum Which {
    /// The paper's Table 2 from a suite run: shape_error.csv and shape_error.md, one row per
    /// object and noise level (medians over seeds) beside the paper's numbers.
    ShapeError(ShapeErrorArgs),
    /// Write the generated objects (ball, soda can, two bottles; the untuned vase and twisted
    /// spindle) as OBJ, with a JSON of their analytic volumes (m^3) and sizes (m).
    Objects(ObjectsArgs),
}

#[derive(clap::Args)]
struct ShapeErrorArgs {
    /// A complete suite run (`simbench suite run`), e.g. of the full tier with `--method
    /// builtin:paper`.
    run: PathBuf,
    /// Output directory.
    #[arg(long, default_value = "results/shape_error")]
    out: PathBuf,
}

#[derive(clap::Args)]
struct ObjectsArgs {
    /// Output directory.
    #[arg(long)]
    out: PathBuf,
    /// Outline spacing, m.
    #[arg(long, default_value_t = 0.5e-3)]
    spacing: f64,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    match args.which {
        Which::ShapeError(a) => shape_error(a),
        Which::Objects(a) => objects(a),
    }
}

fn shape_error(a: ShapeErrorArgs) -> anyhow::Result<()> {
    let (csv, md) = report::table(&a.run)?;
    std::fs::create_dir_all(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
    heatsim::io::write_atomic(&a.out.join("shape_error.csv"), csv.as_bytes()).context("writing shape_error.csv")?;
    heatsim::io::write_atomic(&a.out.join("shape_error.md"), md.as_bytes()).context("writing shape_error.md")?;
    print!("{csv}");
    eprintln!("table: wrote {}", a.out.display());
    Ok(())
}

fn objects(a: ObjectsArgs) -> anyhow::Result<()> {
    anyhow::ensure!(
        a.spacing.is_finite() && a.spacing > 1e-5 && a.spacing <= 0.01,
        "--spacing must be in (1e-5, 0.01] m, got {}",
        a.spacing
    );
    let mut out = heatsim::io::OutputDir::new(&a.out).with_context(|| format!("preparing {}", a.out.display()))?;
    let mut list = Vec::new();
    for r in Revolved::ALL {
        let mesh = r.mesh(a.spacing)?;
        let (lo, hi) = mesh.bounding_box();
        let file = format!("{}.obj", r.name());
        out.write_with(&file, |w| {
            heatsim::mesh::write_obj_to(w, &mesh, &format!("{}: generated object, axis x, metres", r.name()))
        })?;
        let p = r.profile();
        let s = r.section();
        list.push(json!({
            "name": r.name(), "file": file,
            "analytic_volume_m3": r.analytic_volume(),
            "section": { "lobes": s.lobes, "eccentricity": s.eccentricity, "twist_rad": s.twist },
            "mesh_volume_m3": mesh.signed_volume(),
            "length_m": p.length(), "max_radius_m": p.max_radius(),
            "bbox_min_m": lo, "bbox_max_m": hi,
            "vertices": mesh.verts.len(), "triangles": mesh.tris.len(),
        }));
    }
    let text = serde_json::to_string_pretty(&json!({ "spacing_m": a.spacing, "objects": list }))? + "\n";
    out.write_bytes("objects.json", text.as_bytes())?;
    out.commit().with_context(|| format!("writing {}", a.out.display()))?;
    print!("{text}");
    Ok(())
}

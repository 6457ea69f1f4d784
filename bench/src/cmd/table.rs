//! `simbench table shape-error [--quick] [--out DIR] [--resume] [--jobs N]`: the shape-error
//! table (paper Table 2 and Fig. 4; see `crate::table`), and `simbench table objects --out DIR`:
//! the generated objects as OBJ with their analytic volumes.

use std::path::PathBuf;

use anyhow::Context;
use serde_json::json;

use crate::table::cells::{plan, Object, Setup};
use crate::table::objects::Revolved;
use crate::table::{report, run};

#[derive(clap::Args)]
pub struct Args {
    #[command(subcommand)]
    which: Which,
}

#[derive(clap::Subcommand)]
enum Which {
    /// Simulate, reconstruct and score the paper's objects: shape_error.csv, shape_error.md,
    /// renders/*.png, one JSON record per row in cells/ (resumable).
    ShapeError(ShapeErrorArgs),
    /// Write the generated objects (ball, soda can, two bottles; the untuned vase and twisted
    /// spindle) as OBJ, with a JSON of their analytic volumes (m^3) and sizes (m).
    Objects(ObjectsArgs),
}

#[derive(clap::Args)]
struct ShapeErrorArgs {
    /// Small camera (160 x 128), 20 s videos, five rows: about 2 minutes.
    #[arg(long)]
    quick: bool,
    /// Output directory.
    #[arg(long, default_value = "results/shape_error")]
    out: PathBuf,
    /// Skip rows whose record says ok with the same configuration hash.
    #[arg(long)]
    resume: bool,
    /// Rows run at the same time (each child process uses every core).
    #[arg(long, default_value_t = 1)]
    jobs: usize,
    /// Only these objects (comma-separated: ball, soda_can, bottle_1, bottle_2, hemisphere, bunny;
    /// the untuned vase and twisted_spindle, not in the default rows, only when named here).
    #[arg(long, value_delimiter = ',')]
    objects: Vec<String>,
    /// Arguments for `simbench reconstruct` after the datasets and --out (one string, split at
    /// whitespace).
    #[arg(long, default_value = "--stage 2", allow_hyphen_values = true)]
    reconstruct_args: String,
    /// Wall-clock limit of each simulate or reconstruct child process, s.
    #[arg(long, default_value_t = 1800.0)]
    timeout: f64,
    /// Keep the videos in work/ (otherwise removed after each row).
    #[arg(long)]
    keep_work: bool,
    /// Run nothing: rewrite shape_error.csv and shape_error.md from the stored row records.
    #[arg(long, conflicts_with = "resume")]
    report_only: bool,
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
    anyhow::ensure!(a.jobs >= 1, "--jobs must be at least 1, got {}", a.jobs);
    anyhow::ensure!(a.timeout.is_finite() && a.timeout > 0.0, "--timeout must be > 0 s, got {}", a.timeout);
    if a.out.exists() && !a.out.is_dir() {
        anyhow::bail!("--out {}: exists and is not a directory", a.out.display());
    }
    let objects: Vec<Object> = a.objects.iter().map(|s| Object::parse(s)).collect::<anyhow::Result<_>>()?;
    let rows = plan(a.quick, &objects);
    anyhow::ensure!(!rows.is_empty(), "--objects {} selects no row of this plan", a.objects.join(","));
    let setup = Setup::new(a.quick, a.reconstruct_args.split_whitespace().map(String::from).collect());
    let exe = std::env::current_exe().context("locating the simbench executable")?;
    let opts = run::Options {
        rows,
        setup,
        out: a.out.clone(),
        resume: a.resume,
        jobs: a.jobs,
        timeout_s: a.timeout,
        keep_work: a.keep_work,
        exe,
        report_only: a.report_only,
    };
    let (records, rep) = run::run(&opts)?;
    let csv = report::csv(&records);
    heatsim::io::write_atomic(&a.out.join("shape_error.csv"), csv.as_bytes()).context("writing shape_error.csv")?;
    let source = git_describe();
    let wall = (!a.report_only).then_some(rep.wall_seconds);
    let mut md = report::markdown(&records, &opts.setup, wall);
    if !a.report_only {
        md.push_str(&format!(
            "Source at run time (`git describe --always --dirty` in the working directory): `{source}`.\n"
        ));
    }
    heatsim::io::write_atomic(&a.out.join("shape_error.md"), md.as_bytes()).context("writing shape_error.md")?;
    let failed = records.iter().filter(|r| r["status"] != "ok").count();
    let run_json = json!({
        "quick": a.quick, "jobs": a.jobs, "ran": rep.ran, "skipped": rep.skipped,
        "failed_this_run": rep.failed, "failed_rows": failed, "git_describe": source,
        "wall_seconds": rep.wall_seconds,
    });
    if !a.report_only {
        heatsim::io::write_atomic(
            &a.out.join("run.json"),
            (serde_json::to_string_pretty(&run_json)? + "\n").as_bytes(),
        )?;
    }
    print!("{csv}");
    eprintln!(
        "table: {} rows ran, {} skipped; {} of {} rows failed (recorded in the CSV); {:.1} s; wrote {}",
        rep.ran,
        rep.skipped,
        failed,
        records.len(),
        rep.wall_seconds,
        a.out.display()
    );
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

/// `git describe --always --dirty` of the working directory, or "unknown" (the numbers of the
/// table depend on the reconstruction code of the moment).
fn git_describe() -> String {
    std::process::Command::new("git")
        .args(["describe", "--always", "--dirty"])
        .output()
        .ok()
        .filter(|o| o.status.success())
        .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string())
        .unwrap_or_else(|| "unknown".into())
}

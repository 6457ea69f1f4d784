//! `simbench mesh SCENE --out DIR`: the tetrahedral mesh of a scene's object.

use anyhow::Context;
use heatsim::mesh::obj::write_obj_to;
use heatsim::mesh::tetmesh::FaceTag;
use heatsim::mesh::vtu::{write_vtu, Cells, DataArray};
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct Args {
    /// Scene file (JSON; see `simbench schema`).
    scene: PathBuf,
    /// Output directory; files appear there only once everything succeeded.
    #[arg(long)]
    out: PathBuf,
    /// Override the object's thickness (m): the material below the visible surface.
    #[arg(long)]
    thickness: Option<f64>,
    /// Use this Stanford bunny OBJ instead of the cached download (also: HEATSIM_BUNNY).
    #[arg(long)]
    bunny: Option<PathBuf>,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let scene = super::load_scene(&args.scene, args.thickness)?;
    eprintln!("simbench: meshing {} ({}) ...", args.scene.display(), scene.object.kind());
    let meshed = heatsim::meshing::mesh_scene(&scene, args.bunny.as_deref())
        .with_context(|| format!("meshing the object of {}", args.scene.display()))?;
    let mesh = &meshed.mesh;
    let report = &meshed.report;
    eprintln!(
        "simbench: {} nodes, {} tetrahedra, min dihedral {:.1} deg, TetGen {:.2} s",
        report.stats.nodes, report.stats.tetrahedra, report.stats.min_dihedral_deg, report.tetgen_seconds
    );

    let mut out =
        heatsim::io::OutputDir::new(&args.out).with_context(|| format!("preparing {}", args.out.display()))?;
    let region: Vec<i32> = mesh.tet_region.clone();
    // Node height z (m): a handy colouring in ParaView.
    let z: Vec<f64> = mesh.verts.iter().map(|v| v[2]).collect();
    out.write_with("mesh.vtu", |w| {
        write_vtu(
            w,
            &mesh.verts,
            Cells::Tetra(&mesh.tets),
            &[("z_m", DataArray::F64(&z))],
            &[("layer", DataArray::I32(&region))],
        )
    })?;
    let tags: Vec<i32> = mesh.boundary_tag.iter().map(|t| t.marker()).collect();
    out.write_with("boundary.vtu", |w| {
        write_vtu(w, &mesh.verts, Cells::Triangle(&mesh.boundary), &[], &[("tag", DataArray::I32(&tags))])
    })?;
    let comment = format!("{} (metres)", report.object);
    out.write_with("surface.obj", |w| write_obj_to(w, &mesh.boundary_surface(), &format!("boundary of {comment}")))?;
    let (visible, _) = mesh.tagged_surface(FaceTag::Visible);
    out.write_with("visible.obj", |w| write_obj_to(w, &visible, &format!("visible surface of {comment}")))?;
    let json = serde_json::to_string_pretty(report)? + "\n";
    out.write_bytes("mesh_stats.json", json.as_bytes())?;
    out.commit().with_context(|| format!("writing {}", args.out.display()))?;
    print!("{json}");
    Ok(())
}

//! Joining cell results into tables: `thickness_vs_reference.csv`,
//! `surface_vs_volumetric.csv`, `mesh_convergence.csv`, `cells.csv` (timings), then the plots
//! and `summary.md` ([`finalize`]); and `simbench merge` for the outputs of shards ([`merge`]).

use std::path::{Path, PathBuf};

use anyhow::{bail, Context};
use serde_json::Value;

use super::cells::CellSpec;
use super::results::{CellTiming, ConvRow, Part1Row, Part2Row, Results};
use super::run::read_cell;
use super::CELLS_DIR;

fn num(v: &Value, what: &str) -> anyhow::Result<f64> {
    v.as_f64().with_context(|| format!("{what}: expected a number, got {v}"))
}

fn read_plan(dir: &Path) -> anyhow::Result<Value> {
    let path = dir.join("plan.json");
    let text = std::fs::read_to_string(&path).with_context(|| format!("reading {}", path.display()))?;
    serde_json::from_str(&text).with_context(|| format!("parsing {}", path.display()))
}

/// Reads the plan and every cell of `dir`; errors name the cells that are missing or stale.
pub fn collect(dir: &Path) -> anyhow::Result<Results> {
    let plan = read_plan(dir)?;
    let cells = plan["cells"].as_array().context("plan.json: no cells")?;
    let mut records = Vec::new();
    let mut missing = Vec::new();
    for c in cells {
        let (id, hash) = (c["id"].as_str().unwrap_or_default(), c["hash"].as_str().unwrap_or_default());
        match read_cell(&dir.join(CELLS_DIR).join(format!("{id}.json"))) {
            Some(r) if r["hash"].as_str() == Some(hash) => records.push(r),
            Some(_) => missing.push(format!("{id} (stale: its configuration changed)")),
            None => missing.push(id.to_string()),
        }
    }
    if !missing.is_empty() {
        bail!(
            "{}: {} of {} cells are missing or stale: {}{}; run the remaining cells (simbench sweep thickness --resume, or the missing shards)",
            dir.display(),
            missing.len(),
            cells.len(),
            missing.iter().take(8).cloned().collect::<Vec<_>>().join(", "),
            if missing.len() > 8 { ", ..." } else { "" }
        );
    }
    let mut res = Results {
        quick: plan["quick"].as_bool().unwrap_or(false),
        part1: vec![],
        part2: vec![],
        conv: vec![],
        timings: vec![],
        runs: vec![],
    };
    for r in &records {
        let id = r["id"].as_str().unwrap_or_default().to_string();
        let spec: CellSpec = serde_json::from_value(r["spec"].clone()).with_context(|| format!("cell {id}: spec"))?;
        let result = &r["result"];
        let seconds = num(&r["seconds"]["total"], &format!("cell {id}: seconds.total"))?;
        res.timings.push(CellTiming {
            id: id.clone(),
            nodes: r["mesh"]["nodes"].as_u64().unwrap_or(0),
            tetrahedra: r["mesh"]["tetrahedra"].as_u64().unwrap_or(0),
            seconds,
        });
        match spec {
            CellSpec::Thickness { material, thickness_m } => res.part1.push(Part1Row {
                material,
                thickness_m,
                mean_abs_err_k: num(&result["vs_reference"]["mean_abs_k"], &id)?,
                max_abs_err_k: num(&result["vs_reference"]["max_abs_k"], &id)?,
                mean_rise_k: num(&result["mean_rise_k"], &id)?,
            }),
            CellSpec::Surface { shape, material, thickness_m } => {
                for model in ["surface", "surface_effective"] {
                    let m = &result["models"][model];
                    res.part2.push(Part2Row {
                        shape,
                        material: material.clone(),
                        thickness_m,
                        model: model.to_string(),
                        pct_err_abs_k: num(&m["diff"]["pct_err_abs_k"], &id)?,
                        pct_err_rise: num(&m["diff"]["pct_err_rise"], &id)?,
                        mean_abs_k: num(&m["diff"]["mean_abs_k"], &id)?,
                        volumetric_mean_rise_k: num(&result["volumetric_mean_rise_k"], &id)?,
                        layer_thickness_m: num(&m["layer_thickness_m"], &id)?,
                    });
                }
            }
            CellSpec::Convergence { material, thickness_m, element_factor, dt_factor } => res.conv.push(ConvRow {
                material,
                thickness_m,
                element_factor,
                dt_factor,
                surface_element_size_m: num(&r["mesh"]["surface_element_size_m"], &id)?,
                time_step_s: num(&r["config"]["scene"]["timing"]["time_step"], &id)?,
                tetrahedra: r["mesh"]["tetrahedra"].as_u64().unwrap_or(0),
                mean_rise_k: num(&result["mean_rise_k"], &id)?,
                seconds,
            }),
        }
    }
    let order =
        |m: &str| plan["materials"].as_array().and_then(|a| a.iter().position(|x| x == m)).unwrap_or(usize::MAX);
    res.part1.sort_by(|a, b| {
        (order(&a.material), a.thickness_m).partial_cmp(&(order(&b.material), b.thickness_m)).expect("finite")
    });
    res.part2.sort_by(|a, b| {
        (a.shape, order(&a.material), a.thickness_m, &a.model)
            .partial_cmp(&(b.shape, order(&b.material), b.thickness_m, &b.model))
            .expect("finite")
    });
    res.conv
        .sort_by(|a, b| (b.element_factor, b.dt_factor).partial_cmp(&(a.element_factor, a.dt_factor)).expect("finite"));
    res.timings.sort_by(|a, b| a.id.cmp(&b.id));
    let mut run_files: Vec<PathBuf> = std::fs::read_dir(dir)?
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.file_name().is_some_and(|n| n.to_string_lossy().starts_with("run_shard_")))
        .collect();
    run_files.sort();
    for p in run_files {
        if let Ok(v) =
            std::fs::read_to_string(&p).map_err(anyhow::Error::from).and_then(|t| Ok(serde_json::from_str(&t)?))
        {
            res.runs.push(v);
        }
    }
    Ok(res)
}

/// `thickness_vs_reference.csv`.
pub fn part1_csv(rows: &[Part1Row]) -> String {
    let mut s = String::from("material,thickness_m,mean_abs_err_K,max_abs_err_K\n");
    for r in rows {
        s += &format!("{},{},{:.6},{:.6}\n", r.material, r.thickness_m, r.mean_abs_err_k, r.max_abs_err_k);
    }
    s
}

/// `surface_vs_volumetric.csv`.
pub fn part2_csv(rows: &[Part2Row]) -> String {
    let mut s = String::from("shape,material,thickness_m,model,pct_err_abs_K,pct_err_rise\n");
    for r in rows {
        s += &format!(
            "{},{},{},{},{:.4},{:.4}\n",
            r.shape.name(),
            r.material,
            r.thickness_m,
            r.model,
            r.pct_err_abs_k,
            r.pct_err_rise
        );
    }
    s
}

/// `surface_detail.csv`: the figures behind each row of `surface_vs_volumetric.csv`.
pub fn part2_detail_csv(rows: &[Part2Row]) -> String {
    let mut s =
        String::from("shape,material,thickness_m,model,mean_abs_diff_K,volumetric_mean_rise_K,layer_thickness_m\n");
    for r in rows {
        s += &format!(
            "{},{},{},{},{:.6},{:.6},{}\n",
            r.shape.name(),
            r.material,
            r.thickness_m,
            r.model,
            r.mean_abs_k,
            r.volumetric_mean_rise_k,
            r.layer_thickness_m
        );
    }
    s
}

/// `mesh_convergence.csv`.
pub fn conv_csv(rows: &[ConvRow]) -> String {
    let mut s = String::from(
        "material,thickness_m,element_factor,dt_factor,surface_element_size_m,time_step_s,tetrahedra,mean_rise_K,seconds\n",
    );
    for r in rows {
        s += &format!(
            "{},{},{},{},{},{:.6},{},{:.6},{:.2}\n",
            r.material,
            r.thickness_m,
            r.element_factor,
            r.dt_factor,
            r.surface_element_size_m,
            r.time_step_s,
            r.tetrahedra,
            r.mean_rise_k,
            r.seconds
        );
    }
    s
}

/// `cells.csv`: per-cell mesh size and time.
pub fn timings_csv(rows: &[CellTiming]) -> String {
    let mut s = String::from("cell,nodes,tetrahedra,seconds\n");
    for r in rows {
        s += &format!("{},{},{},{:.2}\n", r.id, r.nodes, r.tetrahedra, r.seconds);
    }
    s
}

/// Writes the tables, plots and summary of the complete sweep in `dir`.
pub fn finalize(dir: &Path) -> anyhow::Result<()> {
    let res = collect(dir)?;
    let mut out = heatsim::io::OutputDir::new(dir).with_context(|| format!("preparing {}", dir.display()))?;
    out.write_bytes("thickness_vs_reference.csv", part1_csv(&res.part1).as_bytes())?;
    out.write_bytes("surface_vs_volumetric.csv", part2_csv(&res.part2).as_bytes())?;
    out.write_bytes("surface_detail.csv", part2_detail_csv(&res.part2).as_bytes())?;
    out.write_bytes("mesh_convergence.csv", conv_csv(&res.conv).as_bytes())?;
    out.write_bytes("cells.csv", timings_csv(&res.timings).as_bytes())?;
    for (name, bytes) in crate::figure::optional("the sweep's figures", || super::plots::all(&res)).unwrap_or_default()
    {
        out.write_bytes(&name, &bytes)?;
    }
    out.write_bytes("summary.md", super::summary::markdown(&res).as_bytes())?;
    out.commit().with_context(|| format!("writing {}", dir.display()))?;
    Ok(())
}

/// Joins the outputs of shards `dirs` into `out` (cells, plan, run files), then
/// [`finalize`]s it. The shards must come from the same plan.
pub fn merge(dirs: &[PathBuf], out: &Path) -> anyhow::Result<()> {
    if dirs.is_empty() {
        bail!("merge: give at least one shard directory");
    }
    let plan = read_plan(&dirs[0])?;
    for d in &dirs[1..] {
        let other = read_plan(d)?;
        if other != plan {
            bail!(
                "{} and {} come from different sweeps (their plan.json differ: other options, --quick or software version)",
                dirs[0].display(),
                d.display()
            );
        }
    }
    let hashes: std::collections::BTreeMap<String, String> = plan["cells"]
        .as_array()
        .context("plan.json: no cells")?
        .iter()
        .map(|c| (c["id"].as_str().unwrap_or_default().to_string(), c["hash"].as_str().unwrap_or_default().to_string()))
        .collect();
    let cells_out = out.join(CELLS_DIR);
    std::fs::create_dir_all(&cells_out).with_context(|| format!("creating {}", cells_out.display()))?;
    let mut copied = 0;
    for d in dirs {
        let cells_dir = d.join(CELLS_DIR);
        let entries = std::fs::read_dir(&cells_dir).with_context(|| format!("reading {}", cells_dir.display()))?;
        let mut paths: Vec<PathBuf> = entries.flatten().map(|e| e.path()).collect();
        paths.sort();
        for p in paths {
            let Some(r) = read_cell(&p) else { continue };
            let id = r["id"].as_str().unwrap_or_default();
            if hashes.get(id).map(String::as_str) != r["hash"].as_str() {
                continue; // a stale cell or one of another plan
            }
            let to = cells_out.join(format!("{id}.json"));
            if to != p {
                heatsim::io::write_atomic(&to, &std::fs::read(&p)?)?;
            }
            copied += 1;
        }
        for e in std::fs::read_dir(d)?.flatten() {
            let name = e.file_name().to_string_lossy().into_owned();
            if name.starts_with("run_shard_") && d.as_path() != out {
                heatsim::io::write_atomic(&out.join(&name), &std::fs::read(e.path())?)?;
            }
        }
    }
    heatsim::io::write_atomic(&out.join("plan.json"), (serde_json::to_string_pretty(&plan)? + "\n").as_bytes())?;
    eprintln!("merge: {copied} cell files from {} directories into {}", dirs.len(), out.display());
    finalize(out)
}

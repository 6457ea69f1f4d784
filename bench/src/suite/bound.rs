//! What the data allow: the Cramér–Rao bound of the aligned surface error
//! ([`heatrecon::bound::shape_bound_at_truth`]), computed once at suite build for the objects
//! the spec marks, at each noisy level, on the videos of seed 1.
//!
//! The bound is on the coefficients of a few shape modes (`size`, `relief` and the image
//! monomials u^p v^q with 1 <= p + q <= degree) at one pyramid level, taken at the true depth,
//! fluxes and globals with the material's diffusivity known, reported as the expected mean
//! unsigned surface error after the best rigid motion. Each row frees a different set of
//! nuisances: the per-vertex fluxes (unknown: the paper's setting; known: calibrated lamps) and
//! the globals lambda and C. Each row also carries the bound on the `size` mode alone (all depths
//! scaled by `1 + β`, so its standard deviation is the relative error of the object's distance
//! and size along the camera rays). It holds for unbiased estimators of those modes only: a
//! method may beat it on other shapes or with a bias, and no method is expected to reach it.
//!
//! Stored in `SUITE/bounds/<object>-netd<mK>.json` (kept when a build resumes) and gathered in
//! `SUITE/bounds.json`; not part of the suite's version (they are derived from its bytes).

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;
use serde::{Deserialize, Serialize};

use super::manifest::{CaseEntry, Manifest, VIEWS};

/// Which objects get a bound, at which level and degree.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct BoundSpec {
    /// Object ids (`<object>-<solver>-d<thickness>`) or object names (`hemisphere`).
    pub objects: Vec<String>,
    /// Pyramid level (0: the camera's pixels; each level halves the resolution).
    pub level: usize,
    /// Degree of the image-polynomial modes.
    pub degree: usize,
    /// CGLS iterations at most per flux projection.
    pub max_iterations: usize,
}

/// One row of a bound: which nuisances are free and the expected aligned error.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct BoundRow {
    /// `unknown` (the paper's setting) or `known` (calibrated lamps).
    pub fluxes: String,
    /// lambda and C: `unknown` or `known`.
    pub globals: String,
    /// Expected mean unsigned surface error after the best rigid motion, mm.
    pub expected_mae_mm: f64,
    /// Standard deviation bound of the size (the mean depth along the camera rays), % of it;
    /// absent in bounds computed before it was recorded.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub size_std_pct: Option<f64>,
}

/// The bound of one object at one noise level.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct BoundEntry {
    pub object: String,
    pub netd_mk: f64,
    pub level: usize,
    pub degree: usize,
    /// The modes bounded.
    pub modes: Vec<String>,
    /// Noise measured on the frames before the lamps switch on, K.
    pub sigma_k: f64,
    pub rows: Vec<BoundRow>,
    /// What the figure bounds, in words.
    pub label: String,
    /// The largest relative residual of the normal equations at which a flux projection's
    /// CGLS stopped (converged at or below the tolerance, [`cgls_tolerance`]; above it, at the
    /// spec's `max_iterations`, the bound is approximate); absent in bounds computed before it
    /// was recorded.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub projection_residual: Option<f64>,
    /// CGLS iterations of the slowest flux projection (at most the spec's `max_iterations`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub projection_iterations: Option<usize>,
    /// Wall time of the computation, s.
    pub seconds: f64,
}

/// CGLS stops a flux projection when the normal equations' residual falls below this
/// fraction of the start's (the bound's default, `heatrecon::bound::shape::BoundOptions`).
pub fn cgls_tolerance() -> f64 {
    heatrecon::bound::shape::BoundOptions::default().tolerance
}

impl BoundEntry {
    /// Whether every flux projection converged to [`cgls_tolerance`] (`None`: not recorded).
    pub fn converged(&self) -> Option<bool> {
        self.projection_residual.map(|r| r <= cgls_tolerance())
    }

    /// The row with `fluxes` free or known and the globals free.
    pub fn row(&self, fluxes: &str) -> Option<&BoundRow> {
        self.rows.iter().find(|r| r.fluxes == fluxes && r.globals == "unknown")
    }
}

/// Computes (or keeps) the bounds of the manifest's marked objects; returns every bound the
/// suite holds (those of `simbench suite bound` too). A bound that fails is reported on stderr
/// and left out.
///
/// # Errors
/// I/O errors.
pub fn build_bounds(suite: &Path, manifest: &Manifest, spec: &BoundSpec) -> anyhow::Result<Vec<BoundEntry>> {
    compute_bounds(suite, manifest, spec, &spec.objects)
}

/// Computes (or keeps) the bounds of `objects` (ids or names, `all`: every object) in the
/// family of `spec` (its level and degree; computed with its iterations), then gathers every
/// bound of that family stored in `SUITE/bounds/` into `SUITE/bounds.json`, in the manifest's
/// order, and returns them. A bound that fails is reported on stderr and left out.
///
/// # Errors
/// An object the suite does not hold; I/O errors.
pub fn compute_bounds(
    suite: &Path,
    manifest: &Manifest,
    spec: &BoundSpec,
    objects: &[String],
) -> anyhow::Result<Vec<BoundEntry>> {
    let all = objects.iter().any(|o| o == "all");
    for o in objects.iter().filter(|o| *o != "all") {
        anyhow::ensure!(
            manifest.objects.iter().any(|m| &m.id == o || &m.object == o),
            "suite {} has no object {o:?} (its objects: {})",
            manifest.version,
            manifest.objects.iter().map(|m| m.id.as_str()).collect::<Vec<_>>().join(", ")
        );
    }
    let dir = suite.join("bounds");
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    let mut out = Vec::new();
    for object in &manifest.objects {
        let wanted = all || objects.iter().any(|o| o == &object.id || o == &object.object);
        for noise in manifest.spec.noise.iter().filter(|n| !n.is_clean()) {
            let path = dir.join(format!("{}-netd{}.json", object.id, noise.netd_mk));
            // Kept when stored (`read_stored`); computed for the objects asked for.
            if let Some(b) = read_stored(&path, spec) {
                out.push(b);
                continue;
            }
            if !wanted {
                continue;
            }
            let case = manifest
                .cases
                .iter()
                .find(|c| c.object == object.id && c.noise == *noise && c.seed == 1)
                .with_context(|| format!("{}: no seed-1 case at NETD {} mK", object.id, noise.netd_mk))?;
            eprintln!(
                "suite: bound of {} at NETD {} mK (level {}, degree {})",
                object.id, noise.netd_mk, spec.level, spec.degree
            );
            // A bound that cannot be computed is reported and left out, not fatal.
            match bound_of_case(suite, case, spec) {
                Ok(b) => {
                    heatsim::io::write_atomic(&path, (serde_json::to_string_pretty(&b)? + "\n").as_bytes())?;
                    out.push(b);
                }
                Err(e) => eprintln!("suite: warning: no bound for case {}: {e:#}", case.id),
            }
        }
    }
    let text = serde_json::to_string_pretty(&out)? + "\n";
    heatsim::io::write_atomic(&suite.join("bounds.json"), text.as_bytes()).context("writing bounds.json")?;
    Ok(out)
}

/// A complete stored bound of the family of `spec` (one from before the size or the CGLS
/// residual was recorded, or of another level or degree, is not).
fn read_stored(path: &Path, spec: &BoundSpec) -> Option<BoundEntry> {
    let text = std::fs::read_to_string(path).ok()?;
    let b = serde_json::from_str::<BoundEntry>(&text).ok()?;
    let complete = b.rows.iter().all(|r| r.size_std_pct.is_some()) && b.converged().is_some();
    (complete && b.level == spec.level && b.degree == spec.degree).then_some(b)
}

/// The bound on one case's videos: a temporary dataset per view (the stored ground truth and
/// the case's video), then [`heatrecon::bound::shape_bound_at_truth`].
fn bound_of_case(suite: &Path, case: &CaseEntry, spec: &BoundSpec) -> anyhow::Result<BoundEntry> {
    let t = Instant::now();
    let tmp = tempdir(suite)?;
    let mut dirs: Vec<PathBuf> = Vec::new();
    let inputs = super::inputs::case_inputs(suite, case, false)?;
    for view in VIEWS {
        let store = super::inputs::store_dir(suite, case, view);
        let dir = tmp.join(view);
        std::fs::create_dir_all(&dir)?;
        for e in std::fs::read_dir(&store).with_context(|| format!("listing {}", store.display()))? {
            let p = e?.path();
            let name = p.file_name().expect("a file name").to_owned();
            if name != "film.npy" {
                std::fs::copy(&p, dir.join(&name)).with_context(|| format!("copying {}", p.display()))?;
            }
        }
        let video = inputs.iter().find(|(r, _)| r == &format!("{view}/video.npy")).context("no video input")?;
        std::fs::write(dir.join("video.npy"), &video.1)?;
        dirs.push(dir);
    }
    let paths: Vec<&Path> = dirs.iter().map(PathBuf::as_path).collect();
    let alpha = heatrecon::dataset::read_diffusivity(paths[0])?;
    let opts = heatrecon::bound::shape::BoundOptions {
        degree: spec.degree,
        max_iterations: spec.max_iterations,
        ..Default::default()
    };
    let defaults = heatrecon::config::ReconConfig::default();
    let result = heatrecon::bound::shape_bound_at_truth(
        &paths,
        &heatrecon::dataset::LoadOptions::default(),
        spec.level,
        alpha,
        defaults.shape.boundary_rings,
        defaults.stage1.halfspace_threshold,
        opts,
    );
    let _ = std::fs::remove_dir_all(&tmp);
    let b = result?;
    let word = |unknown: bool| if unknown { "unknown" } else { "known" }.to_string();
    let size = b.modes.iter().position(|m| m == "size");
    let rows = b
        .rows
        .iter()
        .map(|r| BoundRow {
            fluxes: word(r.nuisances.fluxes),
            globals: word(r.nuisances.globals),
            expected_mae_mm: r.joint_mae_m * 1e3,
            size_std_pct: size.map(|i| r.std[i] * 100.0),
        })
        .collect();
    Ok(BoundEntry {
        object: case.object.clone(),
        netd_mk: case.noise.netd_mk,
        level: spec.level,
        degree: spec.degree,
        label: format!(
            "Cramér-Rao bound of the rigidly aligned MAE for unbiased estimators of {} shape modes (size, relief, image polynomials to degree {}) at pyramid level {}, diffusivity known",
            b.modes.len(),
            spec.degree,
            spec.level
        ),
        modes: b.modes,
        sigma_k: b.sigma,
        rows,
        projection_residual: Some(b.projection_residual),
        projection_iterations: Some(b.projection_iterations),
        seconds: t.elapsed().as_secs_f64(),
    })
}

/// A fresh temporary folder inside the suite (same file system, removed after use).
fn tempdir(suite: &Path) -> anyhow::Result<PathBuf> {
    let p = suite.join(format!(".bound-tmp-{}", std::process::id()));
    if p.exists() {
        std::fs::remove_dir_all(&p)?;
    }
    std::fs::create_dir_all(&p).with_context(|| format!("creating {}", p.display()))?;
    Ok(p)
}

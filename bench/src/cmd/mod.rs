//! One module per subcommand.

pub mod bench_recon;
pub mod bench_solver;
pub mod bench_surface;
pub mod docs;
pub mod eval;
pub mod merge;
pub mod mesh;
pub mod mesh_independence;
pub mod peer;
pub mod peer_scaling;
pub mod reconstruct;
pub mod schema;
pub mod simulate;
pub mod suite;
pub mod sweep;
pub mod table;

use anyhow::Context;
use std::path::Path;

/// Loads a scene file and applies the common `--thickness` override; call
/// [`Scene::validate`](heatsim::scene::Scene::validate) again after further overrides.
pub fn load_scene(path: &Path, thickness: Option<f64>) -> anyhow::Result<heatsim::scene::Scene> {
    let mut scene =
        heatsim::scene::Scene::from_file(path).with_context(|| format!("loading scene {}", path.display()))?;
    if let Some(d) = thickness {
        scene.object.set_thickness(d);
        scene.validate().context("--thickness")?;
    }
    Ok(scene)
}

/// The median wall time (s) of `repeat` calls of `f` (at least one): benchmarks on a shared
/// machine report medians, which one busy moment does not move.
pub fn median_time<R>(repeat: usize, mut f: impl FnMut() -> R) -> f64 {
    let mut v: Vec<f64> = (0..repeat.max(1))
        .map(|_| {
            let t = std::time::Instant::now();
            std::hint::black_box(f());
            t.elapsed().as_secs_f64()
        })
        .collect();
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

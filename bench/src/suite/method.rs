//! The methods a suite run can score, and the contract of an external one.
//!
//! **Contract of `--method-cmd`.** The template is run by `sh -c` after replacing `{left}` and
//! `{right}` with the directories of the videos lit from the left and from the right,
//! `{out}` with an empty output directory (required) and `{case}` with the case id; paths are
//! shell-quoted. The input directories hold what a real capture has (`super::inputs`):
//! `video.npy`, `times.npy`, `mask.npy`, `camera.json`, `environment.json`, `material.json`,
//! and `lamps.json` only with `--lamps` (a method that uses calibrated lamps). The method writes
//! `{out}/recon_world.obj` or `{out}/recon_world.ply`: a triangle mesh of the visible surface
//! in the world frame, in metres. It runs in the directory `simbench suite run` was started
//! from (so relative paths in the template work) and must finish within `--timeout`; a non-zero exit, a time-out, or a missing or unreadable mesh
//! is a failed case with its reason.

use std::path::{Path, PathBuf};
use std::process::Command;

use anyhow::{bail, ensure, Context};
use serde_json::{json, Value};

use super::process::{run_logged, Failure};
use crate::sweep::cells::sha256_hex;

/// A method to score.
#[derive(Clone, Debug)]
pub enum Method {
    /// `simbench reconstruct` with a preset, or with a configuration file (its bytes), which
    /// replaces the preset; `lamps`: the configuration uses calibrated lamps.
    Builtin { preset: String, config: Option<(PathBuf, Vec<u8>)>, lamps: bool },
    /// A fronto-parallel plane at the true mean depth ([`super::score::plane`]).
    Plane,
    /// An external command (module documentation).
    Command { template: String, lamps: bool },
}

impl Method {
    /// The method of the command line: `--method builtin[:PRESET]|plane` or `--method-cmd`.
    ///
    /// # Errors
    /// Both or neither given, an unknown method, a template without `{out}`, an unreadable
    /// configuration file, `--config` or `--lamps` with a method that takes none.
    pub fn parse(
        method: Option<&str>,
        cmd: Option<&str>,
        config: Option<&Path>,
        lamps: bool,
    ) -> anyhow::Result<Method> {
        let m = match (method, cmd) {
            (Some(_), Some(_)) => bail!("give either --method or --method-cmd, not both"),
            (None, Some(t)) => {
                ensure!(t.contains("{out}"), "--method-cmd: the template `{t}` has no {{out}}: the method must be told where to write recon_world.obj");
                Method::Command { template: t.to_string(), lamps }
            }
            (m, None) => match m.unwrap_or("builtin") {
                "plane" => Method::Plane,
                b if b == "builtin" || b.starts_with("builtin:") => {
                    let preset = b.strip_prefix("builtin:").unwrap_or("paper").to_string();
                    let mut resolved = heatrecon::config::Preset::from_name(&preset)
                        .with_context(|| format!("--method {b}"))?
                        .config();
                    let config = match config {
                        Some(p) => {
                            let bytes =
                                std::fs::read(p).with_context(|| format!("reading --config {}", p.display()))?;
                            resolved = heatrecon::config::ReconConfig::from_json(
                                &String::from_utf8_lossy(&bytes),
                                &p.display().to_string(),
                            )?;
                            Some((p.to_path_buf(), bytes))
                        }
                        None => None,
                    };
                    Method::Builtin { preset, config, lamps: resolved.shape.lamp_shading.is_some() }
                }
                other => {
                    bail!("--method: unknown method `{other}`; known: builtin, builtin:PRESET, plane (or --method-cmd)")
                }
            },
        };
        ensure!(config.is_none() || matches!(m, Method::Builtin { .. }), "--config applies to --method builtin only");
        ensure!(
            !lamps || matches!(m, Method::Command { .. }),
            "--lamps applies to --method-cmd only (the built-in method takes lamps with its calibrated-lamps preset)"
        );
        Ok(m)
    }

    /// Whether the method is handed `lamps.json`.
    pub fn wants_lamps(&self) -> bool {
        match self {
            Method::Builtin { lamps, .. } | Method::Command { lamps, .. } => *lamps,
            Method::Plane => false,
        }
    }

    /// What identifies the method in a run (a resumed run must have the same).
    pub fn signature(&self) -> Value {
        match self {
            Method::Builtin { preset, config, .. } => json!({
                "kind": "builtin", "preset": preset,
                "config_sha256": config.as_ref().map(|(_, b)| sha256_hex(b)),
                "software": crate::sweep::cells::heatsim_version(),
            }),
            Method::Plane => json!({ "kind": "plane" }),
            Method::Command { template, lamps } => json!({ "kind": "command", "template": template, "lamps": lamps }),
        }
    }

    /// A short label for reports.
    pub fn label(&self) -> String {
        match self {
            Method::Builtin { preset, config: None, .. } => format!("builtin:{preset}"),
            Method::Builtin { config: Some((p, _)), .. } => format!("builtin --config {}", p.display()),
            Method::Plane => "plane".into(),
            Method::Command { template, .. } => format!("command `{template}`"),
        }
    }

    /// Runs the method on the inputs in `case_dir/{left,right}`, writing into `case_dir/out`,
    /// and returns the reconstruction file. `truth_dir` is only read by the plane baseline.
    ///
    /// # Errors
    /// A [`Failure`] (crash, timeout, no output).
    pub fn run(
        &self,
        case_id: &str,
        case_dir: &Path,
        truth_dir: &Path,
        exe: &Path,
        timeout_s: f64,
    ) -> Result<PathBuf, Failure> {
        let out = case_dir.join("out");
        std::fs::create_dir_all(&out)
            .map_err(|e| Failure::new("inputs", format!("creating {}: {e}", out.display())))?;
        let (left, right) = (case_dir.join("left"), case_dir.join("right"));
        let log = case_dir.join("method.log");
        match self {
            Method::Plane => {
                let mesh = super::score::plane(truth_dir).map_err(|e| Failure::new("crash", format!("{e:#}")))?;
                let path = out.join("recon_world.obj");
                let mut bytes = Vec::new();
                heatsim::mesh::write_obj_to(
                    &mut bytes,
                    &mesh,
                    "plane baseline at the true mean depth, world frame (m)",
                )
                .and_then(|()| std::fs::write(&path, &bytes))
                .map_err(|e| Failure::new("crash", format!("writing {}: {e}", path.display())))?;
            }
            Method::Builtin { preset, config, .. } => {
                let mut cmd = Command::new(exe);
                cmd.arg("reconstruct").arg(&left).arg(&right).arg("--out").arg(&out);
                match config {
                    Some((p, _)) => cmd.arg("--config").arg(p),
                    None => cmd.args(["--preset", preset]),
                };
                cmd.args(["--diffusivity", "material"]);
                if !self.wants_lamps() {
                    cmd.args(["--lamp-sides", "left,right"]);
                }
                run_logged(cmd, &log, timeout_s)?;
            }
            Method::Command { template, .. } => {
                let line = template
                    .replace("{left}", &quote(&left))
                    .replace("{right}", &quote(&right))
                    .replace("{out}", &quote(&out))
                    .replace("{case}", &quote(Path::new(case_id)));
                let mut cmd = Command::new("sh");
                cmd.arg("-c").arg(line);
                run_logged(cmd, &log, timeout_s)?;
            }
        }
        ["recon_world.obj", "recon_world.ply"].iter().map(|n| out.join(n)).find(|p| p.is_file()).ok_or_else(|| {
            Failure::new(
                "no_output",
                format!(
                    "the method wrote neither recon_world.obj nor recon_world.ply in {}; log: {}",
                    out.display(),
                    super::process::log_tail(&log)
                ),
            )
        })
    }
}

/// `path` in single quotes for `sh`.
fn quote(path: &Path) -> String {
    format!("'{}'", path.display().to_string().replace('\'', "'\\''"))
}

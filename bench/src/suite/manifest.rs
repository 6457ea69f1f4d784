//! `suite.json`: what a suite holds and the SHA-256 of every byte a method or the scorer reads.
//!
//! The suite's version is `<name>-f<format>-<digest>`, the digest the first 12 hex digits of
//! the SHA-256 of the manifest's canonical JSON without its `version`, `simulator` and
//! `built` fields: the spec, every stored file's hash and every case's input hashes. Building
//! the same spec with a simulator that gives the same bytes gives the same version; any change
//! to a dataset (meshing, solver, camera, noise) gives a new one. Runs record the version, and
//! runs of different versions are never compared.

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::{ensure, Context};
use serde::{Deserialize, Serialize};
use serde_json::Value;

use super::spec::{NoiseLevel, SuiteSpec};
use crate::sweep::cells::{canonical_json, sha256_hex};

/// Version of the suite layout and of this manifest.
pub const SUITE_FORMAT: u32 = 1;
/// The manifest's file name.
pub const MANIFEST: &str = "suite.json";
/// The two lamp configurations (video directories) of every object and case.
pub const VIEWS: [&str; 2] = ["left", "right"];

/// `suite.json` (module documentation).
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Manifest {
    /// [`SUITE_FORMAT`].
    pub format: u32,
    /// `<name>-f<format>-<digest>`.
    pub version: String,
    /// The software that built it, e.g. `simbench 0.1.0`.
    pub simulator: String,
    /// The spec it was built from.
    pub spec: SuiteSpec,
    /// The simulated objects and their stored files.
    pub objects: Vec<ObjectEntry>,
    /// The cases, in run order.
    pub cases: Vec<CaseEntry>,
}

/// One simulated object configuration.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ObjectEntry {
    /// e.g. `ball-surface-d0.002`; its files are in `objects/<id>/`.
    pub id: String,
    pub object: String,
    pub solver: String,
    pub thickness_m: f64,
    pub material: String,
    /// Path (relative to the suite) -> SHA-256 of every stored file.
    pub files: BTreeMap<String, String>,
}

/// One case: an object filmed at one noise level with one seed.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CaseEntry {
    /// `<object id>-netd<mK>-s<seed>`.
    pub id: String,
    /// The object's id.
    pub object: String,
    pub noise: NoiseLevel,
    /// 0 for the noise-free level, 1..=N otherwise; runs are paired on it.
    pub seed: u32,
    /// The sensor seed of each view (`left`, `right`), derived from the case.
    pub sensor_seeds: BTreeMap<String, u64>,
    /// Path (relative to the case's input directory, e.g. `left/video.npy`) -> SHA-256 of every
    /// input file a method may read (`lamps.json` only reaches methods with calibrated lamps).
    pub inputs: BTreeMap<String, String>,
}

impl CaseEntry {
    /// The case id of an object, noise level and seed.
    pub fn make_id(object: &str, noise: &NoiseLevel, seed: u32) -> String {
        format!("{object}-netd{}-s{seed}", noise.netd_mk)
    }

    /// The sensor seed of `view`: the first 8 bytes of SHA-256(`<case id>/<view>`), so that
    /// every case and view draws its own noise.
    pub fn sensor_seed(case_id: &str, view: &str) -> u64 {
        let hex = sha256_hex(format!("{case_id}/{view}").as_bytes());
        u64::from_str_radix(&hex[..16], 16).expect("hex digits")
    }
}

impl Manifest {
    /// The version string of this content (module documentation).
    pub fn compute_version(&self) -> String {
        let mut v = serde_json::to_value(self).expect("the manifest serialises");
        if let Value::Object(m) = &mut v {
            m.remove("version");
            m.remove("simulator");
        }
        let digest = sha256_hex(canonical_json(&v).as_bytes());
        format!("{}-f{}-{}", self.spec.name, self.format, &digest[..12])
    }

    /// Reads and checks `SUITE/suite.json`: the format and the version against the content.
    ///
    /// # Errors
    /// A missing or malformed manifest, another format version, a version that does not match
    /// the content (an edited manifest).
    pub fn read(suite: &Path) -> anyhow::Result<Manifest> {
        let path = suite.join(MANIFEST);
        let text = std::fs::read_to_string(&path).with_context(|| {
            format!("{}: not a suite (no readable {MANIFEST}; build one with `simbench suite build`)", suite.display())
        })?;
        Manifest::parse(&text, &path)
    }

    /// A suite folder's manifest, or a manifest file itself (as `results/suite/*-suite.json`
    /// keeps it), checked as [`Manifest::read`] does.
    ///
    /// # Errors
    /// As [`Manifest::read`].
    pub fn read_dir_or_file(path: &Path) -> anyhow::Result<Manifest> {
        if path.is_dir() {
            return Manifest::read(path);
        }
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("{}: neither a suite folder nor a readable {MANIFEST}", path.display()))?;
        Manifest::parse(&text, path)
    }

    /// Parses and checks a manifest's text; `path` names it in errors.
    fn parse(text: &str, path: &Path) -> anyhow::Result<Manifest> {
        let raw: Value = serde_json::from_str(text).with_context(|| format!("{}: not JSON", path.display()))?;
        let format = raw.get("format").and_then(Value::as_u64);
        ensure!(
            format == Some(u64::from(SUITE_FORMAT)),
            "{}: suite format {} but this simbench reads format {SUITE_FORMAT}; rebuild the suite with this version",
            path.display(),
            format.map_or("missing".to_string(), |f| f.to_string())
        );
        let m: Manifest =
            serde_json::from_value(raw).with_context(|| format!("{}: malformed manifest", path.display()))?;
        let expected = m.compute_version();
        ensure!(
            m.version == expected,
            "{}: the manifest was altered (its content gives version {expected}, it says {})",
            path.display(),
            m.version
        );
        Ok(m)
    }

    /// The object entry of a case.
    pub fn object_of(&self, case: &CaseEntry) -> anyhow::Result<&ObjectEntry> {
        self.objects
            .iter()
            .find(|o| o.id == case.object)
            .with_context(|| format!("case {}: no object {} in the manifest", case.id, case.object))
    }
}

/// SHA-256 of a file, hex.
///
/// # Errors
/// An unreadable file, naming it.
pub fn file_sha256(path: &Path) -> anyhow::Result<String> {
    let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
    Ok(sha256_hex(&bytes))
}

/// Checks every stored file of `manifest` under `suite` against its hash.
///
/// # Errors
/// The first missing or altered file, naming it.
pub fn verify_files(suite: &Path, manifest: &Manifest) -> anyhow::Result<usize> {
    let mut n = 0;
    for o in &manifest.objects {
        for (rel, sha) in &o.files {
            let path = suite.join(rel);
            ensure!(path.is_file(), "{}: missing (the suite is incomplete)", path.display());
            let got = file_sha256(&path)?;
            ensure!(
                &got == sha,
                "{}: SHA-256 {got} but suite.json records {sha}: the file was altered",
                path.display()
            );
            n += 1;
        }
    }
    Ok(n)
}

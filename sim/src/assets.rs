//! The Stanford bunny, fetched on first use and cached, never vendored.
//!
//! Debian's package `glmark2-data` ships the bunny as `/usr/share/glmark2/models/bunny.obj`
//! (34,835 vertices, 69,666 faces, closed). [`bunny_path`] looks, in order, at
//! 1. a path given by the caller (`simbench --bunny PATH`),
//! 2. the environment variable `HEATSIM_BUNNY`,
//! 3. the cache, `$HEATSIM_CACHE_DIR`, else `$XDG_CACHE_HOME/heatsim`, else `~/.cache/heatsim`,
//! 4. an installed `glmark2-data`,
//! 5. `apt-get download glmark2-data` and `dpkg-deb -x` into a temporary directory (no
//!    installation; on a machine whose package lists are empty, the lists are fetched into
//!    the temporary directory too, leaving the system untouched).
//!
//! Copies from 3 to 5 must match [`BUNNY_SHA256`]; a user's own file (1, 2) is used as given.

use sha2::{Digest, Sha256};
use std::path::{Path, PathBuf};
use std::process::Command;

/// SHA-256 of `bunny.obj` in glmark2-data 2023.01+dfsg-1.
pub const BUNNY_SHA256: &str = "bff773d28c62e80187b2dfa8c6c8cc771a4c7707ddcdcf2e515913d322d1f548";
/// Environment variable naming a user's bunny file.
pub const BUNNY_ENV: &str = "HEATSIM_BUNNY";
/// Environment variable overriding the cache directory.
pub const CACHE_ENV: &str = "HEATSIM_CACHE_DIR";
const SYSTEM_BUNNY: &str = "/usr/share/glmark2/models/bunny.obj";

/// Why the bunny is not available.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum AssetError {
    /// A path given explicitly or through `HEATSIM_BUNNY` does not exist.
    #[error("the bunny file {path} (from {origin}) does not exist")]
    Missing { path: PathBuf, origin: &'static str },
    /// The download or extraction failed.
    #[error("could not fetch the Stanford bunny: {reason}. Fix: run `scripts/fetch-bunny.sh`, or install Debian's glmark2-data, or point to your own OBJ with `--bunny PATH` or the environment variable {BUNNY_ENV}=PATH")]
    Fetch { reason: String },
    /// A cached or fetched copy has the wrong checksum.
    #[error("{path} has SHA-256 {actual}, expected {BUNNY_SHA256}; delete it, or point to your own file with `--bunny PATH` or {BUNNY_ENV}=PATH")]
    Checksum { path: PathBuf, actual: String },
}

/// The cache directory for downloaded assets.
pub fn cache_dir() -> PathBuf {
    if let Some(d) = std::env::var_os(CACHE_ENV) {
        return PathBuf::from(d);
    }
    if let Some(d) = std::env::var_os("XDG_CACHE_HOME") {
        return PathBuf::from(d).join("heatsim");
    }
    let home = std::env::var_os("HOME").map(PathBuf::from).unwrap_or_else(std::env::temp_dir);
    home.join(".cache").join("heatsim")
}

/// SHA-256 of a file, as lowercase hex.
pub fn sha256_file(path: &Path) -> std::io::Result<String> {
    let bytes = std::fs::read(path)?;
    Ok(Sha256::digest(&bytes).iter().map(|b| format!("{b:02x}")).collect())
}

/// The path of the Stanford bunny OBJ, fetching and caching it if needed.
///
/// # Errors
/// [`AssetError`] with the exact fix when no copy can be found or fetched.
pub fn bunny_path(explicit: Option<&Path>) -> Result<PathBuf, AssetError> {
    if let Some(p) = explicit {
        return existing(p, "--bunny");
    }
    if let Some(p) = std::env::var_os(BUNNY_ENV).filter(|p| !p.is_empty()) {
        return existing(Path::new(&p), BUNNY_ENV);
    }
    let cached = cache_dir().join("bunny.obj");
    if cached.exists() {
        verify(&cached)?;
        return Ok(cached);
    }
    let system = Path::new(SYSTEM_BUNNY);
    let source = if system.exists() && verify(system).is_ok() {
        std::fs::read(system).map_err(|e| AssetError::Fetch { reason: format!("reading {SYSTEM_BUNNY}: {e}") })?
    } else {
        download()?
    };
    crate::io::write_atomic(&cached, &source)
        .map_err(|e| AssetError::Fetch { reason: format!("writing the cache {}: {e}", cached.display()) })?;
    verify(&cached)?;
    Ok(cached)
}

fn existing(p: &Path, origin: &'static str) -> Result<PathBuf, AssetError> {
    if p.is_file() {
        Ok(p.to_path_buf())
    } else {
        Err(AssetError::Missing { path: p.to_path_buf(), origin })
    }
}

fn verify(path: &Path) -> Result<(), AssetError> {
    let actual =
        sha256_file(path).map_err(|e| AssetError::Fetch { reason: format!("reading {}: {e}", path.display()) })?;
    if actual == BUNNY_SHA256 {
        Ok(())
    } else {
        Err(AssetError::Checksum { path: path.to_path_buf(), actual })
    }
}

/// `apt-get download glmark2-data` and `dpkg-deb -x` in a temporary directory; returns the
/// bytes of bunny.obj after checking the checksum. When the system's package lists do not
/// know the package (a fresh machine), the lists are fetched into the temporary directory
/// (`-o Dir::State::Lists=...`), which changes nothing on the system.
fn download() -> Result<Vec<u8>, AssetError> {
    let fail = |reason: String| AssetError::Fetch { reason };
    let tmp = tempfile::Builder::new().prefix("heatsim-bunny").tempdir().map_err(|e| fail(e.to_string()))?;
    eprintln!("heatsim: fetching the Stanford bunny (Debian package glmark2-data, about 6.6 MB) ...");
    let apt = |private: bool, args: &[&str]| -> Result<(), String> {
        let mut cmd = Command::new("apt-get");
        cmd.arg("-q").current_dir(tmp.path());
        if private {
            let lists = tmp.path().join("lists");
            let cache = tmp.path().join("cache");
            for d in [lists.join("partial"), cache.join("archives").join("partial")] {
                std::fs::create_dir_all(&d).map_err(|e| e.to_string())?;
            }
            cmd.arg("-o").arg(format!("Dir::State::Lists={}", lists.display()));
            cmd.arg("-o").arg(format!("Dir::Cache={}", cache.display()));
            cmd.args(["-o", "Debug::NoLocking=1"]);
        }
        let out = cmd.args(args).output().map_err(|e| format!("cannot run apt-get: {e}"))?;
        if out.status.success() {
            Ok(())
        } else {
            Err(format!("`apt-get {}` failed: {}", args.join(" "), String::from_utf8_lossy(&out.stderr).trim()))
        }
    };
    if apt(false, &["download", "glmark2-data"]).is_err() {
        apt(true, &["update"]).map_err(fail)?;
        apt(true, &["download", "glmark2-data"]).map_err(fail)?;
    }
    let deb = std::fs::read_dir(tmp.path())
        .map_err(|e| fail(e.to_string()))?
        .filter_map(Result::ok)
        .map(|e| e.path())
        .find(|p| p.extension().is_some_and(|x| x == "deb"))
        .ok_or_else(|| fail("apt-get download produced no .deb file".into()))?;
    let root = tmp.path().join("root");
    let out = Command::new("dpkg-deb")
        .arg("-x")
        .arg(&deb)
        .arg(&root)
        .output()
        .map_err(|e| fail(format!("cannot run dpkg-deb: {e}")))?;
    if !out.status.success() {
        return Err(fail(format!("`dpkg-deb -x` failed: {}", String::from_utf8_lossy(&out.stderr).trim())));
    }
    let obj = root.join(SYSTEM_BUNNY.trim_start_matches('/'));
    verify(&obj)?;
    std::fs::read(&obj).map_err(|e| fail(format!("reading {}: {e}", obj.display())))
}

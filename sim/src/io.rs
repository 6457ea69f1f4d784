//! Output files that are either complete or absent.
//!
//! Every writer of this project goes through [`OutputDir`]: files are written into a hidden
//! staging directory beside the destination and moved into place only by
//! [`OutputDir::commit`], so an error or an interruption never leaves a half-written file in
//! the user's output directory.

use std::fs;
use std::io::{self, BufWriter, Write};
use std::path::{Path, PathBuf};

/// A staged output directory.
pub struct OutputDir {
    dest: PathBuf,
    staging: PathBuf,
    files: Vec<String>,
}

impl OutputDir {
    /// Prepares to write into `dest` (created on commit if missing).
    pub fn new(dest: &Path) -> io::Result<OutputDir> {
        let parent = match dest.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
            _ => PathBuf::from("."),
        };
        fs::create_dir_all(&parent)?;
        let name = dest.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_else(|| "out".into());
        let staging = parent.join(format!(".{name}.partial-{}", std::process::id()));
        if staging.exists() {
            fs::remove_dir_all(&staging)?;
        }
        fs::create_dir_all(&staging)?;
        Ok(OutputDir { dest: dest.to_path_buf(), staging, files: Vec::new() })
    }

    /// Writes one file (by name, no directories) with `write`.
    pub fn write_with(
        &mut self,
        name: &str,
        write: impl FnOnce(&mut BufWriter<fs::File>) -> io::Result<()>,
    ) -> io::Result<()> {
        let path = self.staging.join(name);
        let mut w = BufWriter::new(fs::File::create(&path)?);
        write(&mut w)?;
        w.flush()?;
        self.files.push(name.to_string());
        Ok(())
    }

    /// Writes `bytes` to the file `name`.
    pub fn write_bytes(&mut self, name: &str, bytes: &[u8]) -> io::Result<()> {
        self.write_with(name, |w| w.write_all(bytes))
    }

    /// Moves every staged file into the destination (replacing files of the same name) and
    /// removes the staging directory. Returns the destination paths.
    pub fn commit(mut self) -> io::Result<Vec<PathBuf>> {
        fs::create_dir_all(&self.dest)?;
        let mut out = Vec::new();
        for name in std::mem::take(&mut self.files) {
            let to = self.dest.join(&name);
            fs::rename(self.staging.join(&name), &to)?;
            out.push(to);
        }
        fs::remove_dir_all(&self.staging)?;
        Ok(out)
    }
}

impl Drop for OutputDir {
    /// An uncommitted output directory leaves nothing behind.
    fn drop(&mut self) {
        let _ = fs::remove_dir_all(&self.staging);
    }
}

/// Writes `bytes` to `path` atomically (temporary file in the same directory, then rename).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> io::Result<()> {
    let dir = path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    fs::create_dir_all(dir)?;
    let mut tmp = tempfile::NamedTempFile::new_in(dir)?;
    tmp.write_all(bytes)?;
    // Temporary files are private (0600); the result should have ordinary permissions.
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        tmp.as_file().set_permissions(fs::Permissions::from_mode(0o644))?;
    }
    tmp.as_file().sync_all()?;
    tmp.persist(path).map_err(|e| e.error)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn uncommitted_output_leaves_nothing() {
        let root = tempfile::tempdir().unwrap();
        let dest = root.path().join("out");
        {
            let mut o = OutputDir::new(&dest).unwrap();
            o.write_bytes("a.txt", b"hello").unwrap();
        }
        assert!(!dest.exists());
        assert_eq!(fs::read_dir(root.path()).unwrap().count(), 0);
    }

    #[test]
    fn committed_output_has_all_files() {
        let root = tempfile::tempdir().unwrap();
        let dest = root.path().join("out");
        let mut o = OutputDir::new(&dest).unwrap();
        o.write_bytes("a.txt", b"hello").unwrap();
        o.write_bytes("b.txt", b"world").unwrap();
        o.commit().unwrap();
        assert_eq!(fs::read_to_string(dest.join("b.txt")).unwrap(), "world");
        assert_eq!(fs::read_dir(root.path()).unwrap().count(), 1);
    }
}

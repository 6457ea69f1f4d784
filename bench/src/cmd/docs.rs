//! `simbench docs [--out DIR]`: writes the generated reference (`cli.md`, `scene-format.md`,
//! `dataset-format.md`, `recon-config.md`; see [`crate::docs`]) to DIR, each file atomically.

use anyhow::Context;
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct Args {
    /// Directory the reference pages are written to (created if missing).
    #[arg(long, default_value = "docs/reference")]
    out: PathBuf,
}

/// Writes every reference page of `command` (`simbench`'s clap command) to `args.out`.
pub fn run(args: Args, command: clap::Command) -> anyhow::Result<()> {
    std::fs::create_dir_all(&args.out).with_context(|| format!("creating {}", args.out.display()))?;
    for page in crate::docs::pages(command) {
        let path = args.out.join(page.file_name);
        heatsim::io::write_atomic(&path, page.text.as_bytes())
            .with_context(|| format!("writing {}", path.display()))?;
        eprintln!("simbench: wrote {}", path.display());
    }
    Ok(())
}

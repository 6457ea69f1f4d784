//! The repository's documentation stays true: the generated reference in `docs/reference/`
//! matches what `simbench docs` writes now, and no tracked file names a path on one machine.

use std::path::{Path, PathBuf};
use std::process::Command;

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap().to_path_buf()
}

const PAGES: [&str; 4] = ["cli.md", "scene-format.md", "dataset-format.md", "recon-config.md"];

/// `docs/reference/*.md` are byte for byte what `simbench docs` generates.
#[test]
fn generated_reference_is_up_to_date() {
    let tmp = tempfile::tempdir().unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_simbench"))
        .args(["docs", "--out", tmp.path().to_str().unwrap()])
        .output()
        .expect("simbench runs");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let committed = repo().join("docs/reference");
    let mut stale = Vec::new();
    for page in PAGES {
        let fresh = std::fs::read(tmp.path().join(page)).unwrap_or_else(|e| panic!("{page} not written: {e}"));
        if std::fs::read(committed.join(page)).ok().as_deref() != Some(&fresh[..]) {
            stale.push(page);
        }
    }
    let mut written: Vec<String> =
        std::fs::read_dir(tmp.path()).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    written.sort();
    let mut expected: Vec<String> = PAGES.iter().map(|p| p.to_string()).collect();
    expected.sort();
    assert_eq!(written, expected, "simbench docs writes other pages than this test checks");
    assert!(
        stale.is_empty(),
        "docs/reference/{{{}}} differ from the generated reference: run `cargo run --release -p simbench -- docs` \
         and commit the result",
        stale.join(",")
    );
}

/// Top-level directories whose absolute paths only exist on one machine; the test builds
/// `/DIR/` from them, so this file does not name them itself.
const MACHINE_DIRS: [&str; 3] = ["work", "home", "root"];

/// Whether `line` holds an absolute path starting with one of `prefixes`: the prefix starts a
/// path (line start, after a space, quote, bracket, `=` or `:`), not the tail of a relative one
/// such as `results/x/work/` or `$tmp/root/`.
fn names_machine_path(line: &str, prefixes: &[String]) -> bool {
    prefixes.iter().any(|p| {
        line.match_indices(p.as_str()).any(|(i, _)| {
            let before = line[..i].chars().next_back();
            !before.is_some_and(|c| c.is_alphanumeric() || "_-.*$}/~".contains(c))
        })
    })
}

/// No tracked text file names an absolute path of one machine (under one of [`MACHINE_DIRS`]):
/// documents refer to files relative to the repository (or to its parent for the shared
/// reference folder). Files that are not UTF-8 text (images, arrays) are skipped, and so are
/// `.gitignore` files, whose leading `/` anchors a pattern to their own directory and
/// `Cargo.lock`. Skipped, with a note, when git or the checkout is unavailable (a source
/// tarball).
#[test]
fn no_tracked_file_names_a_machine_path() {
    let root = repo();
    let listed = Command::new("git").arg("-C").arg(&root).args(["ls-files", "-z"]).output();
    let files = match listed {
        Ok(o) if o.status.success() => o.stdout,
        _ => {
            eprintln!("note: not a git checkout or no git: the machine-path check is skipped");
            return;
        }
    };
    let prefixes = MACHINE_DIRS.map(|d| format!("/{d}/"));
    let mut hits = Vec::new();
    for name in files.split(|b| *b == 0).filter(|n| !n.is_empty()) {
        let name = String::from_utf8_lossy(name).into_owned();
        if name.ends_with(".lock") || name.ends_with(".gitignore") {
            continue;
        }
        // Tracked but deleted in the work tree, or not text: nothing to check.
        let Ok(bytes) = std::fs::read(root.join(&name)) else { continue };
        let Ok(text) = String::from_utf8(bytes) else { continue };
        for (i, line) in text.lines().enumerate() {
            if names_machine_path(line, &prefixes) {
                hits.push(format!("{name}:{}: {}", i + 1, line.trim()));
            }
        }
    }
    assert!(hits.is_empty(), "absolute machine paths in tracked files (make them relative):\n{}", hits.join("\n"));
}

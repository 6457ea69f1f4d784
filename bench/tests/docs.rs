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

/// The Markdown files whose relative links [`relative_links_resolve`] checks: the README, the
/// architecture, every page under `docs/` and the scene READMEs.
fn linked_documents(root: &Path) -> Vec<PathBuf> {
    fn walk(dir: &Path, out: &mut Vec<PathBuf>) {
        let Ok(entries) = std::fs::read_dir(dir) else { return };
        let mut entries: Vec<_> = entries.map(|e| e.unwrap().path()).collect();
        entries.sort();
        for p in entries {
            if p.is_dir() {
                walk(&p, out);
            } else if p.extension().is_some_and(|e| e == "md") {
                out.push(p);
            }
        }
    }
    let mut files = vec![root.join("README.md"), root.join("ARCHITECTURE.md")];
    walk(&root.join("docs"), &mut files);
    walk(&root.join("scenes"), &mut files);
    files
}

/// Text outside fenced code blocks, with inline code spans blanked, line by line.
fn prose_lines(text: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut fenced = false;
    for line in text.lines() {
        if line.trim_start().starts_with("```") {
            fenced = !fenced;
            out.push(String::new());
            continue;
        }
        if fenced {
            out.push(String::new());
            continue;
        }
        let mut kept = String::new();
        let mut in_code = false;
        for c in line.chars() {
            if c == '`' {
                in_code = !in_code;
            } else if !in_code {
                kept.push(c);
            }
        }
        out.push(kept);
    }
    out
}

/// Targets of the inline links and images `[text](target)` in `line`.
fn link_targets(line: &str) -> Vec<String> {
    let mut targets = Vec::new();
    let mut rest = line;
    while let Some(i) = rest.find("](") {
        let after = &rest[i + 2..];
        let Some(end) = after.find(')') else { break };
        let target = after[..end].split_whitespace().next().unwrap_or("").to_string();
        targets.push(target);
        rest = &after[end + 1..];
    }
    targets
}

/// GitHub's anchor of a heading: lower case, punctuation dropped (letters, digits, `-` and `_`
/// kept), spaces as hyphens; repeated headings get `-1`, `-2`, ...
fn heading_anchors(text: &str) -> Vec<String> {
    let mut seen: Vec<String> = Vec::new();
    let mut anchors = Vec::new();
    let mut fenced = false;
    for line in text.lines() {
        if line.trim_start().starts_with("```") {
            fenced = !fenced;
            continue;
        }
        if fenced || !line.starts_with('#') {
            continue;
        }
        let title = line.trim_start_matches('#').trim();
        let slug: String = title
            .to_lowercase()
            .chars()
            .filter(|c| c.is_alphanumeric() || *c == '-' || *c == '_' || *c == ' ')
            .map(|c| if c == ' ' { '-' } else { c })
            .collect();
        let n = seen.iter().filter(|s| **s == slug).count();
        anchors.push(if n == 0 { slug.clone() } else { format!("{slug}-{n}") });
        seen.push(slug);
    }
    anchors
}

/// Every relative link (and image) in the README, `ARCHITECTURE.md`, `docs/**/*.md` and the
/// scene READMEs points to a file or directory that exists, and an anchor into a Markdown file
/// names one of its headings, so that moving text between pages cannot leave a dead link.
#[test]
fn relative_links_resolve() {
    let root = repo();
    let mut dead = Vec::new();
    let mut checked = 0;
    for file in linked_documents(&root) {
        let text = std::fs::read_to_string(&file).unwrap_or_else(|e| panic!("{}: {e}", file.display()));
        let name = file.strip_prefix(&root).unwrap().display().to_string();
        for (i, line) in prose_lines(&text).iter().enumerate() {
            for target in link_targets(line) {
                if target.is_empty() || target.contains("://") || target.starts_with("mailto:") {
                    continue;
                }
                checked += 1;
                let (path, anchor) = match target.split_once('#') {
                    Some((p, a)) => (p, Some(a)),
                    None => (target.as_str(), None),
                };
                let resolved = if path.is_empty() { file.clone() } else { file.parent().unwrap().join(path) };
                if !resolved.exists() {
                    dead.push(format!("{name}:{}: {target} (no such file)", i + 1));
                    continue;
                }
                if let Some(anchor) = anchor {
                    if resolved.extension().is_some_and(|e| e == "md") {
                        let linked = std::fs::read_to_string(&resolved).unwrap();
                        if !heading_anchors(&linked).iter().any(|a| a == anchor) {
                            dead.push(format!("{name}:{}: {target} (no such heading)", i + 1));
                        }
                    }
                }
            }
        }
    }
    assert!(checked > 20, "only {checked} relative links found: is the scan broken?");
    assert!(dead.is_empty(), "dead relative links:\n{}", dead.join("\n"));
}

#[test]
fn anchors_follow_github() {
    let text = "# A\n## The thickness sweep (paper Fig. 2)\n## The Cramér–Rao bound\n## A\n```\n# not a heading\n```\n";
    assert_eq!(heading_anchors(text), ["a", "the-thickness-sweep-paper-fig-2", "the-cramérrao-bound", "a-1"]);
    assert_eq!(link_targets("see [x](a.md#b) and ![y](img.png \"t\")"), ["a.md#b", "img.png"]);
    assert_eq!(prose_lines("a `[x](y)` b")[0], "a  b");
}

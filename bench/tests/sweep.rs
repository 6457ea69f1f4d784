//! `simbench sweep thickness` and `simbench merge` end to end, on `--quick` plans: outputs,
//! resume, interruption, shards, bad arguments.

use std::collections::BTreeMap;
use std::path::Path;
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant, SystemTime};

fn simbench(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_simbench")).args(args).output().expect("simbench runs")
}

fn ok(out: &Output) -> String {
    assert!(
        out.status.success(),
        "simbench failed:\nstdout: {}\nstderr: {}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// "ran R cells, skipped S" from the sweep's stdout.
fn ran_skipped(stdout: &str) -> (usize, usize) {
    let line = stdout.lines().find(|l| l.starts_with("sweep: ran ")).expect("a summary line");
    let words: Vec<&str> = line.split_whitespace().collect();
    (words[2].parse().unwrap(), words[5].parse().unwrap())
}

fn csv(path: &Path) -> Vec<Vec<String>> {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    text.lines().map(|l| l.split(',').map(str::to_string).collect()).collect()
}

fn cell_mtimes(dir: &Path) -> BTreeMap<String, SystemTime> {
    std::fs::read_dir(dir.join("cells"))
        .unwrap()
        .flatten()
        .map(|e| (e.file_name().to_string_lossy().into_owned(), e.metadata().unwrap().modified().unwrap()))
        .collect()
}

/// Every file under a final name in `cells/` is a complete cell JSON.
fn assert_cells_complete(dir: &Path) -> usize {
    let mut n = 0;
    for e in std::fs::read_dir(dir.join("cells")).unwrap().flatten() {
        let name = e.file_name().to_string_lossy().into_owned();
        if name.starts_with('.') {
            continue; // a temporary of the killed writer, removed by the next run
        }
        assert!(name.ends_with(".json"), "unexpected file {name}");
        let v: serde_json::Value = serde_json::from_slice(&std::fs::read(e.path()).unwrap())
            .unwrap_or_else(|err| panic!("{name} is not complete JSON: {err}"));
        assert_eq!(v["hash"].as_str().map(str::len), Some(64), "{name}");
        n += 1;
    }
    n
}

#[test]
fn quick_sweep_writes_tables_plots_summary_and_resumes() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("thickness");
    let o = out.to_str().unwrap();
    let first = ok(&simbench(&["sweep", "thickness", "--quick", "--out", o]));
    let (ran, skipped) = ran_skipped(&first);
    assert!(ran > 0);
    assert_eq!(skipped, 0);

    // Part 1: every material at every quick thickness, 0 at the reference, > 0 elsewhere.
    let p1 = csv(&out.join("thickness_vs_reference.csv"));
    assert_eq!(p1[0], ["material", "thickness_m", "mean_abs_err_K", "max_abs_err_K"]);
    assert_eq!(p1.len() - 1, 4 * 4, "4 materials x 4 thicknesses");
    for row in &p1[1..] {
        let d: f64 = row[1].parse().unwrap();
        let (mean, max): (f64, f64) = (row[2].parse().unwrap(), row[3].parse().unwrap());
        assert!(mean.is_finite() && max >= mean, "{row:?}");
        if d == 1e-3 {
            assert_eq!(mean, 0.0, "the reference against itself");
        } else {
            assert!(mean > 1e-3, "thickness changes the video: {row:?}");
        }
    }
    // Part 2: 3 shapes x 1 material x 2 thicknesses x 2 models.
    let p2 = csv(&out.join("surface_vs_volumetric.csv"));
    assert_eq!(p2[0], ["shape", "material", "thickness_m", "model", "pct_err_abs_K", "pct_err_rise"]);
    assert_eq!(p2.len() - 1, 3 * 2 * 2);
    for row in &p2[1..] {
        let (abs, rise): (f64, f64) = (row[4].parse().unwrap(), row[5].parse().unwrap());
        assert!(abs > 0.0 && rise > abs, "the rise is smaller than the absolute temperature: {row:?}");
    }
    for name in ["thickness_vs_reference.png", "surface_vs_volumetric.png"] {
        let bytes = std::fs::read(out.join(name)).unwrap();
        assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n", "{name}");
        assert!(bytes.len() > 10_000, "{name} has content");
    }
    for name in ["thickness_vs_reference.svg", "surface_vs_volumetric.svg"] {
        let text = std::fs::read_to_string(out.join(name)).unwrap();
        assert!(text.contains("<svg") && text.contains("thickness d (m)"), "{name}");
    }
    let summary = std::fs::read_to_string(out.join("summary.md")).unwrap();
    for needle in ["Part 1", "Part 2", "pct_err_rise", "convergence", "Timings"] {
        assert!(summary.contains(needle), "summary.md lacks {needle}");
    }

    // Resume with nothing changed: nothing runs, no cell file is rewritten.
    let before = cell_mtimes(&out);
    let again = ok(&simbench(&["sweep", "thickness", "--quick", "--out", o, "--resume"]));
    assert_eq!(ran_skipped(&again), (0, ran));
    assert_eq!(cell_mtimes(&out), before);

    // A cell whose stored configuration differs (as after a change of code or options) runs
    // again, and only it.
    let cell = out.join("cells/thickness_steel_10000um.json");
    let mut v: serde_json::Value = serde_json::from_slice(&std::fs::read(&cell).unwrap()).unwrap();
    v["hash"] = serde_json::json!("0".repeat(64));
    std::fs::write(&cell, serde_json::to_string(&v).unwrap()).unwrap();
    let third = ok(&simbench(&["sweep", "thickness", "--quick", "--out", o, "--resume"]));
    assert_eq!(ran_skipped(&third), (1, ran - 1));
    let v: serde_json::Value = serde_json::from_slice(&std::fs::read(&cell).unwrap()).unwrap();
    assert_ne!(v["hash"].as_str().unwrap(), "0".repeat(64));
    assert_eq!(v["mesh"]["from_cache"], serde_json::json!(true), "the rerun reuses the cached mesh");
}

#[test]
fn killed_run_leaves_complete_cells_and_resume_finishes() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("killed");
    let o = out.to_str().unwrap();
    let args =
        ["sweep", "thickness", "--quick", "--materials", "polystyrene,glass", "--shapes", "cuboid", "--jobs", "1"];
    let mut child = Command::new(env!("CARGO_BIN_EXE_simbench"))
        .args(args)
        .args(["--out", o])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let t0 = Instant::now();
    loop {
        let n = std::fs::read_dir(out.join("cells")).map(|d| d.count()).unwrap_or(0);
        if n >= 3 || t0.elapsed() > Duration::from_secs(120) {
            break;
        }
        if child.try_wait().unwrap().is_some() {
            panic!("the sweep finished before it could be killed; make the test plan longer");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    child.kill().unwrap(); // SIGKILL: no destructor, no handler runs
    child.wait().unwrap();
    let done = assert_cells_complete(&out);
    assert!(done >= 2, "some cells finished before the kill ({done})");
    assert!(!out.join("summary.md").exists(), "no summary of an unfinished sweep");

    let resumed = ok(&simbench(&[&args[..], &["--out", o, "--resume"]].concat()));
    let (ran, skipped) = ran_skipped(&resumed);
    assert!(skipped == done && ran > 0, "ran {ran}, skipped {skipped}, {done} done before");
    let total = assert_cells_complete(&out);
    assert_eq!(total, ran + skipped);
    let leftovers: Vec<String> = std::fs::read_dir(out.join("cells"))
        .unwrap()
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with('.'))
        .collect();
    assert!(leftovers.is_empty(), "temporaries left: {leftovers:?}");
    assert!(out.join("summary.md").exists());
}

#[test]
fn shards_merged_equal_a_full_run() {
    let tmp = tempfile::tempdir().unwrap();
    let p = |n: &str| tmp.path().join(n).display().to_string();
    let common = ["sweep", "thickness", "--quick", "--materials", "steel,glass", "--shapes", "cuboid"];
    ok(&simbench(&[&common[..], &["--out", &p("full")]].concat()));
    let s1 = ok(&simbench(&[&common[..], &["--out", &p("s1"), "--shard", "1/2"]].concat()));
    let s2 = ok(&simbench(&[&common[..], &["--out", &p("s2"), "--shard", "2/2"]].concat()));
    let (r1, _) = ran_skipped(&s1);
    let (r2, _) = ran_skipped(&s2);
    assert!(r1 > 0 && r2 > 0, "both shards have work");
    assert!(!tmp.path().join("s1/summary.md").exists(), "a shard alone does not summarise");

    // One shard alone is incomplete: merge names what is missing and writes no table.
    let partial = simbench(&["merge", &p("s1"), "--out", &p("partial")]);
    assert!(!partial.status.success());
    let err = String::from_utf8_lossy(&partial.stderr);
    assert!(err.contains("missing"), "{err}");
    assert!(!tmp.path().join("partial/thickness_vs_reference.csv").exists());

    ok(&simbench(&["merge", &p("s1"), &p("s2"), "--out", &p("merged")]));
    for name in ["thickness_vs_reference.csv", "surface_vs_volumetric.csv", "surface_detail.csv"] {
        let full = std::fs::read_to_string(tmp.path().join("full").join(name)).unwrap();
        let merged = std::fs::read_to_string(tmp.path().join("merged").join(name)).unwrap();
        assert!(full.lines().count() > 1);
        assert_eq!(full, merged, "{name} differs between the full run and the merged shards");
    }
    // The convergence table holds run times in its last column; the rest must agree.
    let strip = |dir: &str| -> Vec<Vec<String>> {
        csv(&tmp.path().join(dir).join("mesh_convergence.csv"))
            .into_iter()
            .map(|mut r| {
                r.pop();
                r
            })
            .collect()
    };
    assert_eq!(strip("full"), strip("merged"));
    assert!(tmp.path().join("merged/summary.md").exists());
    assert!(tmp.path().join("merged/surface_vs_volumetric.png").exists());
}

#[test]
fn bad_arguments_are_clear_errors() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("bad");
    let o = out.to_str().unwrap();
    let cases: [(&[&str], &str); 4] = [
        (&["--shard", "3/2"], "1 <= K <= N"),
        (&["--shard", "two"], "K/N"),
        (&["--materials", "polystyrene,unobtainium"], "unknown material \"unobtainium\""),
        (&["--jobs", "0"], "--jobs"),
    ];
    for (extra, needle) in cases {
        let r = simbench(&[&["sweep", "thickness", "--quick", "--out", o][..], extra].concat());
        assert!(!r.status.success(), "{extra:?} should fail");
        let err = String::from_utf8_lossy(&r.stderr);
        assert!(err.contains(needle), "{extra:?}: {err}");
        assert!(!err.contains("panicked"), "{err}");
        assert!(!out.exists(), "{extra:?} wrote {}", out.display());
    }
    let r = simbench(&["merge", tmp.path().join("nowhere").to_str().unwrap(), "--out", o]);
    assert!(!r.status.success());
    assert!(String::from_utf8_lossy(&r.stderr).contains("plan.json"));
}

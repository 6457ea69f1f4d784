//! `simbench suite`: a built suite is the bytes its manifest records, built the same at any
//! thread count and filmed exactly as `simbench simulate` films; tampering is refused naming
//! the file; any method runs (built-in, plane, an external command, the Python example), its
//! failures are recorded, runs resume and shards merge; bad input is refused.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use serde_json::Value;

fn simbench_env(args: &[&str], env: &[(&str, &str)]) -> Output {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_simbench"));
    cmd.args(args);
    for (k, v) in env {
        cmd.env(k, v);
    }
    cmd.output().expect("simbench runs")
}

fn simbench(args: &[&str]) -> Output {
    simbench_env(args, &[])
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

fn fails_with(args: &[&str], needles: &[&str]) -> String {
    let out = simbench(args);
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(out.status.code(), Some(1), "{args:?} should exit 1; stderr: {err}");
    assert!(!err.contains("panicked"), "{args:?} panicked: {err}");
    for n in needles {
        assert!(err.contains(n), "{args:?}: stderr should mention `{n}`: {err}");
    }
    err
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

fn build_tiny(dir: &Path, threads: &str) -> PathBuf {
    let out = dir.join(format!("suite-{threads}"));
    ok(&simbench_env(&["suite", "build", "--tier", "tiny", "--out", s(&out)], &[("RAYON_NUM_THREADS", threads)]));
    out
}

/// Builds in `dir/suite` the tiny tier's spec named `name` and changed by `edit`.
fn build_tiny_variant(dir: &Path, name: &str, edit: impl FnOnce(&mut Value)) -> PathBuf {
    build_variant(dir, "tiny", name, &dir.join("suite"), edit)
}

/// Builds in `out` the shipped tier `tier`'s spec (`suites/<tier>.json`) named `name` and
/// changed by `edit`.
fn build_variant(dir: &Path, tier: &str, name: &str, out: &Path, edit: impl FnOnce(&mut Value)) -> PathBuf {
    let spec_file = Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("../suites/{tier}.json"));
    let mut spec: Value = serde_json::from_str(&std::fs::read_to_string(&spec_file).unwrap()).unwrap();
    spec["name"] = name.into();
    edit(&mut spec);
    let spec_path = dir.join(format!("{name}.json"));
    std::fs::write(&spec_path, spec.to_string()).unwrap();
    ok(&simbench(&["suite", "build", "--spec", s(&spec_path), "--out", s(out)]));
    out.to_path_buf()
}

/// The shipped tiers, as `suite build --tier` lists them when refusing an unknown one.
fn shipped_tiers() -> Vec<String> {
    let dir = tempfile::tempdir().unwrap();
    let err =
        fails_with(&["suite", "build", "--tier", "no-such-tier", "--out", s(&dir.path().join("x"))], &["known: "]);
    let list = err.split("known: ").nth(1).unwrap().lines().next().unwrap();
    list.split(',').map(|t| t.trim().to_string()).filter(|t| !t.is_empty()).collect()
}

/// The interpreter of the oracle environment (`scripts/setup-oracles.sh`), or `None` (the test
/// is skipped) when it is missing and the test command's `HEATSIM_REQUIRE_ASSETS` is not set.
fn venv_python() -> Option<PathBuf> {
    let python = Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap().join(".venv/bin/python");
    if python.is_file() {
        return Some(python);
    }
    assert!(
        std::env::var_os("HEATSIM_REQUIRE_ASSETS").is_none(),
        "{} is missing: run scripts/setup-oracles.sh",
        python.display()
    );
    eprintln!("skipped: no {}", python.display());
    None
}

fn json(path: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

fn records(run: &Path) -> Vec<Value> {
    let info = json(&run.join("run.json"));
    info["cases"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| json(&run.join("cases").join(format!("{}.json", c.as_str().unwrap()))))
        .collect()
}

#[test]
fn a_suite_is_its_manifest_and_builds_the_same_at_any_thread_count() {
    let dir = tempfile::tempdir().unwrap();
    let one = build_tiny(dir.path(), "1");
    let two = build_tiny(dir.path(), "2");
    let m1 = std::fs::read(one.join("suite.json")).unwrap();
    assert_eq!(m1, std::fs::read(two.join("suite.json")).unwrap(), "suite.json differs between 1 and 2 threads");
    let m = json(&one.join("suite.json"));
    assert!(m["version"].as_str().unwrap().starts_with("tiny-f1-"));
    assert_eq!(m["cases"].as_array().unwrap().len(), 4, "noise-free once, 50 mK with 3 seeds");
    // Every stored file of both builds is the recorded bytes.
    for o in m["objects"].as_array().unwrap() {
        for (rel, _) in o["files"].as_object().unwrap() {
            assert_eq!(std::fs::read(one.join(rel)).unwrap(), std::fs::read(two.join(rel)).unwrap(), "{rel}");
        }
    }
    let out = ok(&simbench(&["suite", "verify", s(&one), "--deep"]));
    // 4 cases x 2 views x 7 files (video, times, mask, camera, environment, material, lamps).
    assert!(out.contains("56 case inputs re-filmed"), "{out}");
    // Building again into the same folder keeps the object and gives the same manifest.
    ok(&simbench(&["suite", "build", "--tier", "tiny", "--out", s(&one)]));
    assert_eq!(m1, std::fs::read(one.join("suite.json")).unwrap());
    // Another spec into the same folder is refused.
    fails_with(&["suite", "build", "--tier", "quick", "--out", s(&one)], &["another spec"]);
}

#[test]
fn a_case_video_is_what_simulate_films_with_the_same_seed() {
    let dir = tempfile::tempdir().unwrap();
    let suite = build_tiny(dir.path(), "2");
    let m = json(&suite.join("suite.json"));
    let case = m["cases"].as_array().unwrap().iter().find(|c| c["seed"] == 2).unwrap().clone();
    let object_dir = suite.join("objects").join(case["object"].as_str().unwrap());
    let mut scene = json(&object_dir.join("scene.json"));
    let cam = &mut scene["camera"];
    cam["netd"] = 0.05.into();
    cam["fixed_pattern_sigma"] = 0.025.into();
    cam["quantization"] = 0.01.into();
    cam["seed"] = case["sensor_seeds"]["left"].clone();
    let scene_path = dir.path().join("noisy.json");
    std::fs::write(&scene_path, scene.to_string()).unwrap();
    let sim = dir.path().join("sim");
    ok(&simbench(&["simulate", s(&scene_path), "--out", s(&sim), "--vtu-frames", "0"]));
    let run = dir.path().join("run");
    ok(&simbench(&["suite", "run", s(&suite), "--out", s(&run), "--method", "plane", "--keep-work"]));
    let inputs = run.join("work").join(case["id"].as_str().unwrap()).join("left");
    for f in ["video.npy", "mask.npy", "times.npy"] {
        assert_eq!(std::fs::read(sim.join("left").join(f)).unwrap(), std::fs::read(inputs.join(f)).unwrap(), "{f}");
    }
    // What a method is handed: no ground truth, no film, no lamps without --lamps, and no
    // ground-truth convection in environment.json.
    let names: Vec<String> =
        std::fs::read_dir(&inputs).unwrap().map(|e| e.unwrap().file_name().into_string().unwrap()).collect();
    for n in &names {
        assert!(!n.starts_with("gt_") && n != "film.npy" && n != "lamps.json" && n != "meta.json", "method input {n}");
    }
    assert!(json(&inputs.join("environment.json")).get("convection_coefficient").is_none());
}

#[test]
fn a_tampered_or_incomplete_suite_is_refused_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let suite = build_tiny(dir.path(), "2");
    let object = std::fs::read_dir(suite.join("objects")).unwrap().next().unwrap().unwrap().path();
    let film = object.join("left").join("film.npy");
    let mut bytes = std::fs::read(&film).unwrap();
    let last = bytes.len() - 1;
    bytes[last] ^= 1;
    std::fs::write(&film, &bytes).unwrap();
    fails_with(&["suite", "verify", s(&suite)], &["film.npy", "altered"]);
    let run = dir.path().join("run");
    fails_with(&["suite", "run", s(&suite), "--out", s(&run), "--method", "plane"], &["film.npy"]);
    std::fs::remove_file(&film).unwrap();
    fails_with(&["suite", "verify", s(&suite)], &["film.npy", "missing"]);
    // An edited manifest and another format version.
    let manifest = suite.join("suite.json");
    let text = std::fs::read_to_string(&manifest).unwrap();
    std::fs::write(&manifest, text.replacen("\"seed\": 2", "\"seed\": 7", 1)).unwrap();
    fails_with(&["suite", "verify", s(&suite)], &["suite.json", "altered"]);
    std::fs::write(&manifest, text.replacen("\"format\": 1", "\"format\": 99", 1)).unwrap();
    fails_with(&["suite", "verify", s(&suite)], &["suite.json", "format 99"]);
    fails_with(&["suite", "verify", s(dir.path())], &["not a suite"]);
}

#[test]
fn failing_methods_are_recorded_and_runs_resume() {
    let dir = tempfile::tempdir().unwrap();
    let suite = build_tiny(dir.path(), "2");
    let script = |name: &str, body: &str| {
        let p = dir.path().join(name);
        std::fs::write(&p, body).unwrap();
        p
    };
    let crash = script("crash.sh", "echo 'error: I crash' >&2\nexit 3\n");
    // The hanging method's grandchild writes its pid: the time limit must kill the whole group.
    let sleeper = dir.path().join("sleeper.pid");
    let hang = script("hang.sh", &format!("sleep 60 &\necho $! > {}\nwait\n", sleeper.display()));
    let garbage = script("garbage.sh", "echo 'not a mesh' > \"$1/recon_world.obj\"\n");
    let silent = script("silent.sh", "exit 0\n");
    for (path, kind) in [(&crash, "crash"), (&hang, "timeout"), (&garbage, "malformed_output"), (&silent, "no_output")]
    {
        let run = dir.path().join(format!("run-{kind}"));
        let cmd = format!("sh {} {{out}}", path.display());
        let t = std::time::Instant::now();
        ok(&simbench(&[
            "suite",
            "run",
            s(&suite),
            "--out",
            s(&run),
            "--method-cmd",
            &cmd,
            "--timeout",
            "2",
            "--shard",
            "1/4",
        ]));
        assert!(t.elapsed().as_secs_f64() < 30.0, "{kind}: the time limit did not stop the method");
        if kind == "timeout" {
            let pid = std::fs::read_to_string(&sleeper).unwrap();
            let alive = |pid: &str| {
                std::fs::read_to_string(format!("/proc/{}/stat", pid.trim()))
                    .is_ok_and(|stat| stat.rsplit(')').next().is_some_and(|rest| !rest.trim_start().starts_with('Z')))
            };
            let t = std::time::Instant::now();
            while alive(&pid) && t.elapsed().as_secs_f64() < 5.0 {
                std::thread::sleep(std::time::Duration::from_millis(50));
            }
            assert!(!alive(&pid), "the method's child {} outlived the time limit", pid.trim());
        }
        let recs = records(&run);
        assert_eq!(recs.len(), 1);
        assert_eq!(recs[0]["status"], "failed", "{kind}");
        assert_eq!(recs[0]["failure"]["kind"], kind, "{:?}", recs[0]);
    }
    // The plane baseline, resumed: a second run skips every case; another method into the same
    // folder is refused.
    let run = dir.path().join("plane");
    ok(&simbench(&["suite", "run", s(&suite), "--out", s(&run), "--method", "plane"]));
    let first = records(&run);
    assert!(first.iter().all(|r| r["status"] == "ok" && r["scores"]["mae_mm"].as_f64().unwrap() > 0.0));
    assert!(
        first.iter().all(|r| (r["scores"]["size_error"].as_f64().unwrap()).abs() < 0.05),
        "the plane sits at the true mean depth"
    );
    let again = ok(&simbench(&["suite", "run", s(&suite), "--out", s(&run), "--method", "plane"]));
    assert!(again.contains("0 cases run") && again.contains("4 already done"), "{again}");
    fails_with(&["suite", "run", s(&suite), "--out", s(&run), "--method-cmd", "true {out}"], &["choose another --out"]);
    ok(&simbench(&["suite", "report", s(&run)]));
    assert!(run.join("report/report.md").is_file() && run.join("report/errors.png").is_file());
    // The map gathers a run per object and noise level, with its heating from the suite.
    let map = dir.path().join("map");
    ok(&simbench(&["suite", "map", "--run", s(&suite), s(&run), "--out", s(&map)]));
    let csv = std::fs::read_to_string(map.join("map.csv")).unwrap();
    let rows: Vec<&str> = csv.lines().skip(1).collect();
    assert_eq!(rows.len(), 2, "noise-free and 50 mK: {csv}");
    assert!(rows[1].starts_with("hemisphere-surface-d0.001,50,250,10,2500,3,0,0.0,"), "{csv}");
    assert_eq!(&std::fs::read(map.join("map.png")).unwrap()[1..4], b"PNG");
    // Shards merge into the same records (scores are deterministic).
    let shards: Vec<PathBuf> = (1..=2).map(|k| dir.path().join(format!("shard-{k}"))).collect();
    for (k, sh) in shards.iter().enumerate() {
        ok(&simbench(&[
            "suite",
            "run",
            s(&suite),
            "--out",
            s(sh),
            "--method",
            "plane",
            "--shard",
            &format!("{}/2", k + 1),
        ]));
    }
    let merged = dir.path().join("merged");
    fails_with(&["suite", "merge", s(&shards[0]), "--out", s(&merged)], &["shards 1/2 to 2/2"]);
    ok(&simbench(&["suite", "merge", s(&shards[1]), s(&shards[0]), "--out", s(&merged)]));
    let m = records(&merged);
    assert_eq!(m.len(), first.len());
    for (a, b) in m.iter().zip(&first) {
        assert_eq!(a["case"], b["case"]);
        assert_eq!(a["scores"], b["scores"]);
    }
}

#[test]
fn bad_arguments_are_refused_and_nothing_is_written() {
    let dir = tempfile::tempdir().unwrap();
    let suite = build_tiny(dir.path(), "2");
    let run = dir.path().join("run");
    fails_with(
        &["suite", "run", s(&suite), "--out", s(&run), "--method-cmd", "python3 m.py {left} {right}"],
        &["{out}"],
    );
    fails_with(
        &["suite", "run", s(&suite), "--out", s(&run), "--method", "plane", "--shard", "3/2"],
        &["--shard", "3/2"],
    );
    fails_with(&["suite", "run", s(&suite), "--out", s(&run), "--method", "magic"], &["unknown method"]);
    fails_with(&["suite", "run", s(&suite), "--out", s(&run), "--method", "builtin:fast"], &["fast"]);
    assert!(!run.exists(), "a refused run wrote its folder");
    fails_with(&["suite", "build", "--tier", "huge", "--out", s(&dir.path().join("x"))], &["unknown tier"]);
    let spec = dir.path().join("spec.json");
    std::fs::write(&spec, "{\"name\": \"x\"}").unwrap();
    fails_with(&["suite", "build", "--spec", s(&spec), "--out", s(&dir.path().join("y"))], &["spec.json"]);
    fails_with(&["suite", "report", s(dir.path())], &["not a suite run"]);
}

/// The Python example method (numpy only) through `--method-cmd`, with the oracle environment's
/// interpreter (`scripts/setup-oracles.sh`).
#[test]
fn the_python_example_method_runs_through_the_contract() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap();
    let Some(python) = venv_python() else { return };
    let dir = tempfile::tempdir().unwrap();
    let suite = build_tiny(dir.path(), "2");
    let run = dir.path().join("run");
    // The template's relative path resolves against the directory `suite run` starts in.
    let cmd = format!("{} examples/methods/inflate_silhouette.py {{left}} {{right}} {{out}}", python.display());
    let out = Command::new(env!("CARGO_BIN_EXE_simbench"))
        .args(["suite", "run", s(&suite), "--out", s(&run), "--method-cmd", &cmd])
        .current_dir(root)
        .output()
        .unwrap();
    ok(&out);
    for r in records(&run) {
        assert_eq!(r["status"], "ok", "{r}");
        let mae = r["scores"]["mae_mm"].as_f64().unwrap();
        assert!(mae > 0.1 && mae < 30.0, "{mae}");
    }
}

/// The shipped tiers the oracle test covers, and those it leaves out with the reason.
const ORACLE_TIERS: [&str; 2] = ["tiny", "quick"];
const ORACLE_SKIPPED: [(&str, &str); 1] = [("full", "its build takes 19 min (412 s of simulation)")];
/// The rigid and the similarity MAE the truth may score, m (0.01 mm).
const ORACLE_MAX_MAE_M: f64 = 1e-5;
/// The size error the truth may score (relative: 0.001 %, 3 um at 0.3 m). Rigid ICP undoes
/// a rigid offset of the whole surface; the size error, measured without alignment, does not.
const ORACLE_MAX_SIZE_ERROR: f64 = 1e-5;

/// Runs `examples/methods/truth_oracle.py` through `--method-cmd` on every case of `suite`
/// (`checker_m` its depth checkerboard), into `run`; returns the case records, checking that
/// every case of the manifest has one.
fn run_oracle(python: &Path, suite: &Path, run: &Path, checker_m: f64) -> Vec<Value> {
    let oracle = Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap().join("examples/methods/truth_oracle.py");
    let cmd =
        format!("'{}' '{}' '{}' {{case}} {{out}} {checker_m}", python.display(), oracle.display(), suite.display());
    ok(&simbench(&["suite", "run", s(suite), "--out", s(run), "--method-cmd", &cmd]));
    let recs = records(run);
    let manifest = json(&suite.join("suite.json"));
    let ids: Vec<&Value> = manifest["cases"].as_array().unwrap().iter().map(|c| &c["id"]).collect();
    assert_eq!(recs.iter().map(|r| &r["case"]).collect::<Vec<_>>(), ids, "{}: not every case was run", run.display());
    recs
}

/// Why a case's record is not what the truth must score (`None`: it is).
fn oracle_check(r: &Value) -> Option<String> {
    if r["status"] != "ok" {
        return Some(format!("the case failed: {}", r["failure"]));
    }
    let score = |k: &str| r["scores"][k].as_f64().unwrap_or(f64::NAN);
    let (rigid, similarity, size) = (score("mae_mm") * 1e-3, score("similarity_mae_mm") * 1e-3, score("size_error"));
    // NaN (a score missing) is never within its limit.
    let within = |x: f64, limit: f64| x <= limit;
    let mut why = Vec::new();
    if !within(rigid, ORACLE_MAX_MAE_M) {
        why.push(format!("rigid MAE {:.3e} mm (at most {} mm)", rigid * 1e3, ORACLE_MAX_MAE_M * 1e3));
    }
    if !within(similarity, ORACLE_MAX_MAE_M) {
        why.push(format!("similarity MAE {:.3e} mm (at most {} mm)", similarity * 1e3, ORACLE_MAX_MAE_M * 1e3));
    }
    if !within(size.abs(), ORACLE_MAX_SIZE_ERROR) {
        why.push(format!("size error {size:.2e} (at most {ORACLE_MAX_SIZE_ERROR:e})"));
    }
    (!why.is_empty()).then(|| why.join(", "))
}

/// The oracle scores zero: each case's visible truth, un-projected from its `gt_depth.npy` and
/// handed back through the `--method-cmd` contract (`examples/methods/truth_oracle.py`), scores
/// a rigid and a similarity MAE of at most 0.01 mm and a size error of at most 0.001 % on
/// every case of every shipped tier but those too costly for the test command
/// (`ORACLE_SKIPPED`), so that no tier's scoring drifts from its truth unnoticed. The tiers
/// are built without their Cramér–Rao bounds (the `bound` section dropped: the same objects
/// and cases, and bounds are not scores). A new shipped tier fails the test until it is
/// covered or skipped. And the check bites: the oracle with a 1 mm checkerboard in depth fails
/// it on every case of the tiny tier.
#[test]
fn the_oracle_scores_zero_on_every_tier() {
    let Some(python) = venv_python() else { return };
    let uncovered: Vec<String> = shipped_tiers()
        .into_iter()
        .filter(|t| !ORACLE_TIERS.contains(&t.as_str()) && !ORACLE_SKIPPED.iter().any(|(s, _)| s == t))
        .collect();
    assert!(
        uncovered.is_empty(),
        "shipped tiers {uncovered:?} are not checked by the oracle: add them to ORACLE_TIERS (or, if too costly for the test command, to ORACLE_SKIPPED with the reason)"
    );
    let dir = tempfile::tempdir().unwrap();
    for tier in ORACLE_TIERS {
        let t = std::time::Instant::now();
        let suite = build_variant(dir.path(), tier, &format!("{tier}-oracle"), &dir.path().join(tier), |spec| {
            spec.as_object_mut().unwrap().remove("bound");
        });
        let built = t.elapsed().as_secs_f64();
        let recs = run_oracle(&python, &suite, &dir.path().join(format!("run-{tier}")), 0.0);
        for r in &recs {
            if let Some(why) = oracle_check(r) {
                panic!(
                    "tier {tier}, case {}: the truth itself scores {why}: the scoring has drifted from the truth",
                    r["case"].as_str().unwrap()
                );
            }
        }
        let worst = recs
            .iter()
            .max_by(|a, b| a["scores"]["mae_mm"].as_f64().partial_cmp(&b["scores"]["mae_mm"].as_f64()).unwrap())
            .unwrap();
        eprintln!(
            "oracle: tier {tier}: {} cases, max rigid MAE {:.2e} mm ({}); built in {built:.0} s, run in {:.0} s",
            recs.len(),
            worst["scores"]["mae_mm"].as_f64().unwrap(),
            worst["case"].as_str().unwrap(),
            t.elapsed().as_secs_f64() - built
        );
    }
    for r in run_oracle(&python, &dir.path().join("tiny"), &dir.path().join("run-checker"), 1e-3) {
        assert!(
            oracle_check(&r).is_some(),
            "case {}: the truth with a 1 mm checkerboard passes the oracle check: {r}",
            r["case"].as_str().unwrap()
        );
    }
}

/// `compare` end to end with a scripted method (the truth perturbed by a random amount,
/// `tests/support/perturbed_truth.py`) on a suite of 12 seeds at 50 mK: a fresh draw of the same
/// method is not called worse, a method 1.5 times worse is (exit 1); runs of another suite are
/// refused. (The false-alarm rate and the power over repeated draws are measured by the
/// statistics' own tests and by `simbench suite power`.)
#[test]
fn compare_tells_a_worse_method_from_a_fresh_draw() {
    let dir = tempfile::tempdir().unwrap();
    let suite = build_tiny_variant(dir.path(), "seeds", |spec| {
        spec["seeds"] = 12.into();
        spec.as_object_mut().unwrap().remove("bound");
    });
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/support/perturbed_truth.py");
    let run = |name: &str, factor: &str, draw: &str| {
        let out = dir.path().join(name);
        let cmd = format!("python3 {} {} {{case}} {{out}} {factor} {draw} 0.3", script.display(), suite.display());
        ok(&simbench(&["suite", "run", s(&suite), "--out", s(&out), "--method-cmd", &cmd]));
        out
    };
    let base = run("base", "1.0", "1");
    let same = run("same", "1.0", "2");
    let worse = run("worse", "1.5", "3");
    let text = ok(&simbench(&["suite", "compare", s(&base), s(&same)]));
    assert!(text.contains("No group is significantly worse"), "{text}");
    let png = std::fs::read(same.join("compare/compare.png")).unwrap();
    assert_eq!(&png[1..4], b"PNG", "compare writes a plot");
    let c = json(&same.join("compare/compare.json"));
    let level = c["groups"].as_array().unwrap().iter().find(|g| g["noise"] == "NETD 50 mK").unwrap();
    assert_eq!(level["judgement"]["error"]["n"], 12);
    let err = fails_with(&["suite", "compare", s(&base), s(&worse)], &["significantly worse"]);
    let c = json(&worse.join("compare/compare.json"));
    let level = c["groups"].as_array().unwrap().iter().find(|g| g["noise"] == "NETD 50 mK").unwrap();
    assert_eq!(level["judgement"]["verdict"], "Worse", "{err}");
    let ratio = level["judgement"]["error"]["ratio"].as_f64().unwrap();
    assert!(ratio > 1.2 && ratio < 1.9, "geometric mean change {ratio}, scripted 1.5");
    // Runs with different cases (here one case dropped from a copy's run.json) are refused.
    let fewer = dir.path().join("fewer");
    std::fs::create_dir_all(fewer.join("cases")).unwrap();
    let mut info = json(&same.join("run.json"));
    let dropped = info["cases"].as_array_mut().unwrap().pop().unwrap();
    std::fs::write(fewer.join("run.json"), info.to_string()).unwrap();
    for c in info["cases"].as_array().unwrap() {
        let name = format!("{}.json", c.as_str().unwrap());
        std::fs::copy(same.join("cases").join(&name), fewer.join("cases").join(&name)).unwrap();
    }
    fails_with(&["suite", "compare", s(&base), s(&fewer)], &["different cases", dropped.as_str().unwrap()]);
    // A run of another suite is refused, naming both versions.
    let tiny = build_tiny(dir.path(), "2");
    let other = dir.path().join("other");
    ok(&simbench(&["suite", "run", s(&tiny), "--out", s(&other), "--method", "plane"]));
    fails_with(&["suite", "compare", s(&base), s(&other)], &["different suites", "tiny-f1-"]);
    let map = dir.path().join("map");
    fails_with(
        &["suite", "map", "--run", s(&suite), s(&other), "--out", s(&map)],
        &["a run of suite tiny-f1-", "seeds-f1-"],
    );
    assert!(!map.exists(), "a refused map wrote its folder");
}

/// `suite bound` adds the bound of an object the spec did not mark, in the spec's family, to a
/// built suite without changing its version; a run resumed afterwards carries it to its
/// report. An object the suite does not hold is refused, naming it, with nothing written.
#[test]
fn bounds_are_added_to_a_built_suite_and_reach_a_resumed_run() {
    let dir = tempfile::tempdir().unwrap();
    let suite = build_tiny_variant(dir.path(), "unbounded", |spec| spec["bound"]["objects"] = serde_json::json!([]));
    assert_eq!(json(&suite.join("bounds.json")), serde_json::json!([]));
    let manifest = std::fs::read(suite.join("suite.json")).unwrap();
    let run = dir.path().join("run");
    ok(&simbench(&["suite", "run", s(&suite), "--out", s(&run), "--method", "plane"]));
    assert_eq!(json(&run.join("bounds.json")), serde_json::json!([]));

    fails_with(&["suite", "bound", s(&suite), "--objects", "teapot"], &["no object \"teapot\"", "hemisphere"]);
    assert_eq!(json(&suite.join("bounds.json")), serde_json::json!([]), "nothing written");

    ok(&simbench(&["suite", "bound", s(&suite), "--objects", "hemisphere"]));
    let bounds = json(&suite.join("bounds.json"));
    let b = bounds.as_array().unwrap();
    assert_eq!(b.len(), 1, "{bounds}");
    assert_eq!(b[0]["object"], "hemisphere-surface-d0.001");
    assert_eq!(b[0]["netd_mk"], 50.0);
    assert_eq!((b[0]["level"].as_u64(), b[0]["degree"].as_u64()), (Some(1), Some(2)), "the spec's family");
    for row in b[0]["rows"].as_array().unwrap() {
        let mae = row["expected_mae_mm"].as_f64().unwrap();
        assert!(mae.is_finite() && mae > 0.0, "{row}");
    }
    // The flux projections' convergence is stored with the bound.
    let (residual, iterations) = (b[0]["projection_residual"].as_f64(), b[0]["projection_iterations"].as_u64());
    assert!(residual.is_some_and(|r| r.is_finite() && r >= 0.0), "{}", b[0]);
    let limit = json(&suite.join("suite.json"))["spec"]["bound"]["max_iterations"].as_u64().unwrap();
    assert!(iterations.is_some_and(|n| (1..=limit).contains(&n)), "at most the spec's {limit}: {}", b[0]);
    assert_eq!(std::fs::read(suite.join("suite.json")).unwrap(), manifest, "the manifest is untouched");
    ok(&simbench(&["suite", "verify", s(&suite)]));

    // Resuming the finished run refreshes its bounds; the report prints them.
    ok(&simbench(&["suite", "run", s(&suite), "--out", s(&run), "--method", "plane"]));
    assert_eq!(json(&run.join("bounds.json")), bounds);
    let md = ok(&simbench(&["suite", "report", s(&run)]));
    let unknown =
        b[0]["rows"].as_array().unwrap().iter().find(|r| r["fluxes"] == "unknown" && r["globals"] == "unknown");
    let cell = format!("{:.2}", unknown.unwrap()["expected_mae_mm"].as_f64().unwrap());
    let row = md.lines().find(|l| l.contains("hemisphere") && l.contains("50 mK")).unwrap();
    assert!(row.contains(&cell), "the report's row prints the bound {cell}: {row}");
    assert!(md.contains("The flux projections (CGLS)"), "the report says whether they converged: {md}");
}

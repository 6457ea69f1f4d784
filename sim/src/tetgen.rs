//! Quality tetrahedral meshing with TetGen (through `tritet`), contained in a child process.
//!
//! TetGen is C++ with process-wide state. Fed a bad piecewise linear complex (PLC) it can
//! throw (which `tritet` catches, prints `status = N` to *stdout* and then reports success with
//! an empty mesh), abort, crash or loop. This module therefore runs it in a `fork`ed child
//! whose stdout and stderr go to a log file, waits with a time limit, and turns every outcome
//! into a [`MeshingError`] naming what went wrong. A side benefit: separate processes make
//! TetGen safe to call from several threads at once.
//!
//! The switches are `-pzAfq<ratio>a`: a PLC, zero-based numbering, regional attributes and
//! regional maximum volumes, all faces, and a bound on the radius-edge ratio.
//!
//! TetGen is licensed under the AGPL-3.0; linking it makes the binaries of this project
//! AGPL-3.0 as well (see the README's licence section).

use crate::solid::Plc;
use std::fs::File;
use std::io::{Read, Write};
use std::path::Path;
use std::time::{Duration, Instant};

/// Options for one TetGen run.
#[derive(Clone, Debug)]
pub struct TetgenOptions {
    /// Upper bound on the radius-edge ratio of every tetrahedron (TetGen `-q`); TetGen's
    /// default is 2.0, values near 1.1 are the practical minimum.
    pub radius_edge_ratio: f64,
    /// Global maximum tetrahedron volume in m^3 (TetGen `-a`), on top of the regional bounds.
    pub max_volume: Option<f64>,
    /// Wall-clock limit for the TetGen child process.
    pub timeout: Duration,
}

impl Default for TetgenOptions {
    fn default() -> Self {
        Self { radius_edge_ratio: 1.5, max_volume: None, timeout: Duration::from_secs(600) }
    }
}

/// The raw TetGen output: nodes, tetrahedra with their region attribute, marked faces.
#[derive(Clone, Debug, Default)]
pub struct TetgenOutput {
    /// #N x 3 node coordinates (m).
    pub points: Vec<[f64; 3]>,
    /// #T x 4 node indices, in TetGen's order (orientation is fixed by [`crate::mesh::tetmesh`]).
    pub tets: Vec<[usize; 4]>,
    /// #T region attribute of each tetrahedron (the `attribute` of the enclosing [`crate::solid::Region`]).
    pub tet_region: Vec<i32>,
    /// Faces carrying a facet marker: the three nodes and the marker (0 = none).
    pub marked_faces: Vec<([usize; 3], i32)>,
}

/// What can go wrong while meshing; bad input is caught before TetGen runs.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum MeshingError {
    /// The PLC handed to TetGen is malformed (found by [`Plc::validate`]).
    #[error("invalid solid description: {0}")]
    InvalidPlc(String),
    /// TetGen stopped with one of its error codes.
    #[error("TetGen stopped with status {status} ({meaning}){log}", log = log_tail(log))]
    TetgenStatus { status: i32, meaning: &'static str, log: String },
    /// TetGen finished but produced no tetrahedra.
    #[error("TetGen produced an empty mesh{log}", log = log_tail(log))]
    Empty { log: String },
    /// The TetGen child process died (abort, segmentation fault, out of memory).
    #[error("TetGen crashed ({how}){log}", log = log_tail(log))]
    Crashed { how: String, log: String },
    /// TetGen ran past the time limit and was killed.
    #[error("TetGen did not finish within {seconds} s and was stopped; try a coarser mesh (meshing.surface_element_size) or a larger meshing.timeout_seconds")]
    Timeout { seconds: f64 },
    /// The mesh exceeds the allowed number of tetrahedra.
    #[error("the mesh has {count} tetrahedra, more than meshing.max_tetrahedra = {limit}; coarsen meshing.surface_element_size or raise the limit")]
    TooLarge { count: usize, limit: u64 },
    /// A tetrahedron of TetGen's output has (numerically) zero volume.
    #[error("tetrahedron {tet} (nodes {nodes:?}) has volume {volume:e} m^3; the mesh is degenerate")]
    DegenerateTet { tet: usize, nodes: [usize; 4], volume: f64 },
    #[error("the reference mesh has no boundary faces to take tags from")]
    NoBoundary,
    /// Temporary files for the child process could not be created or read.
    #[error("meshing I/O: {0}")]
    Io(#[from] std::io::Error),
    /// This build of heatsim has no TetGen (built without the feature `tetgen`).
    #[error("this build has no TetGen: heatsim was built without its feature `tetgen`")]
    Unavailable,
}

fn log_tail(log: &str) -> String {
    let lines: Vec<&str> = log.lines().filter(|l| !l.trim().is_empty()).collect();
    if lines.is_empty() {
        return String::new();
    }
    let start = lines.len().saturating_sub(6);
    format!("; TetGen said: {}", lines[start..].join(" | "))
}

/// The meaning of TetGen's `terminatetetgen` codes (tetgen.h).
fn status_meaning(status: i32) -> &'static str {
    match status {
        1 => "out of memory",
        2 => "internal error",
        3 => "self-intersecting input facets",
        4 => "an input feature smaller than the tolerance",
        5 => "two very close input facets",
        10 => "an input error",
        _ => "unknown status",
    }
}

/// Tetrahedralises `plc` with TetGen in a child process.
///
/// # Errors
/// [`MeshingError`] for an invalid PLC, a TetGen error status, an empty result, a crash or a
/// time-out.
pub fn tetrahedralize(plc: &Plc, opts: &TetgenOptions) -> Result<TetgenOutput, MeshingError> {
    plc.validate().map_err(MeshingError::InvalidPlc)?;
    if !cfg!(feature = "tetgen") {
        return Err(MeshingError::Unavailable);
    }
    let dir = tempfile::Builder::new().prefix("heatsim-tetgen").tempdir()?;
    let log_path = dir.path().join("tetgen.log");
    let out_path = dir.path().join("mesh.bin");
    let status = run_in_child(&log_path, opts.timeout, || run_tetgen(plc, opts, &out_path))?;
    let log = std::fs::read_to_string(&log_path).unwrap_or_default();
    if let Some(code) = thrown_status(&log) {
        return Err(MeshingError::TetgenStatus { status: code, meaning: status_meaning(code), log });
    }
    match status {
        ChildExit::Code(0) => {}
        ChildExit::Code(code) => {
            return Err(MeshingError::Crashed { how: format!("exit code {code}"), log });
        }
        ChildExit::Signal(sig) => {
            return Err(MeshingError::Crashed { how: signal_name(sig), log });
        }
    }
    let out = read_output(&out_path)?;
    if out.tets.is_empty() || out.points.is_empty() {
        return Err(MeshingError::Empty { log });
    }
    Ok(out)
}

/// `tritet` prints `status = N` when it catches TetGen's `throw N`.
fn thrown_status(log: &str) -> Option<i32> {
    log.lines().find_map(|l| l.trim().strip_prefix("status = ")?.trim().parse().ok())
}

fn signal_name(sig: i32) -> String {
    let name = match sig {
        libc::SIGABRT => "SIGABRT, an abort",
        libc::SIGSEGV => "SIGSEGV, a segmentation fault",
        libc::SIGKILL => "SIGKILL, possibly out of memory",
        libc::SIGFPE => "SIGFPE, a floating-point exception",
        libc::SIGBUS => "SIGBUS",
        _ => "a signal",
    };
    format!("{name}, signal {sig}")
}

/// Without TetGen in the build: never called ([`tetrahedralize`] refuses first).
#[cfg(not(feature = "tetgen"))]
fn run_tetgen(_plc: &Plc, _opts: &TetgenOptions, _out_path: &Path) -> Result<(), String> {
    Err(MeshingError::Unavailable.to_string())
}

/// Runs TetGen in this (child) process and writes the result to `out_path`.
#[cfg(feature = "tetgen")]
fn run_tetgen(plc: &Plc, opts: &TetgenOptions, out_path: &Path) -> Result<(), String> {
    let facet_npoint: Vec<usize> = plc.facets.iter().map(|f| f.points.len()).collect();
    let mut tg = tritet::Tetgen::new(plc.points.len(), Some(facet_npoint), Some(plc.regions.len()), Some(0))
        .map_err(str::to_string)?;
    for (i, p) in plc.points.iter().enumerate() {
        // tritet reserves point marker 1 for boundary points; we use 0.
        tg.set_point(i, 0, p[0], p[1], p[2]).map_err(str::to_string)?;
    }
    for (i, f) in plc.facets.iter().enumerate() {
        for (m, &p) in f.points.iter().enumerate() {
            tg.set_facet_point(i, m, p).map_err(str::to_string)?;
        }
        tg.set_facet_marker(i, f.tag.marker()).map_err(str::to_string)?;
    }
    for (i, r) in plc.regions.iter().enumerate() {
        tg.set_region(i, r.attribute, r.point[0], r.point[1], r.point[2], r.max_volume).map_err(str::to_string)?;
    }
    tg.generate_mesh(false, false, opts.max_volume, Some(opts.radius_edge_ratio)).map_err(str::to_string)?;
    let np = tg.out_npoint();
    let nt = tg.out_ncell();
    let nf = tg.out_n_marked_face();
    let file = File::create(out_path).map_err(|e| e.to_string())?;
    let mut w = std::io::BufWriter::new(file);
    let put = &mut |b: &[u8]| w.write_all(b).map_err(|e| e.to_string());
    put(&(np as u64).to_le_bytes())?;
    put(&(nt as u64).to_le_bytes())?;
    put(&(nf as u64).to_le_bytes())?;
    for i in 0..np {
        for d in 0..3 {
            put(&tg.out_point(i, d).to_le_bytes())?;
        }
    }
    for t in 0..nt {
        for m in 0..4 {
            put(&(tg.out_cell_point(t, m) as u64).to_le_bytes())?;
        }
        put(&tg.out_cell_marker(t).to_le_bytes())?;
    }
    let mut face = [0i32; 6];
    for f in 0..nf {
        let (marker, _cell) = tg.out_marked_face(f, &mut face);
        for &p in &face[..3] {
            put(&(p as i64).to_le_bytes())?;
        }
        put(&marker.to_le_bytes())?;
    }
    w.flush().map_err(|e| e.to_string())
}

fn read_output(path: &Path) -> Result<TetgenOutput, MeshingError> {
    let mut bytes = Vec::new();
    File::open(path)?.read_to_end(&mut bytes)?;
    let mut r = ByteReader { bytes: &bytes, pos: 0 };
    let truncated = || MeshingError::Crashed { how: "truncated output".into(), log: String::new() };
    let np = r.u64().ok_or_else(truncated)? as usize;
    let nt = r.u64().ok_or_else(truncated)? as usize;
    let nf = r.u64().ok_or_else(truncated)? as usize;
    let mut out = TetgenOutput::default();
    out.points.reserve(np);
    for _ in 0..np {
        let p = [r.f64(), r.f64(), r.f64()];
        out.points.push([p[0].ok_or_else(truncated)?, p[1].ok_or_else(truncated)?, p[2].ok_or_else(truncated)?]);
    }
    for _ in 0..nt {
        let mut t = [0usize; 4];
        for v in &mut t {
            *v = r.u64().ok_or_else(truncated)? as usize;
            if *v >= np {
                return Err(MeshingError::Crashed { how: format!("node index {v} out of range"), log: String::new() });
            }
        }
        out.tets.push(t);
        out.tet_region.push(r.i32().ok_or_else(truncated)?);
    }
    for _ in 0..nf {
        let mut f = [0usize; 3];
        for v in &mut f {
            let i = r.i64().ok_or_else(truncated)?;
            *v = usize::try_from(i).ok().filter(|&i| i < np).ok_or_else(truncated)?;
        }
        out.marked_faces.push((f, r.i32().ok_or_else(truncated)?));
    }
    Ok(out)
}

struct ByteReader<'a> {
    bytes: &'a [u8],
    pos: usize,
}

impl ByteReader<'_> {
    fn take<const N: usize>(&mut self) -> Option<[u8; N]> {
        let s = self.bytes.get(self.pos..self.pos + N)?;
        self.pos += N;
        s.try_into().ok()
    }
    fn u64(&mut self) -> Option<u64> {
        self.take().map(u64::from_le_bytes)
    }
    fn i64(&mut self) -> Option<i64> {
        self.take().map(i64::from_le_bytes)
    }
    fn i32(&mut self) -> Option<i32> {
        self.take().map(i32::from_le_bytes)
    }
    fn f64(&mut self) -> Option<f64> {
        self.take().map(f64::from_le_bytes)
    }
}

enum ChildExit {
    Code(i32),
    Signal(i32),
}

/// Runs `work` in a forked child with stdout and stderr redirected to `log_path`; waits at
/// most `timeout`, then kills it.
///
/// The child only runs `work` and `_exit`s: no destructors, no flushing of the parent's
/// buffers. glibc keeps `malloc` usable after `fork` in a multi-threaded parent.
fn run_in_child(
    log_path: &Path,
    timeout: Duration,
    work: impl FnOnce() -> Result<(), String>,
) -> Result<ChildExit, MeshingError> {
    use std::os::fd::AsRawFd;
    let log = File::create(log_path)?;
    // SAFETY: fork has no preconditions; the child below restricts itself to running TetGen,
    // writing files and `_exit`.
    let pid = unsafe { libc::fork() };
    if pid < 0 {
        return Err(std::io::Error::last_os_error().into());
    }
    if pid == 0 {
        // Child.
        unsafe {
            libc::dup2(log.as_raw_fd(), 1);
            libc::dup2(log.as_raw_fd(), 2);
        }
        let code = match std::panic::catch_unwind(std::panic::AssertUnwindSafe(work)) {
            Ok(Ok(())) => 0,
            Ok(Err(msg)) => {
                let _ = writeln!(&log, "heatsim: {msg}");
                3
            }
            Err(_) => 4,
        };
        unsafe {
            libc::fflush(std::ptr::null_mut());
            libc::_exit(code);
        }
    }
    drop(log);
    let start = Instant::now();
    let mut sleep = Duration::from_millis(1);
    loop {
        let mut status: libc::c_int = 0;
        // SAFETY: pid is our own child.
        let r = unsafe { libc::waitpid(pid, &mut status, libc::WNOHANG) };
        if r == pid {
            if libc::WIFEXITED(status) {
                return Ok(ChildExit::Code(libc::WEXITSTATUS(status)));
            }
            if libc::WIFSIGNALED(status) {
                return Ok(ChildExit::Signal(libc::WTERMSIG(status)));
            }
        } else if r < 0 {
            let err = std::io::Error::last_os_error();
            if err.kind() != std::io::ErrorKind::Interrupted {
                return Err(err.into());
            }
        }
        if start.elapsed() > timeout {
            unsafe {
                libc::kill(pid, libc::SIGKILL);
                libc::waitpid(pid, &mut status, 0);
            }
            return Err(MeshingError::Timeout { seconds: timeout.as_secs_f64() });
        }
        std::thread::sleep(sleep);
        sleep = (sleep * 2).min(Duration::from_millis(50));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn thrown_status_is_parsed_from_tritet_output() {
        assert_eq!(thrown_status("foo\nstatus = 3\n"), Some(3));
        assert_eq!(thrown_status("all fine\n"), None);
    }

    #[test]
    fn child_crash_is_reported_not_propagated() {
        let dir = tempfile::tempdir().unwrap();
        let r = run_in_child(&dir.path().join("log"), Duration::from_secs(10), || {
            std::process::abort();
        });
        assert!(matches!(r, Ok(ChildExit::Signal(libc::SIGABRT))));
    }

    #[test]
    fn hanging_child_is_killed_after_timeout() {
        let dir = tempfile::tempdir().unwrap();
        let r = run_in_child(&dir.path().join("log"), Duration::from_millis(200), || loop {
            std::thread::sleep(Duration::from_millis(10));
        });
        assert!(matches!(r, Err(MeshingError::Timeout { .. })));
    }

    #[test]
    fn child_output_goes_to_log() {
        let dir = tempfile::tempdir().unwrap();
        let log = dir.path().join("log");
        let r = run_in_child(&log, Duration::from_secs(10), || {
            // What C++ code prints goes straight to file descriptor 1 (println! would be
            // captured by the test harness instead).
            let msg = b"status = 3\n";
            unsafe { libc::write(1, msg.as_ptr().cast(), msg.len()) };
            Ok(())
        });
        assert!(matches!(r, Ok(ChildExit::Code(0))));
        assert_eq!(thrown_status(&std::fs::read_to_string(log).unwrap()), Some(3));
    }
}

//! Running a method as a child process: its output to a log, a wall-clock limit, and every
//! way it can fail turned into a reason (never the end of the run).

use std::os::unix::process::CommandExt;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use serde::Serialize;

/// Why a case failed.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct Failure {
    /// `inputs`, `crash`, `timeout`, `no_output`, `malformed_output` or `scoring`.
    pub kind: &'static str,
    /// What happened, with the log's last lines where there is one.
    pub message: String,
}

impl Failure {
    pub fn new(kind: &'static str, message: impl Into<String>) -> Failure {
        Failure { kind, message: message.into() }
    }
}

/// Runs `cmd` (in its own process group), stdout and stderr into `log`, for at most
/// `timeout_s` seconds; on time-out the whole group is killed.
///
/// # Errors
/// A [`Failure`] of kind `crash` (cannot start, non-zero exit, signal) or `timeout`.
pub fn run_logged(mut cmd: Command, log: &Path, timeout_s: f64) -> Result<(), Failure> {
    let file =
        std::fs::File::create(log).map_err(|e| Failure::new("crash", format!("creating {}: {e}", log.display())))?;
    let err = file.try_clone().map_err(|e| Failure::new("crash", e.to_string()))?;
    cmd.stdin(Stdio::null()).stdout(Stdio::from(file)).stderr(Stdio::from(err)).process_group(0);
    let mut child =
        cmd.spawn().map_err(|e| Failure::new("crash", format!("cannot start {:?}: {e}", cmd.get_program())))?;
    let start = Instant::now();
    let status = loop {
        match child.try_wait() {
            Ok(Some(s)) => break s,
            Ok(None) => {}
            Err(e) => return Err(Failure::new("crash", format!("waiting for the method: {e}"))),
        }
        if start.elapsed().as_secs_f64() > timeout_s {
            kill_group(child.id());
            let _ = child.kill();
            let _ = child.wait();
            return Err(Failure::new(
                "timeout",
                format!("did not finish within {timeout_s} s (--timeout); log {}", log.display()),
            ));
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    if status.success() {
        return Ok(());
    }
    Err(Failure::new("crash", format!("exited with {status}: {}", log_tail(log))))
}

/// Kills the process group `pgid` (the child and everything it started) with `SIGKILL`, by
/// the system call rather than a `kill` program, which a minimal machine may lack. A group
/// that is already gone is not an error: the caller kills and reaps the child next.
fn kill_group(pgid: u32) {
    let Ok(pgid) = libc::pid_t::try_from(pgid) else { return };
    if pgid > 1 {
        // SAFETY: `killpg` takes plain integers and touches no memory of ours.
        unsafe { libc::killpg(pgid, libc::SIGKILL) };
    }
}

/// The lines starting with `error` of a log, or its last 5 lines, joined with ` | `.
pub fn log_tail(log: &Path) -> String {
    let text = std::fs::read_to_string(log).unwrap_or_default();
    let errors: Vec<&str> = text.lines().filter(|l| l.starts_with("error")).collect();
    let lines = if errors.is_empty() {
        let all: Vec<&str> = text.lines().collect();
        all[all.len().saturating_sub(5)..].to_vec()
    } else {
        errors
    };
    lines.join(" | ").chars().take(2000).collect()
}

//! Spawning, watching, stopping and reaping a run's processes.

use std::collections::HashMap;
use std::fs::File;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use shoal_scenario::ProcessSpec;

use super::os::{self as sys, ExitInfo};

/// One child process.
#[derive(Debug)]
pub struct ChildProc {
    /// What it is.
    pub spec: ProcessSpec,
    /// Its pid.
    pub pid: i32,
    /// Where its stderr goes.
    pub log: PathBuf,
    /// How it ended, once reaped.
    pub exit: Option<ExitInfo>,
    /// 0 for the first process of its index, n for its n-th restart.
    pub incarnation: u32,
}

/// Every child of a run.
#[derive(Debug, Default)]
pub struct Supervisor {
    children: Vec<ChildProc>,
    by_pid: HashMap<i32, usize>,
    /// When set, exits are expected (the run is being stopped).
    stopping: bool,
    /// Signals to send later: `(when, pid, signal)` (the end of a stall).
    timers: Vec<(Instant, i32, i32)>,
}

/// A child that ended while the run needed it.
#[derive(Debug, Clone)]
pub struct Death {
    /// Index of the process in the run.
    pub index: usize,
    /// `vehicle/kind`.
    pub label: String,
    /// How it ended.
    pub exit: ExitInfo,
    /// The last lines of its log.
    pub log_tail: String,
}

impl Supervisor {
    /// Spawns one child with the given arguments; stderr and stdout go to
    /// `log`. `incarnation` is 0 for a process's first start and n for its
    /// n-th restart, whose log goes on in the same file after a marker line.
    pub fn spawn(
        &mut self,
        spec: &ProcessSpec,
        binary: &Path,
        args: &[String],
        log: &Path,
        incarnation: u32,
    ) -> std::io::Result<()> {
        let mut out = if incarnation == 0 {
            File::create(log)?
        } else {
            File::options().append(true).create(true).open(log)?
        };
        if incarnation > 0 {
            use std::io::Write;
            writeln!(
                out,
                "--- shoal: restart {incarnation} of {} ---",
                spec.label()
            )?;
        }
        let err = out.try_clone()?;
        let mut cmd = Command::new(binary);
        cmd.args(args)
            .stdin(Stdio::null())
            .stdout(Stdio::from(out))
            .stderr(Stdio::from(err));
        cmd.env(
            "GLIBC_TUNABLES",
            without_rseq(std::env::var("GLIBC_TUNABLES").ok()),
        );
        sys::die_with_parent(&mut cmd);
        let child = cmd.spawn()?;
        let pid = child.id() as i32;
        // The handle is dropped without waiting: children are reaped with wait4.
        drop(child);
        self.by_pid.insert(pid, self.children.len());
        self.children.push(ChildProc {
            spec: spec.clone(),
            pid,
            log: log.to_path_buf(),
            exit: None,
            incarnation,
        });
        Ok(())
    }

    /// The latest child of each process index (the one a restart replaced
    /// is left out).
    pub fn latest(&self) -> impl Iterator<Item = &ChildProc> {
        self.children.iter().filter(|c| {
            !self
                .children
                .iter()
                .any(|o| o.spec.index == c.spec.index && o.incarnation > c.incarnation)
        })
    }

    /// All children.
    pub fn children(&self) -> &[ChildProc] {
        &self.children
    }

    /// The live child running process `index` of the run.
    pub fn pid_of(&self, index: usize) -> Option<i32> {
        self.children
            .iter()
            .rev()
            .find(|c| c.spec.index == index && c.exit.is_none())
            .map(|c| c.pid)
    }

    /// Sends `sig` to `pid` once `after` has passed (checked on every reap).
    pub fn signal_later(&mut self, pid: i32, sig: i32, after: Duration) {
        self.timers.push((Instant::now() + after, pid, sig));
    }

    /// Reaps every child that has exited; returns the ones that died while
    /// the run still needed them. Sends the signals that are due.
    pub fn reap(&mut self) -> Vec<Death> {
        self.send_due_signals();
        let mut deaths = Vec::new();
        while let Some((pid, info)) = sys::reap_any() {
            if let Some(&i) = self.by_pid.get(&pid) {
                let c = &mut self.children[i];
                c.exit = Some(info);
                if !self.stopping {
                    deaths.push(Death {
                        index: c.spec.index,
                        label: c.spec.label(),
                        exit: info,
                        log_tail: tail(&c.log, 12),
                    });
                }
            }
        }
        deaths
    }

    /// Sends the signals that are due (no system call when none is).
    pub fn send_due_signals(&mut self) {
        if self.timers.is_empty() {
            return;
        }
        let now = Instant::now();
        self.timers.retain(|&(at, pid, sig)| {
            if at <= now {
                sys::send_signal(pid, sig);
                false
            } else {
                true
            }
        });
    }

    /// Marks the run as stopping: exits from now on are expected.
    pub fn begin_stop(&mut self) {
        self.stopping = true;
    }

    /// Sends a signal to the children selected by `pick`.
    pub fn signal(&self, sig: i32, pick: impl Fn(&ChildProc) -> bool) {
        for c in &self.children {
            if c.exit.is_none() && pick(c) {
                sys::send_signal(c.pid, sig);
            }
        }
    }

    /// Waits until the selected children have exited, or `timeout`; returns
    /// true if they all did.
    pub fn wait_for(&mut self, timeout: Duration, pick: impl Fn(&ChildProc) -> bool) -> bool {
        let start = Instant::now();
        loop {
            self.reap();
            if self
                .children
                .iter()
                .filter(|c| pick(c))
                .all(|c| c.exit.is_some())
            {
                return true;
            }
            if start.elapsed() > timeout {
                return false;
            }
            std::thread::sleep(Duration::from_millis(5));
        }
    }

    /// Stops everything: SIGTERM the selected group first (the recorder,
    /// which must finish its file), then the rest, then SIGKILL whatever is
    /// left after the grace period. Every child is reaped.
    pub fn stop_all(&mut self, first: impl Fn(&ChildProc) -> bool + Copy, grace: Duration) {
        self.begin_stop();
        // A stalled child must run again to stop.
        for (_, pid, sig) in std::mem::take(&mut self.timers) {
            sys::send_signal(pid, sig);
        }
        self.signal(libc::SIGTERM, first);
        if !self.wait_for(grace * 6, first) {
            self.signal(libc::SIGKILL, first);
        }
        self.signal(libc::SIGTERM, |_| true);
        if !self.wait_for(grace, |_| true) {
            self.signal(libc::SIGKILL, |_| true);
            self.wait_for(Duration::from_secs(5), |_| true);
        }
    }
}

/// The last `n` lines of a file.
pub fn tail(path: &Path, n: usize) -> String {
    let text = std::fs::read_to_string(path).unwrap_or_default();
    let lines: Vec<&str> = text.lines().collect();
    lines[lines.len().saturating_sub(n)..].join("\n")
}

/// `GLIBC_TUNABLES` for a service process: the caller's, with glibc's
/// restartable sequence turned off unless the caller set it. glibc
/// registers one per thread to cache its CPU number, which no service
/// reads, and the kernel then writes it on every return to the process
/// after a switch: in a lockstep run every step is such a return, and at
/// N = 100 that write (`__rseq_handle_notify_resume`) was 1.2 % of the
/// run's CPU under perf.
fn without_rseq(inherited: Option<String>) -> String {
    match inherited {
        Some(t) if t.contains("glibc.pthread.rseq") => t,
        Some(t) if !t.is_empty() => format!("{t}:glibc.pthread.rseq=0"),
        _ => "glibc.pthread.rseq=0".to_string(),
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn services_run_without_rseq_unless_the_caller_chose() {
        assert_eq!(super::without_rseq(None), "glibc.pthread.rseq=0");
        assert_eq!(
            super::without_rseq(Some("glibc.malloc.arena_max=2".into())),
            "glibc.malloc.arena_max=2:glibc.pthread.rseq=0"
        );
        assert_eq!(
            super::without_rseq(Some("glibc.pthread.rseq=1".into())),
            "glibc.pthread.rseq=1"
        );
    }
}

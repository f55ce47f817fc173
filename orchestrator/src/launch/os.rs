//! The operating system, each call wrapped once: what the supervisor needs
//! (spawn, reap, signal, CPU time, file limits) and what pre-flight reads
//! of the machine's limits (statvfs, rlimits, the pids cgroup, /proc).
#![allow(unsafe_code)]

use std::os::unix::process::CommandExt;
use std::process::Command;

/// How a child ended.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ExitInfo {
    /// Exit code, if it exited.
    pub code: Option<i32>,
    /// Signal, if a signal ended it.
    pub signal: Option<i32>,
    /// User + system CPU time, s.
    pub cpu_s: f64,
    /// Peak resident memory, KiB.
    pub max_rss_kib: i64,
}

impl ExitInfo {
    /// True for a clean exit (code 0).
    pub fn success(&self) -> bool {
        self.code == Some(0)
    }
    /// Human description.
    pub fn describe(&self) -> String {
        match (self.code, self.signal) {
            (Some(c), _) => format!("exit code {c}"),
            (_, Some(s)) => format!("killed by signal {s} ({})", signal_name(s)),
            _ => "unknown status".into(),
        }
    }
}

fn signal_name(s: i32) -> &'static str {
    match s {
        libc::SIGKILL => "SIGKILL",
        libc::SIGTERM => "SIGTERM",
        libc::SIGINT => "SIGINT",
        libc::SIGSEGV => "SIGSEGV",
        libc::SIGABRT => "SIGABRT",
        _ => "signal",
    }
}

/// Moves the calling thread into the network namespace `ns` (an open
/// `/var/run/netns/NAME` or `/proc/.../ns/net`); threads and processes it
/// starts afterwards are born there.
pub fn enter_netns(ns: &std::fs::File) -> std::io::Result<()> {
    use std::os::fd::AsRawFd;
    // SAFETY: setns only reads the descriptor, which `ns` keeps open.
    if unsafe { libc::setns(ns.as_raw_fd(), libc::CLONE_NEWNET) } != 0 {
        return Err(std::io::Error::last_os_error());
    }
    Ok(())
}

/// Asks the kernel to keep CPUs out of idle states deeper than polling
/// while the returned file is open (PM QoS, as cyclictest does; `None` if
/// it cannot, e.g. without permission).
pub fn hold_cpu_latency() -> Option<std::fs::File> {
    use std::io::Write;
    let mut f = std::fs::OpenOptions::new()
        .write(true)
        .open("/dev/cpu_dma_latency")
        .ok()?;
    f.write_all(&0i32.to_ne_bytes()).ok()?;
    Some(f)
}

/// CPU time of one blocking wake-up, µs: `echo`, on a thread of its own,
/// answers `rounds` round trips that `ping` starts one at a time here; the
/// process's CPU over the wake-ups (two per round).
fn ping_pong_cpu_us(
    rounds: u32,
    echo: impl FnOnce() -> anyhow::Result<()> + Send + 'static,
    mut ping: impl FnMut() -> anyhow::Result<()>,
) -> anyhow::Result<f64> {
    let echo = std::thread::spawn(echo);
    let before = self_cpu_s();
    for _ in 0..rounds {
        ping()?;
    }
    echo.join()
        .map_err(|_| anyhow::anyhow!("the echo thread panicked"))??;
    let cpu = self_cpu_s() - before;
    Ok(cpu * 1e6 / (2.0 * f64::from(rounds.max(1))))
}

/// CPU time of one blocking wake-up on this machine, µs: two threads
/// bounce a byte over a Unix datagram socket pair, each blocking in `recv`
/// until the other's `send` wakes it.
pub fn wake_up_cpu_us(rounds: u32) -> anyhow::Result<f64> {
    use std::os::unix::net::UnixDatagram;
    let (a, b) = UnixDatagram::pair()?;
    let mut buf = [0u8; 1];
    ping_pong_cpu_us(
        rounds,
        move || {
            let mut buf = [0u8; 1];
            for _ in 0..rounds {
                b.recv(&mut buf)?;
                b.send(&buf)?;
            }
            Ok(())
        },
        || {
            a.send(&buf)?;
            a.recv(&mut buf)?;
            Ok(())
        },
    )
}

/// CPU time of one blocking wake-up through the lockstep doorbell (a futex
/// in shared memory, as the orchestrator wakes a process), µs: two threads
/// ring each other, each on a mapping of its own.
pub fn futex_wake_up_cpu_us(rounds: u32) -> anyhow::Result<f64> {
    use shoal_runtime::{Doorbell, Rung};
    // Waits for slot `i` to move past `seen`.
    fn next(bell: &Doorbell, i: usize, seen: u32) -> u32 {
        loop {
            if let Some(s) = bell.wait(i, seen, std::time::Duration::from_secs(1)) {
                return s;
            }
        }
    }
    let id = format!("wakeref{}", std::process::id());
    let bell = Doorbell::create(&id, 2)?;
    let mut seen = 0;
    ping_pong_cpu_us(
        rounds,
        move || {
            let bell = Doorbell::open(&id, 2)?;
            let mut seen = 0;
            for _ in 0..rounds {
                seen = next(&bell, 0, seen);
                bell.ring(1, Rung::default(), true);
            }
            Ok(())
        },
        || {
            bell.ring(0, Rung::default(), true);
            seen = next(&bell, 1, seen);
            Ok(())
        },
    )
}

/// Waits until `fd` is readable or `timeout` has passed: `Ok(true)` if it
/// is, `Ok(false)` on the timeout or a signal (the caller checks for a
/// termination request).
pub fn wait_readable(fd: i32, timeout: std::time::Duration) -> std::io::Result<bool> {
    let mut p = [libc::pollfd {
        fd,
        events: libc::POLLIN,
        revents: 0,
    }];
    shoal_runtime::poll_until(&mut p, timeout.as_nanos().min(u64::MAX as u128) as u64)
}

/// Makes the child receive SIGTERM if the orchestrator dies, so no
/// process outlives its run.
pub fn die_with_parent(cmd: &mut Command) {
    // SAFETY: prctl is async-signal-safe and touches only the child's own state.
    unsafe {
        cmd.pre_exec(|| {
            if libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGTERM) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            Ok(())
        });
    }
}

/// Waits for child `pid` to exit and reaps it: its exit and usage, or
/// `None` if it is not a child of this process.
pub fn wait_pid(pid: i32) -> Option<ExitInfo> {
    let mut status: libc::c_int = 0;
    // SAFETY: an all-zero rusage is a valid value; wait4 fills it.
    let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
    // SAFETY: plain syscall with pointers to locals.
    let r = unsafe { libc::wait4(pid, &mut status, 0, &mut usage) };
    (r == pid).then(|| exit_info(status, &usage))
}

/// Gives the heap's free memory back to the system (`malloc_trim`), so
/// that a child spawned next does not count this process's freed pages in
/// its peak (a vfork'd child's peak includes the parent's resident pages).
pub fn trim_heap() {
    // SAFETY: malloc_trim only walks glibc's own free lists.
    unsafe {
        libc::malloc_trim(0);
    }
}

/// Reaps one exited child without blocking: `Some((pid, info))`, or `None`
/// if no child has exited.
pub fn reap_any() -> Option<(i32, ExitInfo)> {
    let mut status: libc::c_int = 0;
    // SAFETY: an all-zero rusage is a valid value; wait4 fills it.
    let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
    // SAFETY: plain syscall with pointers to locals.
    let pid = unsafe { libc::wait4(-1, &mut status, libc::WNOHANG, &mut usage) };
    if pid <= 0 {
        return None;
    }
    Some((pid, exit_info(status, &usage)))
}

/// Sends a signal to a process.
pub fn send_signal(pid: i32, sig: i32) {
    // SAFETY: kill has no memory effects.
    unsafe {
        libc::kill(pid, sig);
    }
}

/// CPU time of this process so far (user + system), s.
pub fn self_cpu_s() -> f64 {
    // SAFETY: an all-zero rusage is valid; getrusage fills it.
    let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
    // SAFETY: plain syscall with a pointer to a local.
    unsafe {
        libc::getrusage(libc::RUSAGE_SELF, &mut usage);
    }
    let tv = |t: libc::timeval| t.tv_sec as f64 + t.tv_usec as f64 * 1e-6;
    tv(usage.ru_utime) + tv(usage.ru_stime)
}

/// A short random hex id from the kernel's generator.
pub fn random_id() -> String {
    let mut buf = [0u8; 4];
    if let Ok(mut f) = std::fs::File::open("/dev/urandom") {
        use std::io::Read;
        let _ = f.read_exact(&mut buf);
    }
    if buf == [0; 4] {
        let t = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map(|d| d.subsec_nanos())
            .unwrap_or(0)
            ^ std::process::id();
        buf = t.to_le_bytes();
    }
    buf.iter().map(|b| format!("{b:02x}")).collect()
}

/// Raises the soft limit of open files to the hard limit (a run of many
/// vehicles needs thousands: the recorder opens every channel); returns the
/// new soft limit.
pub fn raise_nofile_limit() -> u64 {
    let mut lim = libc::rlimit {
        rlim_cur: 0,
        rlim_max: 0,
    };
    // SAFETY: getrlimit/setrlimit read and write the rlimit struct we own.
    unsafe {
        if libc::getrlimit(libc::RLIMIT_NOFILE, &mut lim) != 0 {
            return 0;
        }
        if lim.rlim_cur < lim.rlim_max {
            let raised = libc::rlimit {
                rlim_cur: lim.rlim_max,
                rlim_max: lim.rlim_max,
            };
            if libc::setrlimit(libc::RLIMIT_NOFILE, &raised) == 0 {
                return raised.rlim_cur;
            }
        }
    }
    lim.rlim_cur
}

/// Restores the default SIGPIPE action, so `shoal inspect … | head` ends
/// quietly like any Unix tool instead of failing on a closed pipe.
pub fn default_sigpipe() {
    // SAFETY: resetting a signal's disposition to its default has no memory effects.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
}

/// Gives Ctrl-C and SIGTERM back their default (end the process): once a
/// run has been interrupted, a second Ctrl-C during the work that follows
/// (summarising what ran) ends it at once.
pub fn default_termination_signals() {
    // SAFETY: resetting a signal's disposition to its default has no memory effects.
    unsafe {
        libc::signal(libc::SIGINT, libc::SIG_DFL);
        libc::signal(libc::SIGTERM, libc::SIG_DFL);
    }
}

/// The one-minute load average (/proc/loadavg), printed beside benchmark
/// figures so a reader sees how busy the machine was.
pub fn load_average() -> Option<f64> {
    std::fs::read_to_string("/proc/loadavg")
        .ok()?
        .split_whitespace()
        .next()?
        .parse()
        .ok()
}

// The machine limits of pre-flight (`preflight::resources`).

/// Free bytes and free inodes of a file system, for an unprivileged user.
pub fn statvfs_free(path: &str) -> (Option<u64>, Option<u64>) {
    let Ok(c) = std::ffi::CString::new(path) else {
        return (None, None);
    };
    // SAFETY: an all-zero statvfs is a valid value; statvfs fills it.
    let mut st: libc::statvfs = unsafe { std::mem::zeroed() };
    // SAFETY: a NUL-terminated path and a pointer to a local.
    if unsafe { libc::statvfs(c.as_ptr(), &mut st) } != 0 {
        return (None, None);
    }
    let bytes = (st.f_bavail as u64).saturating_mul(st.f_frsize as u64);
    // A file system without inode accounting (tmpfs with nr_inodes=0) reports 0 files.
    let files = (st.f_files != 0).then_some(st.f_favail as u64);
    (Some(bytes), files)
}

fn soft_limit(resource: libc::__rlimit_resource_t) -> Option<u64> {
    let mut r = libc::rlimit {
        rlim_cur: 0,
        rlim_max: 0,
    };
    // SAFETY: a pointer to a local.
    if unsafe { libc::getrlimit(resource, &mut r) } != 0 || r.rlim_cur == libc::RLIM_INFINITY {
        return None;
    }
    Some(r.rlim_cur)
}

/// `RLIMIT_NOFILE` (soft), `None` if unlimited.
pub fn nofile_limit() -> Option<u64> {
    soft_limit(libc::RLIMIT_NOFILE)
}

/// `RLIMIT_NPROC` (soft) and the effective uid.
pub fn nproc_limit() -> (Option<u64>, u32) {
    // SAFETY: geteuid has no memory effects.
    let uid = unsafe { libc::geteuid() };
    (soft_limit(libc::RLIMIT_NPROC), uid)
}

/// `pids.max` and `pids.current` of this process's pids cgroup, if limited.
pub fn pids_cgroup() -> Option<(u64, u64, String)> {
    let text = std::fs::read_to_string("/proc/self/cgroup").ok()?;
    for line in text.lines() {
        let mut parts = line.splitn(3, ':');
        let (_, ctrl, path) = (parts.next()?, parts.next()?, parts.next()?);
        let dir = if ctrl == "pids" {
            format!("/sys/fs/cgroup/pids{path}")
        } else if ctrl.is_empty() {
            format!("/sys/fs/cgroup{path}")
        } else {
            continue;
        };
        let max = std::fs::read_to_string(format!("{dir}/pids.max")).ok();
        let Some(max) = max.and_then(|m| m.trim().parse::<u64>().ok()) else {
            continue;
        };
        let current = std::fs::read_to_string(format!("{dir}/pids.current"))
            .ok()
            .and_then(|c| c.trim().parse::<u64>().ok())
            .unwrap_or(0);
        return Some((max, current, dir));
    }
    None
}

/// Processes owned by `uid` (entries of /proc owned by it).
pub fn user_processes(uid: u32) -> u64 {
    use std::os::unix::fs::MetadataExt;
    let Ok(entries) = std::fs::read_dir("/proc") else {
        return 0;
    };
    entries
        .flatten()
        .filter(|e| {
            e.file_name()
                .to_string_lossy()
                .bytes()
                .all(|b| b.is_ascii_digit())
        })
        .filter(|e| e.metadata().is_ok_and(|m| m.uid() == uid))
        .count() as u64
}

// What `shoal bench scale` reads of the run's processes (/proc).

/// Resets this process's peak RSS (`VmHWM`) to its current RSS, so the
/// next reading is the peak of the coming run; false if the kernel refused.
pub fn reset_own_peak_rss() -> bool {
    std::fs::write("/proc/self/clear_refs", "5").is_ok()
}

/// One process's memory as `/proc/PID/status` gives it, KiB.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct MemReading {
    /// Peak resident set (`VmHWM`).
    pub hwm_kib: i64,
    /// Private anonymous pages now (`RssAnon`).
    pub anon_kib: i64,
}

/// Reads `VmHWM` and `RssAnon` out of a `/proc/PID/status` text.
pub fn parse_status(text: &str) -> Option<MemReading> {
    let field = |name: &str| {
        shoal_runtime::stats::proc_status_kib(text, name).and_then(|k| i64::try_from(k).ok())
    };
    Some(MemReading {
        hwm_kib: field("VmHWM:")?,
        anon_kib: field("RssAnon:").unwrap_or(0),
    })
}

/// The process kind of a service process from its command line (the value
/// of `--process`); `None` for anything else, including a child between
/// fork and exec, which still carries the orchestrator's memory.
pub fn kind_from_cmdline(raw: &[u8]) -> Option<String> {
    arg_from_cmdline(raw, "--process")
}

/// The value after `flag` in a NUL-separated command line
/// (`/proc/PID/cmdline`).
pub fn arg_from_cmdline(raw: &[u8], flag: &str) -> Option<String> {
    let mut args = raw.split(|&b| b == 0);
    while let Some(a) = args.next() {
        if a == flag.as_bytes() {
            return args.next().map(|v| String::from_utf8_lossy(v).into_owned());
        }
    }
    None
}

/// Children of this process (every thread's), from `/proc/self/task/*/children`.
pub fn child_pids() -> Vec<i32> {
    let Ok(tasks) = std::fs::read_dir("/proc/self/task") else {
        return Vec::new();
    };
    tasks
        .flatten()
        .filter_map(|t| std::fs::read_to_string(t.path().join("children")).ok())
        .flat_map(|c| {
            c.split_whitespace()
                .filter_map(|p| p.parse().ok())
                .collect::<Vec<i32>>()
        })
        .collect()
}

/// CPU time of the calling thread, s (`/proc/thread-self/schedstat`, or
/// `stat` at 100 ticks per second).
pub fn thread_cpu_s() -> f64 {
    let schedstat = std::fs::read_to_string("/proc/thread-self/schedstat")
        .ok()
        .and_then(|t| t.split_whitespace().next()?.parse::<u64>().ok())
        .filter(|&ns| ns > 0);
    if let Some(ns) = schedstat {
        return ns as f64 * 1e-9;
    }
    std::fs::read_to_string("/proc/thread-self/stat")
        .ok()
        .and_then(|t| {
            let rest = t.rsplit_once(')')?.1;
            let f: Vec<&str> = rest.split_whitespace().collect();
            let ticks = f.get(11)?.parse::<u64>().ok()? + f.get(12)?.parse::<u64>().ok()?;
            Some(ticks as f64 / 100.0)
        })
        .unwrap_or(0.0)
}

/// This process's `VmHWM` and `RssAnon`.
pub fn own_memory() -> Option<MemReading> {
    parse_status(&std::fs::read_to_string("/proc/self/status").ok()?)
}

/// Clock ticks per second of `/proc/PID/stat`'s CPU times (`_SC_CLK_TCK`).
pub fn clock_ticks_per_s() -> f64 {
    // SAFETY: sysconf only reads a constant.
    let t = unsafe { libc::sysconf(libc::_SC_CLK_TCK) };
    if t > 0 {
        t as f64
    } else {
        100.0
    }
}

/// The page size, bytes (`/proc/PID/statm` counts pages).
pub fn page_size() -> u64 {
    // SAFETY: sysconf only reads a constant.
    let p = unsafe { libc::sysconf(libc::_SC_PAGESIZE) };
    u64::try_from(p).unwrap_or(4096).max(1)
}

/// An exit status and a usage as [`ExitInfo`].
fn exit_info(status: libc::c_int, usage: &libc::rusage) -> ExitInfo {
    let tv = |t: libc::timeval| t.tv_sec as f64 + t.tv_usec as f64 * 1e-6;
    ExitInfo {
        code: libc::WIFEXITED(status).then(|| libc::WEXITSTATUS(status)),
        signal: libc::WIFSIGNALED(status).then(|| libc::WTERMSIG(status)),
        cpu_s: tv(usage.ru_utime) + tv(usage.ru_stime),
        max_rss_kib: usage.ru_maxrss,
    }
}

/// Where `program` is, as `execvp` would find it: a name with a `/` as it
/// stands (relative to the working directory), any other name in a
/// directory of `PATH`; `None` when no executable file is there.
pub fn find_program(program: &str) -> Option<std::path::PathBuf> {
    use std::os::unix::fs::PermissionsExt;
    let executable = |p: &std::path::Path| {
        std::fs::metadata(p).is_ok_and(|m| m.is_file() && m.permissions().mode() & 0o111 != 0)
    };
    if program.contains('/') {
        let p = std::path::PathBuf::from(program);
        return executable(&p).then_some(p);
    }
    let path = std::env::var_os("PATH")?;
    std::env::split_paths(&path)
        .map(|d| d.join(program))
        .find(|p| executable(p))
}

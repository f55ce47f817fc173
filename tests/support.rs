//! Helpers for tests that run real shoal processes. Binaries are found next
//! to the test executable's target directory (build them first with
//! `cargo build --release`), or in `SHOAL_BIN_DIR`.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

/// Where the shoal binaries are.
pub fn bin_dir() -> PathBuf {
    if let Some(d) = std::env::var_os("SHOAL_BIN_DIR") {
        return PathBuf::from(d);
    }
    // target/<profile>/deps/<test> -> target/<profile>
    let exe = std::env::current_exe().expect("current exe");
    let dir = exe
        .parent()
        .and_then(Path::parent)
        .expect("target dir")
        .to_path_buf();
    assert!(
        dir.join("shoal").is_file(),
        "no shoal binary in {}: run `cargo build --release --workspace` before the tests, or set SHOAL_BIN_DIR",
        dir.display()
    );
    dir
}

/// Every kind of process of a run, as `summary.json` and `[[faults]]` name
/// them (written out here, not taken from the scenario crate, so a kind that
/// went missing there fails the tests).
pub const PROCESS_KINDS: [&str; 7] = [
    "sim-plant",
    "camera-pose",
    "sonar",
    "planner",
    "mpc",
    "world",
    "recorder",
];

/// A `shoal` command.
pub fn shoal() -> Command {
    Command::new(bin_dir().join("shoal"))
}

/// Runs `shoal` with arguments and returns its output.
pub fn run_shoal(args: &[&str]) -> Output {
    shoal().args(args).output().expect("spawn shoal")
}

/// Runs `shoal` with arguments, asserts that it succeeded (showing its
/// stderr if not) and returns its output.
pub fn run_shoal_ok(args: &[&str]) -> Output {
    let o = run_shoal(args);
    assert!(
        o.status.success(),
        "shoal {}: {}",
        args.join(" "),
        String::from_utf8_lossy(&o.stderr)
    );
    o
}

/// Runs the small scenario `name` of `duration_s` simulated seconds in
/// lockstep into `dir/name` (asserting success); returns that directory.
pub fn run_small(dir: &Path, name: &str, duration_s: f64) -> PathBuf {
    let sc = write_scenario(
        dir,
        &format!("{name}.toml"),
        &small_scenario(name, duration_s),
    );
    let out = dir.join(name);
    run_shoal_ok(&[
        "run",
        "--quiet",
        sc.to_str().unwrap_or_default(),
        "--out",
        out.to_str().unwrap_or_default(),
    ]);
    out
}

/// The repository root.
pub fn repo_root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .unwrap()
        .to_path_buf()
}

/// A small scenario: a leader and `followers` followers in a chain or pair,
/// no obstacles, `duration_s` long.
pub fn small_scenario(name: &str, duration_s: f64) -> String {
    format!(
        r#"
name = "{name}"
seed = 3
duration_s = {duration_s:?}

[[vehicles]]
name = "L"

[[vehicles]]
name = "F1"
parent = "L"
slot_m = [-8.0, -4.0, 0.0]

[[vehicles]]
name = "F2"
parent = "L"
slot_m = [-8.0, 4.0, 0.0]

[mission]
waypoints_ned_m = [[200.0, 0.0, 10.0]]
speed_mps = 1.0
"#
    )
}

/// [`small_scenario`] with the camera's image model (camera-sim renders each
/// follower's frames; six stages per frame, so a 0.01 s tick).
pub fn small_image_scenario(name: &str, duration_s: f64) -> String {
    format!(
        "{}\n[rates]\ntick_s = 0.01\n\n[camera]\nmodel = \"image\"\n",
        small_scenario(name, duration_s)
    )
}

/// Writes a scenario into `dir` and returns its path.
pub fn write_scenario(dir: &Path, file: &str, text: &str) -> PathBuf {
    let p = dir.join(file);
    std::fs::write(&p, text).unwrap();
    p
}

/// Reads `run.json` of a live or finished run, waiting up to `timeout` for it.
pub fn wait_run_json(out: &Path, timeout: Duration) -> serde_json::Value {
    wait_run_json_unless(out, timeout, || None)
}

/// Waits as [`wait_run_json`] for the run `child` is, but fails at once
/// with its standard error when it ends without having written `run.json`.
pub fn wait_child_run_json(child: &mut Child, out: &Path, timeout: Duration) -> serde_json::Value {
    wait_run_json_unless(out, timeout, || {
        let status = child.try_wait().unwrap()?;
        let mut err = String::new();
        if let Some(mut e) = child.stderr.take() {
            std::io::Read::read_to_string(&mut e, &mut err).unwrap();
        }
        Some(format!(
            "the run ended ({status}) before run.json appeared:\n{err}"
        ))
    })
}

/// Polls for `out`/run.json until `timeout`; panics with what `ended` says
/// as soon as it says something.
fn wait_run_json_unless(
    out: &Path,
    timeout: Duration,
    mut ended: impl FnMut() -> Option<String>,
) -> serde_json::Value {
    let start = Instant::now();
    loop {
        if let Ok(t) = std::fs::read_to_string(out.join("run.json")) {
            if let Ok(v) = serde_json::from_str(&t) {
                return v;
            }
        }
        if let Some(why) = ended() {
            panic!("{why}");
        }
        assert!(
            start.elapsed() < timeout,
            "run.json never appeared in {}",
            out.display()
        );
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Starts `shoal run --quiet EXTRA… SCENARIO --out OUT` (stdout dropped,
/// stderr piped) and waits until its `run.json` names the run and `up`
/// processes mention the run id (the orchestrator and its children);
/// returns the running child and the run id.
pub fn start_run(scenario: &Path, out: &Path, extra: &[&str], up: usize) -> (Child, String) {
    let mut child = shoal()
        .args(["run", "--quiet"])
        .args(extra)
        .arg(scenario)
        .arg("--out")
        .arg(out)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let run = wait_run_json(out, Duration::from_secs(20));
    let run_id = run["run_id"].as_str().unwrap().to_string();
    let start = Instant::now();
    while processes_mentioning(&run_id).len() < up {
        if start.elapsed() > Duration::from_secs(20) {
            let _ = child.kill();
            panic!("the run's processes never came up");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    (child, run_id)
}

/// Pids of processes whose command line mentions `needle`.
pub fn processes_mentioning(needle: &str) -> Vec<(i32, String)> {
    let mut out = Vec::new();
    if let Ok(entries) = std::fs::read_dir("/proc") {
        for e in entries.flatten() {
            let Ok(pid) = e.file_name().to_string_lossy().parse::<i32>() else {
                continue;
            };
            if let Ok(cmd) = std::fs::read(e.path().join("cmdline")) {
                let cmd = String::from_utf8_lossy(&cmd).replace('\0', " ");
                if cmd.contains(needle) && pid != std::process::id() as i32 {
                    // Zombies have an empty cmdline; a listed process is alive.
                    out.push((pid, cmd));
                }
            }
        }
    }
    out
}

/// Sends a signal.
#[allow(unsafe_code)]
pub fn signal(pid: u32, sig: i32) {
    // SAFETY: kill has no memory effects.
    unsafe {
        libc::kill(pid as i32, sig);
    }
}

/// Python 3 with the third-party readers, or a failing assertion that says
/// how to install them (tests never skip).
pub fn python() -> Command {
    Command::new(python_having(
        "mcap, mcap_ros2",
        "pip install -r tests/requirements.txt",
    ))
}

/// The tests' Python 3 (`SHOAL_PYTHON`, default `python3`), asserted to
/// import `modules` (`"a, b"`); a failing assertion says `install`.
pub fn python_having(modules: &str, install: &str) -> String {
    let py = std::env::var("SHOAL_PYTHON").unwrap_or_else(|_| "python3".into());
    let ok = Command::new(&py)
        .args(["-c", &format!("import {modules}")])
        .status()
        .map(|s| s.success())
        .unwrap_or(false);
    assert!(ok, "{py} that imports {modules} is required: {install}");
    py
}

/// Runs one of `tests/python/`'s checkers with `args` and returns the JSON
/// report it prints; a failing checker fails the test with its stderr.
pub fn python_report<S: AsRef<std::ffi::OsStr>>(script: &str, args: &[S]) -> serde_json::Value {
    let mut c = python();
    c.arg(repo_root().join("tests/python").join(script))
        .args(args);
    report_of(c, script)
}

/// Runs `command` (one of `tests/python/`'s scripts, however started) and
/// returns the JSON report it prints; a failure or no report fails the
/// test with what it said.
pub fn report_of(mut command: Command, what: &str) -> serde_json::Value {
    let o = command.output().unwrap();
    assert!(
        o.status.success(),
        "{what} failed: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    serde_json::from_slice(&o.stdout).unwrap_or_else(|e| {
        panic!(
            "{what} printed no report ({e}): {}",
            String::from_utf8_lossy(&o.stdout)
        )
    })
}

/// A JSON array of unsigned integers (a checker's report), as numbers.
pub fn u64s(v: &serde_json::Value) -> Vec<u64> {
    v.as_array()
        .unwrap_or_else(|| panic!("not an array: {v}"))
        .iter()
        .map(|x| x.as_u64().unwrap_or_else(|| panic!("not a u64: {x}")))
        .collect()
}

/// What `summary.json` says happened to one process (`vehicle/kind`), in
/// order.
pub fn events_of<'a>(summary: &'a serde_json::Value, label: &str) -> Vec<&'a str> {
    summary["events"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|e| e["process"] == label)
        .map(|e| e["event"].as_str().unwrap())
        .collect()
}

/// The events of a process killed by a fault and restarted, in order.
pub const KILLED_AND_RESTARTED: [&str; 4] = [
    "fault_injected",
    "process_died",
    "process_restarted",
    "process_ready",
];

/// The `summary.json` of a finished run.
pub fn summary(out: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap()
}

/// Asserts that run `run_id` left nothing behind: no file of its shared
/// memory domain, no process that mentions it.
pub fn assert_domain_clean(run_id: &str) {
    let left = shoal_runtime::list_domain_files(run_id);
    assert!(
        left.is_empty(),
        "stale shared memory of run {run_id}: {left:?}"
    );
    let procs = processes_mentioning(run_id);
    assert!(
        procs.is_empty(),
        "orphan processes of run {run_id}: {procs:?}"
    );
}

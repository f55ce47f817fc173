//! A vehicle's process replaced by the user's own program (`[[replace]]`,
//! `--replace`), with real processes: the paper's follower planner written
//! in Python (examples/python/paper_follower.py, on the shoal_node package)
//! flies the paper scenario in lockstep (and re-runs on its recorded inputs
//! with no difference), in realtime and through a restart;
//! a user program that crashes, hangs or writes garbage is named in the
//! run's error (or its counts) and leaves nothing behind.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::path::{Path, PathBuf};

use shoal_tests::*;

/// The Python of the tests, with the checkout's shoal_node package (which
/// `.ci/run` installs): a missing package fails here, saying how to get it.
fn python3() -> String {
    python_having("shoal_node, numpy", "pip install -e ./python numpy")
}

/// `--replace` of every follower's planner by the Python example.
fn python_planner_flag() -> String {
    format!(
        "planner@followers={} {}",
        python3(),
        repo_root()
            .join("examples/python/paper_follower.py")
            .display()
    )
}

/// The paper scenario with its followers' planner the Python example.
fn paper_python() -> String {
    let text = std::fs::read_to_string(repo_root().join("scenarios/paper-python.toml")).unwrap();
    // The scenario's command is relative to the repository's root; the
    // tests run elsewhere.
    let example = repo_root().join("examples/python/paper_follower.py");
    text.replace(
        "command = [\"python3\", \"examples/python/paper_follower.py\"]",
        &format!("command = [\"{}\", \"{}\"]", python3(), example.display()),
    )
}

/// `shoal run` of `scenario` into `dir/out` with `extra`; the output dir.
fn run(dir: &Path, scenario: &str, extra: &[&str]) -> (std::process::Output, PathBuf) {
    std::fs::create_dir_all(dir).unwrap();
    let sc = write_scenario(dir, "s.toml", scenario);
    let out = dir.join("out");
    let mut args = vec![
        "run",
        "--quiet",
        sc.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    (run_shoal(&args), out)
}

fn run_id(out: &Path) -> String {
    let run: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("run.json")).unwrap()).unwrap();
    run["run_id"].as_str().unwrap().to_string()
}

/// The Python planner's statistics as the summary merged them: every
/// follower's planner took a step per frame.
fn assert_planners_stepped(s: &serde_json::Value, at_least: u64) {
    let planner = &s["step_us"]["planner"];
    // Five planners: the leader's (Rust) and four followers' (Python).
    assert!(
        planner["count"].as_u64().unwrap() >= 5 * at_least,
        "planner steps: {planner}"
    );
}

#[test]
fn the_paper_with_python_follower_planners_passes_in_lockstep() {
    let tmp = tempfile::tempdir().unwrap();
    let (o, out) = run(tmp.path(), &paper_python(), &[]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let s = summary(&out);
    assert_eq!(s["verdict"]["pass"], true, "verdict: {}", s["verdict"]);
    let safety = &s["safety"];
    assert_eq!(safety["collisions"], 0, "{safety}");
    let min_pair = safety["min_pair_distance_m"].as_f64().unwrap();
    assert!(min_pair >= 2.0, "min pair {min_pair} m");
    let rms = s["formation"]["slot_error_rms_m"]["after"]
        .as_f64()
        .unwrap();
    assert!(rms < 0.5, "after-passage slot RMS {rms} m");
    // 200 s at 10 Hz.
    assert_planners_stepped(&s, 1900);
    // The Python processes' setpoints reached the controllers and the
    // recording: nothing lost, nothing rejected.
    assert_eq!(s["samples_rejected"]["setpoint"], 0);
    assert_eq!(s["samples_lost"]["setpoint"], 0);
    assert_domain_clean(&run_id(&out));
    // Re-run on its recorded inputs, the user's planner (the recording's
    // scenario names it) gives the same outputs: it is deterministic too.
    let rec = out.join("recording.mcap");
    let o = run_shoal_ok(&[
        "replay",
        rec.to_str().unwrap(),
        "--rerun",
        "planner",
        "--vehicle",
        "F3",
    ]);
    let said = String::from_utf8_lossy(&o.stdout).to_string() + &String::from_utf8_lossy(&o.stderr);
    assert!(
        said.contains("F3/planner: no differences over 2000 steps"),
        "{said}"
    );
}

#[test]
fn python_follower_planners_run_in_realtime_in_dataflow_and_through_a_restart() {
    let tmp = tempfile::tempdir().unwrap();
    // Realtime: the Python node keeps its phased timer.
    let rt = tmp.path().join("rt");
    let (o, out) = run(
        &rt,
        &paper_python(),
        &["--mode", "realtime", "--duration", "6"],
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let s = summary(&out);
    assert_planners_stepped(&s, 50);
    assert_eq!(s["safety"]["collisions"], 0);
    assert_domain_clean(&run_id(&out));

    // Dataflow: the Python planner steps on the arrivals of its frame's
    // sonar scan and parent fix (iceoryx2 events, as shoal's planner), and
    // announces its setpoints to the controller.
    let df = tmp.path().join("df");
    let (o, out) = run(
        &df,
        &paper_python(),
        &["--mode", "dataflow", "--duration", "6"],
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let s = summary(&out);
    // Four Python planners at 10 Hz once their first inputs came.
    let steps = s["step_us"]["planner"]["count"].as_u64().unwrap();
    assert!(steps >= 4 * 40, "planner steps: {}", s["step_us"]);
    assert_eq!(s["samples_rejected"]["setpoint"], 0);
    let log = std::fs::read_to_string(out.join("logs/F1.planner.log")).unwrap();
    assert!(
        log.contains("F1/planner: dataflow, stepping on the arrivals of sonar, leader_pose"),
        "{log}"
    );
    assert_domain_clean(&run_id(&out));

    // Killed (SIGKILL) at 30 s, restarted with --restart 1, joined again.
    let rs = tmp.path().join("restart");
    let scenario = format!(
        "{}\n[supervision]\npolicy = \"restart\"\n\n[[faults]]\naction = \"kill\"\nvehicle = \"F3\"\nprocess = \"planner\"\nat_s = 30.0\n",
        paper_python().replace("duration_s = 200.0", "duration_s = 60.0")
    );
    let (o, out) = run(&rs, &scenario, &[]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let s = summary(&out);
    assert_eq!(events_of(&s, "F3/planner"), KILLED_AND_RESTARTED);
    assert_eq!(s["safety"]["collisions"], 0);
    assert_domain_clean(&run_id(&out));
}

/// A user planner for F1 as Python code run with `-c` (the run's arguments
/// follow it): `body` runs at every step with `node`, `step`, `sn`, `out`
/// (F1's setpoint publisher) and `msgs` in scope.
fn user_planner(body: &str) -> String {
    format!(
        "planner@F1={} -c 'import shoal_node as sn, time, math\nfrom shoal_node import msgs\nnode = sn.Node.from_args()\nout = node.publisher(\"setpoint\")\nfor step in node.steps():\n{}\n'",
        python3(),
        body.lines()
            .map(|l| format!("    {l}"))
            .collect::<Vec<_>>()
            .join("\n")
    )
}

/// Runs `scenario` with `extra` in `dir`: the run fails, its error says
/// every one of `needles`, and it leaves nothing behind.
fn fails_naming(dir: &Path, scenario: &str, extra: &[&str], needles: &[&str]) {
    let (o, out) = run(dir, scenario, extra);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success(), "{err}");
    assert!(
        needles.iter().all(|n| err.contains(n)),
        "{needles:?}: {err}"
    );
    assert_domain_clean(&run_id(&out));
}

#[test]
fn a_user_program_that_crashes_hangs_or_writes_garbage_is_named_and_leaves_nothing_behind() {
    let tmp = tempfile::tempdir().unwrap();
    let scenario = small_scenario("byo", 10.0);

    // Crashes at start: the run's error names the process and its exit.
    let flag = format!("planner@F1={} -c 'raise SystemExit(3)'", python3());
    fails_naming(
        &tmp.path().join("start"),
        &scenario,
        &["--replace", &flag],
        &["F1/planner", "exit code 3"],
    );

    // Crashes mid-run, with a traceback in its log, which the error shows.
    let flag =
        user_planner("if step.sim_time_s > 2.0:\n    raise RuntimeError(\"my planner gave up\")");
    fails_naming(
        &tmp.path().join("mid"),
        &scenario,
        &["--replace", &flag],
        &["F1/planner", "my planner gave up"],
    );

    // Hangs inside a step: the tick timeout names it.
    let flag = user_planner("if step.sim_time_s > 1.0:\n    time.sleep(3600)");
    fails_naming(
        &tmp.path().join("hang"),
        &scenario,
        &["--replace", &flag, "--tick-timeout", "5"],
        &["no progress", "F1/planner"],
    );

    // Writes garbage (NaN, or more keep-out points than a setpoint holds,
    // past the package's own check): the controller rejects and counts
    // every such sample, the recording holds none, and the run goes on to
    // its end.
    let dir = tmp.path().join("nan");
    let flag = user_planner(
        "sp = msgs.Setpoint()\nsp.header.sim_time_ns = step.sim_time_ns\nif step.tick % 2:\n    sp.position_m[0] = math.nan\nelse:\n    sp.keepout_count = 99\nout._pub.send_copy(sp)",
    );
    let (o, out) = run(&dir, &scenario, &["--replace", &flag]);
    // The run goes to its end, and its verdict (a fail) names the garbage.
    let said = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{said}");
    let s = summary(&out);
    assert_eq!(s["verdict"]["pass"], false);
    let failed = s["verdict"]["failed"].to_string();
    assert!(failed.contains("on setpoint rejected"), "{failed}");
    let rejected = s["samples_rejected"]["setpoint"].as_u64().unwrap();
    // 10 s at 10 Hz, each refused by F1's mpc and by the recorder.
    assert!(rejected >= 2 * 90, "setpoints rejected: {rejected}");
    let report = python_report("read_mcap.py", &[out.join("recording.mcap")]);
    let count = report["counts"]["/F1/setpoint"].as_u64().unwrap_or(0);
    assert_eq!(count, 0, "a NaN setpoint was recorded: {report}");
    assert_domain_clean(&run_id(&out));

    // A program that cannot be found is refused before anything starts.
    let dir = tmp.path().join("missing");
    let (o, out) = run(
        &dir,
        &scenario,
        &["--replace", "mpc@F2=./no-such-controller"],
    );
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(
        err.contains("no-such-controller") && err.contains("cannot be found"),
        "{err}"
    );
    assert!(!out.join("run.json").exists(), "a refused run started");
}

#[test]
fn the_campaign_runs_a_users_method_and_names_it() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("c");
    let flag = python_planner_flag();
    // The paper's method as published (shoal's planner) over the same
    // courses first, to be shown beside the user's.
    let theirs = tmp.path().join("published");
    let course = [
        "campaign",
        "--families",
        "gate,turn",
        "--courses",
        "2",
        "--published",
        "--quiet",
    ];
    let mut args = course.to_vec();
    args.extend(["--out", theirs.to_str().unwrap()]);
    let o = run_shoal(&args);
    assert!(
        matches!(o.status.code(), Some(0 | 3)),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let beside = theirs.join("campaign.json");
    let mut args = course.to_vec();
    args.extend([
        "--replace",
        &flag,
        "--beside",
        beside.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    let o = run_shoal(&args);
    let said = String::from_utf8_lossy(&o.stdout).to_string();
    // A failing run is the method's result, not the campaign's error.
    assert!(
        o.status.success() || o.status.code() == Some(3),
        "{said}{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("campaign.json")).unwrap()).unwrap();
    let method = r["method"].as_str().unwrap();
    assert!(
        method.starts_with("published, with --replace 'planner@followers=")
            && method.contains("paper_follower.py"),
        "{method}"
    );
    assert!(said.contains(method), "the table names the method: {said}");
    // The published campaign's pass counts stand beside the user's, per
    // family and over all.
    let published: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&beside).unwrap()).unwrap();
    assert!(
        said.contains(&format!("| family | {method} | published |")),
        "{said}"
    );
    for (own, theirs) in r["by_family"]
        .as_array()
        .unwrap()
        .iter()
        .zip(published["by_family"].as_array().unwrap())
    {
        let cell = |t: &serde_json::Value| format!("{}/{}", t["passed"], t["runs"]);
        let line = format!("| {} | {} (", own["family"].as_str().unwrap(), cell(own));
        let row = said
            .lines()
            .find(|l| l.starts_with(&line))
            .unwrap_or_else(|| panic!("no row {line}: {said}"));
        assert!(row.contains(&format!("| {} (", cell(theirs))), "{row}");
    }
    let runs = r["runs"].as_array().unwrap();
    assert_eq!(runs.len(), 2);
    for run in runs {
        let dir = std::path::Path::new(run["dir"].as_str().unwrap());
        // Each run flew the user's planner: its scenario says so, and its
        // followers' planner logs are Python's.
        let scenario = std::fs::read_to_string(dir.join("scenario.toml")).unwrap();
        assert!(scenario.contains("[[replace]]"), "{scenario}");
        let s = summary(dir);
        assert!(s["step_us"]["planner"]["count"].as_u64().unwrap() > 0);
        assert_eq!(s["samples_rejected"]["setpoint"], 0);
    }
}

#[test]
fn an_out_of_tree_rust_follower_takes_the_planners_place_and_passes() {
    // examples/rust-follower: a crate on shoal's runtime and libraries only,
    // built with the workspace's binaries.
    let bin = bin_dir().join("my-follower");
    assert!(bin.is_file(), "{} not built", bin.display());
    let tmp = tempfile::tempdir().unwrap();
    let paper = std::fs::read_to_string(repo_root().join("scenarios/paper.toml")).unwrap();
    let flag = format!("planner@followers={}", bin.display());
    let (o, out) = run(tmp.path(), &paper, &["--replace", &flag]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let s = summary(&out);
    assert_eq!(s["verdict"]["pass"], true, "verdict: {}", s["verdict"]);
    let rms = s["formation"]["slot_error_rms_m"]["after"]
        .as_f64()
        .unwrap();
    assert!(rms < 0.5, "after-passage slot RMS {rms} m");
    assert_planners_stepped(&s, 1900);
    // The replaced planners ran from the user's binary.
    let effective = std::fs::read_to_string(out.join("logs/effective-scenario.toml")).unwrap();
    assert!(effective.contains("my-follower"), "{effective}");
    assert_domain_clean(&run_id(&out));
}

#[test]
fn compare_puts_a_users_method_beside_the_papers_and_shoals() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("cmp");
    let flag = python_planner_flag();
    let o = run_shoal(&[
        "compare",
        "--quiet",
        "--replace",
        &flag,
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let rows: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("compare.json")).unwrap()).unwrap();
    let names: Vec<&str> = rows
        .as_array()
        .unwrap()
        .iter()
        .map(|r| r["variant"].as_str().unwrap())
        .collect();
    assert_eq!(
        names,
        [
            "method",
            "published",
            "acoustic",
            "no_vertical_shift",
            "yours"
        ]
    );
    // Yours flew the user's planner: its run's scenario names it, and it
    // passes the paper as the published method does.
    let scenario = std::fs::read_to_string(out.join("yours/scenario.toml")).unwrap();
    assert!(scenario.contains("paper_follower.py"), "{scenario}");
    let yours = &rows[4];
    assert_eq!(yours["pass"], true, "{yours}");
    let md = std::fs::read_to_string(out.join("compare.md")).unwrap();
    assert!(md.contains("vs yours (planner → `"), "{md}");
}

#[test]
fn the_python_package_passes_its_own_unit_tests() {
    // This checkout's package, whatever an editable install points at.
    let o = std::process::Command::new(python3())
        .args(["-m", "unittest", "discover", "-s", "python/tests", "-v"])
        .current_dir(repo_root())
        .env("PYTHONPATH", repo_root().join("python"))
        .output()
        .unwrap();
    let said = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{said}");
    // unittest's last line: OK (with the count of tests above it).
    assert!(said.trim_end().ends_with("OK"), "{said}");
}

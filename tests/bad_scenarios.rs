//! The corpus of bad scenarios in `tests/bad_scenarios/`: the real
//! `shoal check` refuses every file before anything starts, without a
//! panic, with a message that contains the file's `# expect:` line (which
//! names the key); the good scenarios in `scenarios/` pass.
//!
//! Each corpus file starts with comment lines:
//! `# <what is wrong>`, `# expect: <substring of the error>`, optionally
//! `# at: LINE` (the message starts `FILE:LINE: `, as a compiler's does),
//! and optionally `# rlimit-nofile: N` (the check runs under `ulimit -n N`,
//! for the "impossible for this machine" cases).
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use shoal_tests::{bin_dir, repo_root};

/// One corpus file.
struct Case {
    path: PathBuf,
    what: String,
    expect: String,
    at_line: Option<usize>,
    rlimit_nofile: Option<u64>,
}

fn corpus() -> Vec<Case> {
    let dir = repo_root().join("tests/bad_scenarios");
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    files.sort();
    files
        .into_iter()
        .map(|path| {
            let text = String::from_utf8_lossy(&std::fs::read(&path).unwrap()).into_owned();
            let header = |key: &str| {
                text.lines()
                    .take_while(|l| l.starts_with('#'))
                    .find_map(|l| l.strip_prefix(key).map(|v| v.trim().to_string()))
            };
            let expect = header("# expect:")
                .unwrap_or_else(|| panic!("{} has no `# expect:` line", path.display()));
            assert!(!expect.is_empty(), "{}: empty expect", path.display());
            Case {
                what: text
                    .lines()
                    .next()
                    .unwrap_or("")
                    .trim_start_matches('#')
                    .trim()
                    .to_string(),
                expect,
                at_line: header("# at:").map(|v| v.parse().unwrap()),
                rlimit_nofile: header("# rlimit-nofile:").map(|v| v.parse().unwrap()),
                path,
            }
        })
        .collect()
}

/// `shoal` alone in a fresh directory, so a check that tried to
/// start a service would find no binary; and an empty working directory.
struct Sandbox {
    _tmp: tempfile::TempDir,
    shoal: PathBuf,
    cwd: PathBuf,
}

impl Sandbox {
    fn new() -> Self {
        // A hard link, not a copy: a copy is open for writing while other
        // tests fork, and exec of a file open for writing fails (ETXTBSY).
        let tmp = tempfile::tempdir_in(bin_dir()).unwrap();
        let bin = tmp.path().join("bin");
        let cwd = tmp.path().join("cwd");
        std::fs::create_dir_all(&bin).unwrap();
        std::fs::create_dir_all(&cwd).unwrap();
        let shoal = bin.join("shoal");
        std::fs::hard_link(bin_dir().join("shoal"), &shoal).unwrap();
        Self {
            _tmp: tmp,
            shoal,
            cwd,
        }
    }

    fn check(&self, scenario: &Path, rlimit_nofile: Option<u64>) -> Output {
        let mut cmd = match rlimit_nofile {
            Some(n) => {
                let mut c = Command::new("sh");
                c.arg("-c")
                    .arg(r#"ulimit -n "$1" && exec "$2" check "$3""#)
                    .arg("sh")
                    .arg(n.to_string())
                    .arg(&self.shoal)
                    .arg(scenario);
                c
            }
            None => {
                let mut c = Command::new(&self.shoal);
                c.arg("check").arg(scenario);
                c
            }
        };
        let out = cmd.current_dir(&self.cwd).output().unwrap();
        let left: Vec<_> = std::fs::read_dir(&self.cwd).unwrap().collect();
        assert!(
            left.is_empty(),
            "check of {} wrote into its working directory: {left:?}",
            scenario.display()
        );
        out
    }
}

#[test]
fn every_bad_scenario_is_refused_naming_the_key() {
    let cases = corpus();
    assert!(
        cases.len() >= 30,
        "the corpus holds {} files, at least 30 are wanted",
        cases.len()
    );
    let sandbox = Sandbox::new();
    let mut failures = Vec::new();
    for c in &cases {
        let out = sandbox.check(&c.path, c.rlimit_nofile);
        let stderr = String::from_utf8_lossy(&out.stderr);
        let stdout = String::from_utf8_lossy(&out.stdout);
        let name = c.path.file_name().unwrap().to_string_lossy();
        if out.status.success() {
            failures.push(format!("{name} ({}): accepted\n{stdout}", c.what));
        } else if stderr.contains("panicked") || out.status.code().is_none() {
            failures.push(format!("{name}: crashed ({:?})\n{stderr}", out.status));
        } else if !stderr.contains(&c.expect) {
            failures.push(format!(
                "{name} ({}): the message does not contain `{}`:\n{stderr}",
                c.what, c.expect
            ));
        } else if let Some(line) = c.at_line {
            let place = format!("{}:{line}: ", c.path.display());
            if !stderr.contains(&place) {
                failures.push(format!(
                    "{name} ({}): the message is not placed at `{place}`:\n{stderr}",
                    c.what
                ));
            }
        }
    }
    assert!(
        failures.is_empty(),
        "{} of {} corpus files failed:\n{}",
        failures.len(),
        cases.len(),
        failures.join("\n")
    );
}

#[test]
fn good_scenarios_pass_the_same_check() {
    let sandbox = Sandbox::new();
    let dir = repo_root().join("scenarios");
    let mut n = 0;
    for e in std::fs::read_dir(&dir).unwrap() {
        let p = e.unwrap().path();
        if p.extension().is_none_or(|x| x != "toml") {
            continue;
        }
        let out = sandbox.check(&p, None);
        assert!(
            out.status.success(),
            "{} refused:\n{}",
            p.display(),
            String::from_utf8_lossy(&out.stderr)
        );
        assert!(String::from_utf8_lossy(&out.stdout).contains(": ok ("));
        n += 1;
    }
    assert!(n >= 1, "no scenario in {}", dir.display());
}

#[test]
fn the_machine_limit_is_what_refuses_the_big_group() {
    // The same 40-vehicle file passes under the hard limit: the refusal
    // comes from the limit, not from the file.
    let case = corpus()
        .into_iter()
        .find(|c| c.rlimit_nofile.is_some())
        .expect("a corpus file with # rlimit-nofile");
    let sandbox = Sandbox::new();
    let out = sandbox.check(&case.path, Some(65_536.min(hard_nofile())));
    assert!(
        out.status.success(),
        "{}: refused even with a high limit:\n{}",
        case.path.display(),
        String::from_utf8_lossy(&out.stderr)
    );
}

/// The hard `RLIMIT_NOFILE` of this process, from /proc/self/limits.
fn hard_nofile() -> u64 {
    let limits = std::fs::read_to_string("/proc/self/limits").unwrap();
    let line = limits
        .lines()
        .find(|l| l.starts_with("Max open files"))
        .unwrap();
    let hard = line.split_whitespace().nth(4).unwrap();
    hard.parse().unwrap_or(u64::MAX)
}

#[test]
fn oversized_inputs_are_refused_by_their_counts_before_anything_that_grows_with_them() {
    let dir = tempfile::tempdir().unwrap();
    let sandbox = Sandbox::new();
    // The inputs `shoal bench refuse` times.
    for (name, text, expect) in shoal::bench::refuse::oversized_inputs() {
        let path = dir.path().join(format!("{name}.toml"));
        std::fs::write(&path, text).unwrap();
        let out = sandbox.check(&path, None);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{name}: accepted");
        assert!(!stderr.contains("panicked"), "{name}: {stderr}");
        assert!(
            stderr.contains(expect),
            "{name}: `{expect}` not in {stderr}"
        );
    }
}

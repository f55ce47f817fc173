//! A real recording cut short at many byte offsets (as if the writer had
//! been SIGKILLed): `shoal inspect` reads it up to its last complete chunk
//! and says it is truncated; `shoal recover` writes a complete, indexed copy
//! holding exactly those messages, which the official Python reader opens
//! through its summary; nothing is overwritten; corrupt files give a clear
//! error, never a panic.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::path::{Path, PathBuf};
use std::process::Output;

use recordings::Recording;
use shoal_tests::{python, repo_root, run_shoal, run_shoal_ok, small_scenario, write_scenario};

/// Runs the small scenario with 16 KiB chunks (many chunks) and returns
/// the recording's path.
fn real_recording(dir: &Path) -> PathBuf {
    let text = format!(
        "{}\n[recording]\nchunk_kib = 16\n",
        small_scenario("recover", 20.0)
    );
    let sc = write_scenario(dir, "s.toml", &text);
    let out = dir.join("run");
    let o = run_shoal(&[
        "run",
        "--quiet",
        sc.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(
        o.status.success(),
        "run failed: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    out.join("recording.mcap")
}

fn ok(o: &Output, what: &str) -> String {
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(!stderr.contains("panicked"), "{what} panicked:\n{stderr}");
    assert!(o.status.success(), "{what} failed:\n{stderr}");
    String::from_utf8_lossy(&o.stdout).into_owned()
}

fn inspect_json(path: &Path) -> serde_json::Value {
    let o = run_shoal(&["inspect", "--json", path.to_str().unwrap()]);
    serde_json::from_str(&ok(&o, "inspect")).unwrap()
}

#[test]
fn truncated_recordings_are_reported_and_recovered_whole() {
    let tmp = tempfile::tempdir().unwrap();
    let rec_path = real_recording(tmp.path());
    let bytes = std::fs::read(&rec_path).unwrap();
    let full = Recording::open(&rec_path).unwrap();
    assert!(!full.truncated());
    let full_hashes = full.message_hashes();
    assert!(full_hashes.len() > 1000, "{} messages", full_hashes.len());

    // Offsets spread over the file, plus one inside the first chunk and
    // cuts of the end magic alone.
    let n = bytes.len();
    let mut offsets: Vec<usize> = (1..12).map(|k| n * k / 12).collect();
    offsets.extend([100, n - 1, n - 8]);
    let mut recovered_counts = Vec::new();
    for (i, &cut) in offsets.iter().enumerate() {
        let cut_path = tmp.path().join(format!("cut{i}.mcap"));
        std::fs::write(&cut_path, &bytes[..cut]).unwrap();

        // inspect: truncated, table says so, JSON says so.
        let report = inspect_json(&cut_path);
        assert_eq!(report["truncated"], true, "cut at {cut}: {report}");
        let table = ok(
            &run_shoal(&["inspect", cut_path.to_str().unwrap()]),
            "inspect",
        );
        assert!(table.contains("TRUNCATED"), "cut at {cut}: {table}");
        let seen = report["messages"].as_u64().unwrap() as usize;

        // What was read is a prefix of the whole recording.
        let cut_rec = Recording::open(&cut_path).unwrap();
        assert_eq!(cut_rec.messages().len(), seen);
        assert_eq!(
            cut_rec.message_hashes()[..],
            full_hashes[..seen],
            "cut at {cut}"
        );

        // recover: a complete copy with exactly those messages.
        let out = tmp.path().join(format!("cut{i}.recovered.mcap"));
        let o = run_shoal(&[
            "recover",
            "--json",
            cut_path.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ]);
        let r: serde_json::Value = serde_json::from_str(&ok(&o, "recover")).unwrap();
        assert_eq!(r["messages"].as_u64().unwrap() as usize, seen, "{r}");
        assert_eq!(r["input_truncated"], true, "{r}");
        let (kept, dropped) = (
            r["kept_bytes"].as_u64().unwrap(),
            r["dropped_bytes"].as_u64().unwrap(),
        );
        if r["data_section_complete"] == true {
            // Cut inside the summary: no data lost, the summary is rebuilt.
            assert!(dropped == 0 && kept <= cut as u64, "{r}");
            assert_eq!(seen, full_hashes.len());
        } else {
            // (A cut exactly between two records drops nothing.)
            assert_eq!(kept + dropped, cut as u64, "{r}");
        }
        let back = Recording::open(&out).unwrap();
        assert!(!back.truncated(), "cut at {cut}: the copy is truncated");
        assert_eq!(back.message_hashes(), cut_rec.message_hashes());
        // Every record the cut file kept, but the copy's own rosbag2
        // record, which counts what the copy holds.
        let mut kept_meta = cut_rec.metadata().clone();
        kept_meta.remove("rosbag2");
        let mut back_meta = back.metadata().clone();
        let bag = back_meta
            .remove("rosbag2")
            .expect("the copy has a rosbag2 record");
        assert_eq!(back_meta, kept_meta);
        assert!(
            bag["serialized_metadata"].contains(&format!("\n  message_count: {seen}\n")),
            "cut at {cut}: {bag:?}"
        );
        let again = inspect_json(&out);
        assert_eq!(again["truncated"], false);
        recovered_counts.push((cut, seen, out));
    }
    // More of the file, never fewer messages; the last cut (end magic
    // missing) keeps every message.
    for w in recovered_counts.windows(2) {
        if w[0].0 < w[1].0 {
            assert!(w[0].1 <= w[1].1, "{} then {}", w[0].1, w[1].1);
        }
    }
    let (_, last_seen, _) = recovered_counts.last().unwrap();
    assert_eq!(*last_seen, full_hashes.len());

    // The official reader opens three of the copies through their summary.
    for (cut, seen, out) in [
        &recovered_counts[0],
        &recovered_counts[5],
        &recovered_counts[10],
    ] {
        let py = python()
            .arg(repo_root().join("tests/python/check_recovered.py"))
            .arg(out)
            .output()
            .unwrap();
        assert!(
            py.status.success(),
            "cut at {cut}: python reader refused the copy: {}",
            String::from_utf8_lossy(&py.stderr)
        );
        let report: serde_json::Value = serde_json::from_slice(&py.stdout).unwrap();
        assert_eq!(report["messages"].as_u64().unwrap() as usize, *seen);
        assert!(report["chunks"].as_u64().unwrap() >= 1 || *seen == 0);
    }

    // Cut inside the file header: nothing readable, a clear error.
    let cut_path = tmp.path().join("cut-header.mcap");
    std::fs::write(&cut_path, &bytes[..9]).unwrap();
    for cmd in ["inspect", "recover"] {
        let o = run_shoal(&[cmd, cut_path.to_str().unwrap()]);
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert!(
            !o.status.success() && !stderr.contains("panicked"),
            "{stderr}"
        );
        assert!(
            stderr.contains("before its first complete record")
                || stderr.contains("cannot be recovered"),
            "{stderr}"
        );
    }

    // Nothing is overwritten: the same output again is refused, intact.
    let (_, _, out) = &recovered_counts[3];
    let before = std::fs::read(out).unwrap();
    let o = run_shoal(&[
        "recover",
        rec_path.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("exists already"));
    assert_eq!(std::fs::read(out).unwrap(), before);

    // A complete recording recovers to the same messages, 0 bytes dropped;
    // the default output is REC.recovered.mcap.
    let o = run_shoal(&["recover", "--json", rec_path.to_str().unwrap()]);
    let r: serde_json::Value = serde_json::from_str(&ok(&o, "recover")).unwrap();
    assert_eq!(r["dropped_bytes"], 0);
    assert_eq!(r["input_truncated"], false);
    let default_out = rec_path.with_extension("recovered.mcap");
    assert_eq!(r["output"], default_out.display().to_string());
    assert_eq!(
        Recording::open(&default_out).unwrap().message_hashes(),
        full_hashes
    );
}

#[test]
fn corrupt_files_give_a_clear_error_never_a_panic() {
    let tmp = tempfile::tempdir().unwrap();
    let cases: [(&str, Vec<u8>); 4] = [
        ("empty", Vec::new()),
        ("text", b"name = \"not a recording\"\n".to_vec()),
        ("magic, then garbage", {
            let mut b = b"\x89MCAP0\r\n".to_vec();
            b.extend(std::iter::repeat_n(0xFFu8, 64));
            b
        }),
        ("magic, then a record that claims 2^63 bytes", {
            let mut b = b"\x89MCAP0\r\n".to_vec();
            b.push(0x06);
            b.extend((1u64 << 63).to_le_bytes());
            b.extend([0u8; 32]);
            b
        }),
    ];
    for (what, bytes) in cases {
        let p = tmp.path().join("bad.mcap");
        std::fs::write(&p, &bytes).unwrap();
        for args in [
            vec!["inspect", p.to_str().unwrap()],
            vec![
                "recover",
                p.to_str().unwrap(),
                "--out",
                tmp.path().join("out.mcap").to_str().unwrap(),
            ],
        ] {
            let o = run_shoal(&args);
            let stderr = String::from_utf8_lossy(&o.stderr);
            assert!(!o.status.success(), "{what}: {} accepted it", args[0]);
            assert!(!stderr.contains("panicked"), "{what}: {stderr}");
            assert!(
                stderr.contains("error: ") && stderr.contains("bad.mcap"),
                "{what}: {} gave no clear error: {stderr}",
                args[0]
            );
        }
        assert!(!tmp.path().join("out.mcap").exists());
        assert!(!tmp.path().join("out.mcap.partial").exists());
    }
}

/// A tmpfs of `size` mounted on `dir` for one test, unmounted when dropped
/// (also on failure).
struct SmallDisk(PathBuf);

impl SmallDisk {
    fn mount(dir: &Path, size: &str) -> Self {
        std::fs::create_dir_all(dir).unwrap();
        let status = std::process::Command::new("mount")
            .args(["-t", "tmpfs", "-o", &format!("size={size}"), "tmpfs"])
            .arg(dir)
            .status()
            .unwrap();
        assert!(
            status.success(),
            "mounting a small tmpfs needs root (as the hosts tests do)"
        );
        Self(dir.to_path_buf())
    }
}

impl Drop for SmallDisk {
    fn drop(&mut self) {
        let _ = std::process::Command::new("umount")
            .arg("-l")
            .arg(&self.0)
            .status();
    }
}

#[test]
fn a_run_that_fills_its_disk_stops_naming_the_disk_and_its_recording_still_reads() {
    let tmp = tempfile::tempdir().unwrap();
    let disk = SmallDisk::mount(&tmp.path().join("small"), "3m");
    let out = disk.0.join("run");
    // `shoal check` says beforehand that it will not fit; with room
    // elsewhere, it says nothing.
    let o = run_shoal_ok(&["check", "--out", out.to_str().unwrap()]);
    let said = String::from_utf8_lossy(&o.stdout);
    assert!(
        said.contains("warning: the output disk cannot hold the expected recording"),
        "{said}"
    );
    let o = run_shoal_ok(&["check", "--out", tmp.path().to_str().unwrap()]);
    let said = String::from_utf8_lossy(&o.stdout);
    assert!(
        said.contains("recording: about") && !said.contains("cannot hold"),
        "{said}"
    );
    // The paper scenario records about 10 MB: it cannot fit.
    let o = run_shoal(&["run", "--quiet", "--out", out.to_str().unwrap()]);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success(), "the run fitted on 3 MiB");
    assert!(
        stderr.contains("the output disk is full") && stderr.contains(out.to_str().unwrap()),
        "{stderr}"
    );
    let run: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("run.json")).unwrap()).unwrap();
    shoal_tests::assert_domain_clean(run["run_id"].as_str().unwrap());

    // What was written reads: a whole copy elsewhere, and a summary.
    let rec = out.join("recording.mcap");
    let copy = tmp.path().join("copy.mcap");
    ok(
        &run_shoal(&[
            "recover",
            rec.to_str().unwrap(),
            "--out",
            copy.to_str().unwrap(),
        ]),
        "recover",
    );
    let n = Recording::open(&copy)
        .unwrap()
        .topic_messages("/L/truth")
        .count();
    assert!(n > 100, "{n} truths recovered");
    let summary_dir = tmp.path().join("summary");
    ok(
        &run_shoal(&[
            "summarize",
            rec.to_str().unwrap(),
            "--out",
            summary_dir.to_str().unwrap(),
        ]),
        "summarize",
    );
    let s = shoal_tests::summary(&summary_dir);
    assert!(s["sim_time_s"].as_f64().unwrap() > 10.0, "{s}");
}

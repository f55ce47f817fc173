//! Joining the files of a recorder that was restarted during a run.
#![allow(clippy::unwrap_used)] // test fixtures

use ipc_types::Sample;
use recordings::{merge, Compression, Recording, RecordingWriter, WriterOptions};

/// Writes `/L/truth` samples `from..to` and, when `finish` is false, leaves
/// the file as a killed writer would (no summary, last chunk maybe cut).
fn part(path: &std::path::Path, from: u64, to: u64, finish: bool, meta: &str) {
    let opts = WriterOptions {
        compression: Compression::Zstd,
        chunk_bytes: 4096,
        ..WriterOptions::default()
    };
    let mut w = RecordingWriter::create(path, &opts).unwrap();
    let truth = w.add_channel::<ipc_types::Truth>("/L/truth").unwrap();
    let ev = w.add_channel::<ipc_types::Event>("/events").unwrap();
    let mut m = std::collections::BTreeMap::new();
    m.insert("part".to_string(), meta.to_string());
    w.metadata("shoal.run", m).unwrap();
    for i in from..to {
        let mut tr = ipc_types::Truth::zeroed();
        tr.header.seq = i;
        tr.header.sim_time_ns = i * 100_000_000;
        tr.position_ned_m = [i as f64, 0.0, 10.0];
        w.write(truth, &tr).unwrap();
    }
    // The events channel keeps history: every part holds event 0.
    let mut e = ipc_types::Event::zeroed();
    e.kind = ipc_types::EventKind::ProcessDied as u32;
    w.write(ev, &e).unwrap();
    if finish {
        w.finish().unwrap();
    } else {
        w.flush().unwrap();
        std::mem::forget(w); // a killed writer: no summary, no footer
    }
}

#[test]
fn parts_join_in_order_with_the_overlap_written_once() {
    let dir = tempfile::tempdir().unwrap();
    let (a, b, out) = (
        dir.path().join("recording.mcap"),
        dir.path().join("recording.r1.mcap"),
        dir.path().join("merged.mcap"),
    );
    // The first recorder died after sample 299; the second got 298 and 299
    // again from the publisher's history and went on to 599.
    part(&a, 0, 300, false, "first");
    part(&b, 298, 600, true, "second");
    assert!(Recording::open(&a).unwrap().truncated());
    let report = merge(&[&a, &b], &out).unwrap();
    assert!(report.input_truncated);
    assert_eq!(report.channels, 2);
    assert_eq!(report.schemas, 2);
    assert_eq!(
        report.metadata, 2,
        "one shoal.run record (the first) and the copy's own rosbag2 record"
    );
    let rec = Recording::open(&out).unwrap();
    assert!(!rec.truncated());
    let truths = rec.samples::<ipc_types::Truth>("/L/truth");
    let seqs: Vec<u64> = truths.iter().map(|t| t.header.seq).collect();
    assert_eq!(seqs, (0..600).collect::<Vec<_>>());
    assert_eq!(rec.samples::<ipc_types::Event>("/events").len(), 1);
    assert_eq!(rec.metadata()["shoal.run"]["part"], "first");
    // The rosbag2 record counts the copy, not the finished part alone.
    let bag = &rec.metadata()["rosbag2"]["serialized_metadata"];
    assert!(bag.contains("  message_count: 601\n"), "{bag}");
    assert!(
        bag.contains("name: \"/L/truth\"\n        type: \"shoal_msgs/msg/Truth\""),
        "{bag}"
    );
    // Nothing is overwritten.
    assert!(merge(&[&a, &b], &out).is_err());
}

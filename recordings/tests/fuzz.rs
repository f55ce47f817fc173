//! The MCAP reader and `recover` against random and mutated input: random
//! bytes, real recordings (zstd, lz4, uncompressed; small chunks) cut at
//! random offsets, with random byte flips, insertions, deletions and
//! corrupted length fields. Never a panic, never a hang, and never an
//! allocation beyond a small multiple of the input's size (measured by a
//! counting allocator, per thread). A cut recording reads as a prefix of
//! the whole one.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::path::Path;
use std::sync::OnceLock;
use std::time::{Duration, Instant};

use ipc_types::Sample;
use proptest::prelude::*;
use recordings::{Compression, Recording, RecordingWriter, WriterOptions};

// ---- a per-thread peak-allocation counter -------------------------------

struct Counting;

thread_local! {
    static LIVE: Cell<usize> = const { Cell::new(0) };
    static PEAK: Cell<usize> = const { Cell::new(0) };
}

fn note_alloc(n: usize) {
    let _ = LIVE.try_with(|l| {
        let v = l.get().saturating_add(n);
        l.set(v);
        let _ = PEAK.try_with(|p| p.set(p.get().max(v)));
    });
}

fn note_free(n: usize) {
    let _ = LIVE.try_with(|l| l.set(l.get().saturating_sub(n)));
}

// SAFETY: forwards to the system allocator; only counts.
#[allow(unsafe_code)]
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        note_alloc(layout.size());
        // SAFETY: same contract as the caller's.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        note_free(layout.size());
        // SAFETY: same contract as the caller's.
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        note_alloc(layout.size());
        // SAFETY: same contract as the caller's.
        unsafe { System.alloc_zeroed(layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        note_free(layout.size());
        note_alloc(new_size);
        // SAFETY: same contract as the caller's.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static ALLOC: Counting = Counting;

/// Most bytes reading `len` input bytes may hold at once: chunks may
/// decompress to 256× (the reader's bound), plus a fixed allowance.
fn alloc_bound(len: usize) -> usize {
    300 * len + (16 << 20)
}

/// Runs `f`, asserting that it returns within 10 s and that the thread's
/// allocations never rose more than [`alloc_bound`]`(len)` above the start.
fn bounded<R>(len: usize, what: &str, f: impl FnOnce() -> R) -> R {
    let start_live = LIVE.with(Cell::get);
    PEAK.with(|p| p.set(start_live));
    let t0 = Instant::now();
    let r = f();
    let took = t0.elapsed();
    let peak = PEAK.with(Cell::get) - start_live;
    assert!(
        took < Duration::from_secs(10),
        "{what}: {took:?} on {len} bytes"
    );
    assert!(
        peak <= alloc_bound(len),
        "{what}: allocated {peak} bytes at peak for {len} input bytes"
    );
    r
}

// ---- real recordings ----------------------------------------------------

/// A recording of three channels, 400 messages each, with a metadata
/// record, written by shoal's writer with 4 KiB chunks.
fn make_recording(compression: Compression) -> Vec<u8> {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("r.mcap");
    let opts = WriterOptions {
        compression,
        chunk_bytes: 4096,
        ..WriterOptions::default()
    };
    let mut w = RecordingWriter::create(&path, &opts).unwrap();
    let nav = w.add_channel::<ipc_types::Nav>("/L/nav").unwrap();
    let truth = w.add_channel::<ipc_types::Truth>("/L/truth").unwrap();
    let thrust = w.add_channel::<ipc_types::Thrust>("/F1/thrust").unwrap();
    let mut meta = std::collections::BTreeMap::new();
    meta.insert("scenario".to_string(), "fuzz".to_string());
    w.metadata("shoal.run", meta).unwrap();
    for i in 0..400u64 {
        let t = i * 100_000_000;
        let mut n = ipc_types::Nav::zeroed();
        n.header.seq = i;
        n.header.sim_time_ns = t;
        n.depth_m = 10.0 + (i as f64 * 0.37).sin();
        w.write(nav, &n).unwrap();
        let mut tr = ipc_types::Truth::zeroed();
        tr.header.seq = i;
        tr.header.sim_time_ns = t;
        tr.position_ned_m = [i as f64 * 0.1, (i as f64).cos(), 10.0];
        w.write(truth, &tr).unwrap();
        let mut th = ipc_types::Thrust::zeroed();
        th.header.seq = i;
        th.header.sim_time_ns = t;
        w.write(thrust, &th).unwrap();
    }
    w.finish().unwrap();
    std::fs::read(&path).unwrap()
}

struct Corpus {
    files: Vec<(&'static str, Vec<u8>, Recording)>,
}

fn corpus() -> &'static Corpus {
    static C: OnceLock<Corpus> = OnceLock::new();
    C.get_or_init(|| Corpus {
        files: [
            ("zstd", Compression::Zstd),
            ("lz4", Compression::Lz4),
            ("none", Compression::None),
        ]
        .into_iter()
        .map(|(name, c)| {
            let bytes = make_recording(c);
            let rec = Recording::from_bytes(Path::new(name), &bytes).unwrap();
            assert!(!rec.truncated());
            assert_eq!(rec.messages().len(), 1200);
            (name, bytes, rec)
        })
        .collect(),
    })
}

fn read(bytes: &[u8], what: &str) -> Option<Recording> {
    bounded(bytes.len(), what, || {
        Recording::from_bytes(Path::new("fuzz.mcap"), bytes).ok()
    })
}

/// Offsets of the top-level records' length fields (after the magic).
fn length_fields(bytes: &[u8]) -> Vec<usize> {
    let mut out = Vec::new();
    let mut pos = 8;
    while pos + 9 <= bytes.len() {
        out.push(pos + 1);
        let len = u64::from_le_bytes(bytes[pos + 1..pos + 9].try_into().unwrap());
        match usize::try_from(len)
            .ok()
            .and_then(|l| pos.checked_add(9 + l))
        {
            Some(next) if next <= bytes.len() => pos = next,
            _ => break,
        }
    }
    out
}

/// A mutation of a real recording.
#[derive(Debug, Clone)]
enum Mutation {
    Cut(usize),
    Flip(Vec<(usize, u8)>),
    Insert(usize, Vec<u8>),
    Delete(usize, usize),
    Length(usize, u64),
}

fn apply(bytes: &[u8], m: &Mutation) -> Vec<u8> {
    let n = bytes.len();
    match m {
        Mutation::Cut(at) => bytes[..at % (n + 1)].to_vec(),
        Mutation::Flip(flips) => {
            let mut b = bytes.to_vec();
            for (at, x) in flips {
                b[at % n] ^= x | 1;
            }
            b
        }
        Mutation::Insert(at, ins) => {
            let mut b = bytes.to_vec();
            let at = at % (n + 1);
            b.splice(at..at, ins.iter().copied());
            b
        }
        Mutation::Delete(at, len) => {
            let mut b = bytes.to_vec();
            let at = at % n;
            let end = (at + len).min(n);
            b.drain(at..end);
            b
        }
        Mutation::Length(which, value) => {
            let mut b = bytes.to_vec();
            let fields = length_fields(bytes);
            let at = fields[which % fields.len()];
            b[at..at + 8].copy_from_slice(&value.to_le_bytes());
            b
        }
    }
}

fn mutation() -> impl Strategy<Value = Mutation> {
    let huge = prop_oneof![
        Just(u64::MAX),
        Just(1u64 << 63),
        Just(1u64 << 40),
        Just(u64::from(u32::MAX)),
        0u64..100_000,
        any::<u64>(),
    ];
    prop_oneof![
        any::<usize>().prop_map(Mutation::Cut),
        prop::collection::vec((any::<usize>(), any::<u8>()), 1..16).prop_map(Mutation::Flip),
        (any::<usize>(), prop::collection::vec(any::<u8>(), 1..64))
            .prop_map(|(a, b)| Mutation::Insert(a, b)),
        (any::<usize>(), 1usize..256).prop_map(|(a, l)| Mutation::Delete(a, l)),
        (any::<usize>(), huge).prop_map(|(w, v)| Mutation::Length(w, v)),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 3000, ..ProptestConfig::default() })]

    /// Random bytes, bare or behind the MCAP magic (and the header record
    /// shoal writes), never panic and never allocate beyond the bound.
    #[test]
    fn random_bytes_never_panic(body in prop::collection::vec(any::<u8>(), 0..4096), prefix in 0usize..3) {
        let mut bytes = Vec::new();
        if prefix >= 1 {
            bytes.extend_from_slice(mcap::MAGIC);
        }
        if prefix == 2 {
            let real = &corpus().files[0].1;
            bytes.extend_from_slice(&real[8..40.min(real.len())]);
        }
        bytes.extend_from_slice(&body);
        let _ = read(&bytes, "random bytes");
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 1500, ..ProptestConfig::default() })]

    /// A real recording cut anywhere reads as a prefix of the whole one,
    /// marked truncated.
    #[test]
    fn a_cut_recording_reads_as_a_prefix(which in 0usize..3, at in any::<usize>()) {
        let (name, bytes, full) = &corpus().files[which];
        let cut = at % bytes.len();
        if let Some(rec) = read(&bytes[..cut], name) {
            prop_assert!(rec.truncated(), "{name} cut at {cut} not reported truncated");
            let n = rec.messages().len();
            prop_assert_eq!(rec.messages(), &full.messages()[..n]);
            prop_assert!(rec.dropped_bytes() as usize <= cut);
        }
    }

    /// Any mutation of a real recording: no panic, bounded memory and time.
    #[test]
    fn mutated_recordings_never_panic(which in 0usize..3, m in mutation()) {
        let (name, bytes, _) = &corpus().files[which];
        let b = apply(bytes, &m);
        let _ = read(&b, name);
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 300, ..ProptestConfig::default() })]

    /// `recover` on mutated recordings: no panic; when it succeeds the copy
    /// is complete and holds exactly what the reader found in the input.
    #[test]
    fn recover_never_panics_and_its_copy_is_whole(which in 0usize..3, m in mutation()) {
        let (name, bytes, _) = &corpus().files[which];
        let b = apply(bytes, &m);
        let dir = tempfile::tempdir().unwrap();
        let input = dir.path().join("in.mcap");
        let output = dir.path().join("out.mcap");
        std::fs::write(&input, &b).unwrap();
        let result = bounded(b.len(), name, || recordings::recover(&input, &output));
        let read_in = Recording::from_bytes(&input, &b);
        match result {
            Ok(report) => {
                let copy = Recording::open(&output).unwrap();
                prop_assert!(!copy.truncated());
                let original = read_in.unwrap();
                prop_assert_eq!(report.messages as usize, copy.messages().len());
                // Messages of channels that were never declared cannot be copied.
                let declared: Vec<u16> = original.channels().iter().map(|c| c.id).collect();
                let kept = original.messages().iter().filter(|m| declared.contains(&m.channel)).count();
                prop_assert_eq!(kept, copy.messages().len());
            }
            Err(_) => prop_assert!(!output.exists()),
        }
        prop_assert!(!dir.path().join("out.mcap.partial").exists());
    }
}

#[test]
fn every_length_field_set_to_huge_values_is_survived() {
    for (name, bytes, _) in &corpus().files {
        let fields = length_fields(bytes);
        assert!(fields.len() > 10, "{name}: {} records", fields.len());
        for (i, _) in fields.iter().enumerate() {
            for v in [u64::MAX, 1 << 40, u64::from(u32::MAX), 0, 7] {
                let b = apply(bytes, &Mutation::Length(i, v));
                let _ = read(&b, name);
            }
        }
    }
}

#[test]
fn cuts_at_and_around_every_record_boundary_read_as_a_prefix() {
    // At, just before and just after every top-level record boundary (where
    // a writer killed between two flushes leaves the file) and inside each
    // record's opcode and length, every byte of the first 256, and every
    // 997th byte elsewhere; all three compressions.
    for (name, bytes, full) in &corpus().files {
        let mut cuts: Vec<usize> = (0..256).chain((0..bytes.len()).step_by(997)).collect();
        for f in length_fields(bytes) {
            let start = f - 1;
            cuts.extend(
                [
                    start.saturating_sub(1),
                    start,
                    start + 1,
                    start + 5,
                    start + 9,
                    start + 10,
                ]
                .into_iter()
                .filter(|c| *c < bytes.len()),
            );
        }
        cuts.sort_unstable();
        cuts.dedup();
        for cut in cuts {
            if let Some(rec) = read(&bytes[..cut], name) {
                assert!(rec.truncated(), "{name} cut at {cut}");
                let n = rec.messages().len();
                assert_eq!(rec.messages(), &full.messages()[..n], "{name} cut at {cut}");
            }
        }
    }
}

//! Recovering a recording whose writer died: everything up to the last
//! complete chunk is copied into a new, complete MCAP file with a summary
//! and indexes, so every reader (and seeking) works on it again.
//!
//! ```no_run
//! let report = recordings::recover("run/recording.mcap".as_ref(), "run/recovered.mcap".as_ref())?;
//! println!("{} messages saved, {} bytes dropped", report.messages, report.dropped_bytes);
//! # Ok::<(), recordings::RecoverError>(())
//! ```

use std::collections::HashMap;
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use crate::rosbag2;
use crate::scan::{scan, Item};

/// Why a recording could not be recovered.
#[derive(Debug, thiserror::Error)]
pub enum RecoverError {
    /// The input could not be read.
    #[error("cannot read {path}: {source}")]
    Read {
        /// The input.
        path: PathBuf,
        /// Cause.
        source: std::io::Error,
    },
    /// The input holds nothing readable.
    #[error("{path} cannot be recovered: {reason}")]
    Unreadable {
        /// The input.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// The output exists already; nothing is overwritten.
    #[error("{0} exists already (nothing was overwritten); choose another --out")]
    Exists(PathBuf),
    /// The output could not be written.
    #[error("cannot write {path}: {source}")]
    Write {
        /// The output (or its temporary file).
        path: PathBuf,
        /// Cause.
        source: std::io::Error,
    },
    /// The MCAP writer refused something.
    #[error("mcap: {0}")]
    Mcap(#[from] mcap::McapError),
    /// The copy did not read back as written (a bug; the copy is removed).
    #[error("the recovered copy does not read back: {0}")]
    Verify(String),
}

/// What [`recover`] did.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
pub struct RecoverReport {
    /// The input file.
    pub input: String,
    /// The complete copy.
    pub output: String,
    /// Size of the input, bytes.
    pub input_bytes: u64,
    /// Bytes of the input that were read: up to the end of its last
    /// complete record.
    pub kept_bytes: u64,
    /// Bytes after that, which could not be read and were dropped (0 for
    /// an input whose data section was complete).
    pub dropped_bytes: u64,
    /// The input's data section ended properly (only its summary, which the
    /// copy rebuilds, was missing or cut).
    pub data_section_complete: bool,
    /// The input was cut short or corrupt.
    pub input_truncated: bool,
    /// Why reading the input stopped, if it stopped early.
    pub stop_reason: Option<String>,
    /// Complete chunks read.
    pub chunks: u64,
    /// Schemas copied.
    pub schemas: u64,
    /// Channels copied.
    pub channels: u64,
    /// Metadata records copied.
    pub metadata: u64,
    /// Messages copied.
    pub messages: u64,
    /// Size of the copy, bytes.
    pub output_bytes: u64,
}

/// Copies what is readable of `input` into a new complete MCAP file at
/// `output` (which must not exist: nothing is overwritten). Chunks keep
/// the input's compression. The copy is written beside `output` under a
/// temporary name, read back and checked, then moved into place.
pub fn recover(input: &Path, output: &Path) -> Result<RecoverReport, RecoverError> {
    merge(&[input], output)
}

/// Joins recordings written one after the other (a recorder that was
/// restarted during a run writes a new file each time) into one complete
/// MCAP file at `output`, like [`recover`] does for one: each input is read
/// up to its last complete chunk. Channels and schemas are matched by topic
/// and name; a message that an earlier input holds already (same channel,
/// log time and sequence: a restarted recorder receives the publishers'
/// history again) is written once. Metadata records are kept once per name
/// (the first). The report's byte counts add up over the inputs; its
/// `input` names them joined by ` + `.
pub fn merge(inputs: &[&Path], output: &Path) -> Result<RecoverReport, RecoverError> {
    join(inputs, output, Join::Restarts)
}

/// Joins recordings written side by side (one recorder per host of a run
/// spread over hosts, each recording what its host's processes publish)
/// into one complete MCAP file at `output`, messages in log-time order
/// (ties: input order, then the input's own order). Nothing is taken for a
/// duplicate: two hosts' `/stats` samples may share a time and sequence.
/// Metadata records are kept once per name (the first), except the
/// recorders' counts (`shoal.recorder`: messages, dropped, rejected), which
/// add up over the inputs, and the hosts, which `shoal.run` lists
/// (`hosts`, comma-separated, in input order).
pub fn join_hosts(inputs: &[&Path], output: &Path) -> Result<RecoverReport, RecoverError> {
    join(inputs, output, Join::Hosts)
}

/// How inputs are joined.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Join {
    /// One after the other in time; repeats dropped.
    Restarts,
    /// Side by side; interleaved by time; counts added.
    Hosts,
}

/// A message held until every input has been read (joining hosts).
struct Held {
    log_time: u64,
    input: usize,
    order: usize,
    header: mcap::records::MessageHeader,
    data: Vec<u8>,
}

/// The recorder counts that add up over hosts.
const SUMMED: [&str; 3] = ["messages", "dropped", "rejected"];

fn join(inputs: &[&Path], output: &Path, how: Join) -> Result<RecoverReport, RecoverError> {
    if output.exists() {
        return Err(RecoverError::Exists(output.to_path_buf()));
    }
    let mut all = Vec::with_capacity(inputs.len());
    for input in inputs {
        let bytes = std::fs::read(input).map_err(|source| RecoverError::Read {
            path: input.to_path_buf(),
            source,
        })?;
        all.push((input.to_path_buf(), bytes));
    }
    let mut name = output.file_name().unwrap_or_default().to_os_string();
    name.push(".partial");
    let tmp = output.with_file_name(name);
    let file = File::options()
        .write(true)
        .create_new(true)
        .open(&tmp)
        .map_err(|source| RecoverError::Write {
            path: tmp.clone(),
            source,
        })?;
    let result = copy(&all, file, output, how).and_then(|mut report| {
        report.output_bytes = verify(&tmp, &report)?;
        // Hard link then unlink: fails rather than replace an output that
        // appeared meanwhile.
        std::fs::hard_link(&tmp, output).map_err(|source| {
            if source.kind() == std::io::ErrorKind::AlreadyExists {
                RecoverError::Exists(output.to_path_buf())
            } else {
                RecoverError::Write {
                    path: output.to_path_buf(),
                    source,
                }
            }
        })?;
        Ok(report)
    });
    let _ = std::fs::remove_file(&tmp);
    result
}

/// Writes the copy of `inputs` (path, bytes), in order, into `file`; the
/// report names `output`.
fn copy(
    inputs: &[(PathBuf, Vec<u8>)],
    file: File,
    output: &Path,
    how: Join,
) -> Result<RecoverReport, RecoverError> {
    // First pass over the first input: the profile and compression go in
    // the copy's header and options.
    let Some((first_path, first)) = inputs.first() else {
        return Err(RecoverError::Unreadable {
            path: output.to_path_buf(),
            reason: "no input".into(),
        });
    };
    let mut profile = String::new();
    let probe = scan(first, |item| {
        if let Item::Header { profile: p } = item {
            profile = p;
        }
    });
    if probe.good_end <= mcap::MAGIC.len() {
        return Err(RecoverError::Unreadable {
            path: first_path.clone(),
            reason: probe
                .error
                .unwrap_or_else(|| "no record after the magic".into()),
        });
    }
    let compression = match probe.compression.as_deref() {
        Some("lz4") => Some(mcap::Compression::Lz4),
        Some("") => None,
        _ => Some(mcap::Compression::Zstd),
    };
    let ros2 = profile == "ros2";
    let mut writer = mcap::WriteOptions::new()
        .compression(compression)
        .compression_threads(0)
        .profile(profile)
        .library(format!("shoal recover {}", env!("CARGO_PKG_VERSION")))
        .create(BufWriter::with_capacity(1 << 20, file))?;

    let mut report = RecoverReport {
        input: inputs
            .iter()
            .map(|(p, _)| p.display().to_string())
            .collect::<Vec<_>>()
            .join(" + "),
        output: output.display().to_string(),
        input_bytes: 0,
        kept_bytes: 0,
        dropped_bytes: 0,
        data_section_complete: true,
        input_truncated: false,
        stop_reason: None,
        chunks: 0,
        schemas: 0,
        channels: 0,
        metadata: 0,
        messages: 0,
        output_bytes: 0,
    };
    // Output ids by schema name and by topic, shared by all inputs.
    let mut schemas_by_name: HashMap<String, u16> = HashMap::new();
    let mut channels_by_topic: HashMap<String, u16> = HashMap::new();
    // Per output channel: (log time, sequence) of the last message an
    // earlier input wrote.
    let mut written_before: HashMap<u16, (u64, u32)> = HashMap::new();
    let mut metadata_names: std::collections::HashSet<String> = Default::default();
    // The copy's own rosbag2 record: an input's (if any) counts only that
    // input's messages, and a cut input has none.
    let mut schema_names: HashMap<u16, String> = HashMap::new();
    let mut topics: std::collections::BTreeMap<u16, rosbag2::Topic> = Default::default();
    let mut span: Option<(u64, u64)> = None;
    // Joining hosts: every message, and the metadata, until the end.
    let mut held: Vec<Held> = Vec::new();
    let mut held_metadata: Vec<(String, std::collections::BTreeMap<String, String>)> = Vec::new();
    let mut hosts: Vec<String> = Vec::new();
    for (input, (path, bytes)) in inputs.iter().enumerate() {
        let mut schema_ids: HashMap<u16, u16> = HashMap::new();
        let mut channel_ids: HashMap<u16, u16> = HashMap::new();
        let mut written_now: HashMap<u16, (u64, u32)> = HashMap::new();
        let mut failure: Option<mcap::McapError> = None;
        let end = scan(bytes, |item| {
            if failure.is_some() {
                return;
            }
            let step = (|| -> Result<(), mcap::McapError> {
                match item {
                    Item::Header { .. } => {}
                    Item::Schema(s) => {
                        if let std::collections::hash_map::Entry::Vacant(e) = schema_ids.entry(s.id)
                        {
                            let id = match schemas_by_name.get(&s.name) {
                                Some(&id) => id,
                                None => {
                                    let id = writer.add_schema(&s.name, &s.encoding, &s.data)?;
                                    schemas_by_name.insert(s.name.clone(), id);
                                    schema_names.insert(id, s.name.clone());
                                    report.schemas += 1;
                                    id
                                }
                            };
                            e.insert(id);
                        }
                    }
                    Item::Channel(c) => {
                        if channel_ids.contains_key(&c.id) {
                            return Ok(());
                        }
                        let id = match channels_by_topic.get(&c.topic) {
                            Some(&id) => id,
                            None => {
                                // Schema id 0 means "no schema"; an unknown one is dropped to 0.
                                let schema = schema_ids.get(&c.schema_id).copied().unwrap_or(0);
                                let id = writer.add_channel(
                                    schema,
                                    &c.topic,
                                    &c.message_encoding,
                                    &c.metadata,
                                )?;
                                channels_by_topic.insert(c.topic.clone(), id);
                                report.channels += 1;
                                topics.insert(
                                    id,
                                    rosbag2::Topic {
                                        name: c.topic.clone(),
                                        type_name: schema_names
                                            .get(&schema)
                                            .cloned()
                                            .unwrap_or_default(),
                                        qos: c
                                            .metadata
                                            .get(rosbag2::OFFERED_QOS_PROFILES)
                                            .cloned()
                                            .unwrap_or_default(),
                                        messages: 0,
                                    },
                                );
                                id
                            }
                        };
                        channel_ids.insert(c.id, id);
                    }
                    Item::Message(m) => {
                        // A message of a channel never declared cannot be written.
                        if let Some(&id) = channel_ids.get(&m.channel_id) {
                            let key = (m.log_time, m.sequence);
                            let header = mcap::records::MessageHeader {
                                channel_id: id,
                                sequence: m.sequence,
                                log_time: m.log_time,
                                publish_time: m.publish_time,
                            };
                            if how == Join::Hosts {
                                held.push(Held {
                                    log_time: m.log_time,
                                    input,
                                    order: held.len(),
                                    header,
                                    data: m.data,
                                });
                            } else {
                                if written_before.get(&id).is_some_and(|last| key <= *last) {
                                    return Ok(());
                                }
                                writer.write_to_known_channel(&header, &m.data)?;
                            }
                            let last = written_now.entry(id).or_insert(key);
                            *last = (*last).max(key);
                            report.messages += 1;
                            if let Some(t) = topics.get_mut(&id) {
                                t.messages += 1;
                            }
                            span = Some(match span {
                                None => (m.log_time, m.log_time),
                                Some((a, b)) => (a.min(m.log_time), b.max(m.log_time)),
                            });
                        }
                    }
                    Item::Metadata { name, values } => {
                        // An input's rosbag2 record counts that input only.
                        if name == rosbag2::RECORD_NAME {
                            return Ok(());
                        }
                        if how == Join::Hosts {
                            if name == "shoal.run" {
                                hosts.extend(values.get("host").cloned());
                            }
                            match held_metadata.iter_mut().find(|(n, _)| *n == name) {
                                Some((_, kept)) if name == "shoal.recorder" => {
                                    for k in SUMMED {
                                        let add = |v: Option<&String>| {
                                            v.and_then(|v| v.parse::<u64>().ok()).unwrap_or(0)
                                        };
                                        let sum = add(kept.get(k)) + add(values.get(k));
                                        kept.insert(k.to_string(), sum.to_string());
                                    }
                                }
                                Some(_) => {}
                                None => held_metadata.push((name, values)),
                            }
                            return Ok(());
                        }
                        if metadata_names.insert(name.clone()) {
                            writer.write_metadata(&mcap::records::Metadata {
                                name,
                                metadata: values,
                            })?;
                            report.metadata += 1;
                        }
                    }
                }
                Ok(())
            })();
            if let Err(e) = step {
                failure = Some(e);
            }
        });
        if let Some(e) = failure {
            return Err(e.into());
        }
        for (id, key) in written_now {
            let last = written_before.entry(id).or_insert(key);
            *last = (*last).max(key);
        }
        let complete = bytes.len() >= 16 && bytes[bytes.len() - 8..] == *mcap::MAGIC;
        report.input_bytes += bytes.len() as u64;
        report.kept_bytes += end.good_end as u64;
        if !end.data_end {
            report.dropped_bytes += (bytes.len() - end.good_end) as u64;
        }
        report.data_section_complete &= end.data_end;
        report.input_truncated |= !complete || !end.data_end || end.error.is_some();
        if let Some(e) = end.error {
            report.stop_reason.get_or_insert(if inputs.len() > 1 {
                format!("{}: {e}", path.display())
            } else {
                e
            });
        }
        report.chunks += end.chunks;
    }
    if how == Join::Hosts {
        held.sort_unstable_by_key(|h| (h.log_time, h.input, h.order));
        for h in &held {
            writer.write_to_known_channel(&h.header, &h.data)?;
        }
        for (name, mut values) in held_metadata {
            if name == "shoal.run" && !hosts.is_empty() {
                values.remove("host");
                values.insert("hosts".to_string(), hosts.join(","));
            }
            writer.write_metadata(&mcap::records::Metadata {
                name,
                metadata: values,
            })?;
            report.metadata += 1;
        }
    }
    if ros2 {
        let (start, end) = span.unwrap_or((0, 0));
        let file = output
            .file_name()
            .map_or_else(String::new, |n| n.to_string_lossy().into_owned());
        let topics: Vec<rosbag2::Topic> = topics.into_values().collect();
        writer.write_metadata(&mcap::records::Metadata {
            name: rosbag2::RECORD_NAME.to_string(),
            metadata: std::collections::BTreeMap::from([(
                rosbag2::SERIALIZED_METADATA.to_string(),
                rosbag2::serialized_metadata(&file, &topics, start, end),
            )]),
        })?;
        report.metadata += 1;
    }
    writer.finish()?;
    drop(writer);
    Ok(report)
}

/// Reads the copy back: complete, with a summary, and every message there.
/// Returns its size.
fn verify(tmp: &Path, report: &RecoverReport) -> Result<u64, RecoverError> {
    let bytes = std::fs::read(tmp).map_err(|source| RecoverError::Read {
        path: tmp.to_path_buf(),
        source,
    })?;
    let back = crate::Recording::from_bytes(tmp, &bytes)
        .map_err(|e| RecoverError::Verify(e.to_string()))?;
    if back.truncated() {
        return Err(RecoverError::Verify(format!(
            "the copy reads as truncated: {:?}",
            back.stop_reason()
        )));
    }
    if back.messages().len() as u64 != report.messages {
        return Err(RecoverError::Verify(format!(
            "{} messages written, {} read back",
            report.messages,
            back.messages().len()
        )));
    }
    match mcap::Summary::read(&bytes) {
        Ok(Some(_)) => Ok(bytes.len() as u64),
        Ok(None) => Err(RecoverError::Verify("the copy has no summary".into())),
        Err(e) => Err(RecoverError::Verify(format!("summary: {e}"))),
    }
}

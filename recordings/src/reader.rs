//! Reading a recording: channels, messages, metadata, and the facts
//! `shoal inspect` prints. A truncated file (the writer was killed) is read
//! up to its last complete chunk and reported as truncated.

use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};

use sha2::{Digest, Sha256};

use crate::registry::type_info_by_schema;
use crate::scan::{scan, Item};
use crate::writer::CDR_HEADER;

/// Errors of the reader.
#[derive(Debug, thiserror::Error)]
pub enum RecordingError {
    /// The file could not be read.
    #[error("cannot read {path}: {source}")]
    Io {
        /// The path.
        path: PathBuf,
        /// Cause.
        source: std::io::Error,
    },
    /// Not an MCAP file, or broken before any complete chunk.
    #[error("{path} is not a readable MCAP file: {reason}")]
    Format {
        /// The path.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
}

/// One channel of a recording.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ChannelInfo {
    /// MCAP channel id.
    pub id: u16,
    /// Topic, `/<vehicle>/<channel>`.
    pub topic: String,
    /// Schema name, e.g. `shoal_msgs/msg/Nav`.
    pub schema_name: String,
    /// Message encoding (`cdr`).
    pub encoding: String,
}

/// One message.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct StoredMessage {
    /// MCAP channel id.
    pub channel: u16,
    /// Log time (simulation time), ns.
    pub log_time: u64,
    /// Sequence number (the sample's, truncated to 32 bits).
    pub sequence: u32,
    /// CDR header + raw sample bytes.
    pub data: Vec<u8>,
}

/// A recording loaded in memory.
#[derive(Debug, Clone)]
pub struct Recording {
    path: PathBuf,
    channels: Vec<ChannelInfo>,
    messages: Vec<StoredMessage>,
    metadata: BTreeMap<String, BTreeMap<String, String>>,
    truncated: bool,
    stop_reason: Option<String>,
    dropped_bytes: u64,
}

impl Recording {
    /// Reads a file. A file cut short is read up to its last complete chunk.
    pub fn open(path: &Path) -> Result<Self, RecordingError> {
        let bytes = std::fs::read(path).map_err(|source| RecordingError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        Self::from_bytes(path, &bytes)
    }

    /// Parses MCAP bytes. Never panics and allocates at most a small
    /// multiple of `bytes.len()`, whatever the bytes hold (see the `scan`
    /// module): a file cut short or corrupted after some complete chunks
    /// gives those chunks and [`Self::truncated`]; a file broken before
    /// anything readable is an error.
    pub fn from_bytes(path: &Path, bytes: &[u8]) -> Result<Self, RecordingError> {
        let mut schemas: HashMap<u16, String> = HashMap::new();
        let mut channels: Vec<ChannelInfo> = Vec::new();
        let mut messages: Vec<StoredMessage> = Vec::new();
        let mut metadata: BTreeMap<String, BTreeMap<String, String>> = BTreeMap::new();
        let end = scan(bytes, |item| match item {
            Item::Schema(s) => {
                schemas.insert(s.id, s.name);
            }
            Item::Channel(c) if !channels.iter().any(|x| x.id == c.id) => {
                channels.push(ChannelInfo {
                    id: c.id,
                    topic: c.topic,
                    schema_name: schemas.get(&c.schema_id).cloned().unwrap_or_default(),
                    encoding: c.message_encoding,
                });
            }
            Item::Message(m) => messages.push(StoredMessage {
                channel: m.channel_id,
                log_time: m.log_time,
                sequence: m.sequence,
                data: m.data,
            }),
            Item::Metadata { name, values } => {
                metadata.insert(name, values);
            }
            Item::Header { .. } | Item::Channel(_) => {}
        });
        if end.good_end <= mcap::MAGIC.len() && end.error.is_some() {
            return Err(RecordingError::Format {
                path: path.to_path_buf(),
                reason: format!(
                    "broken before its first complete record: {}",
                    end.error.unwrap_or_default()
                ),
            });
        }
        let complete = bytes.len() >= 16 && &bytes[bytes.len() - 8..] == mcap::MAGIC;
        let truncated = !complete || !end.data_end || end.error.is_some();
        Ok(Self {
            path: path.to_path_buf(),
            channels,
            messages,
            metadata,
            truncated,
            stop_reason: end.error,
            dropped_bytes: if end.data_end {
                0
            } else {
                (bytes.len() - end.good_end) as u64
            },
        })
    }

    /// The file this was read from.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Channels in id order.
    pub fn channels(&self) -> &[ChannelInfo] {
        &self.channels
    }

    /// A channel by topic.
    pub fn channel(&self, topic: &str) -> Option<&ChannelInfo> {
        self.channels.iter().find(|c| c.topic == topic)
    }

    /// Every message, in file order.
    pub fn messages(&self) -> &[StoredMessage] {
        &self.messages
    }

    /// Messages of one topic, in file order.
    pub fn topic_messages<'a>(
        &'a self,
        topic: &str,
    ) -> impl Iterator<Item = &'a StoredMessage> + 'a {
        let id = self.channel(topic).map(|c| c.id);
        self.messages.iter().filter(move |m| Some(m.channel) == id)
    }

    /// Decoded samples of one topic.
    pub fn samples<T: ipc_types::Sample>(&self, topic: &str) -> Vec<T> {
        self.topic_messages(topic)
            .filter_map(|m| crate::decode::<T>(&m.data))
            .collect()
    }

    /// Metadata records by name.
    pub fn metadata(&self) -> &BTreeMap<String, BTreeMap<String, String>> {
        &self.metadata
    }

    /// A value of the `shoal.run` record the recorder writes first
    /// (`scenario_toml`, `effective_toml`, `mode`, `run_id`,
    /// `start_unix_ns`, …).
    pub fn run_meta(&self, key: &str) -> Option<&str> {
        self.metadata
            .get("shoal.run")
            .and_then(|m| m.get(key))
            .map(String::as_str)
    }

    /// True when shoal wrote the file: it has the `shoal.run` record or a
    /// channel of a shoal sample type.
    pub fn written_by_shoal(&self) -> bool {
        self.metadata.contains_key("shoal.run")
            || self
                .channels
                .iter()
                .any(|c| crate::type_info_by_schema(&c.schema_name).is_some())
    }

    /// True if the file was cut short (no footer, or a broken last chunk).
    pub fn truncated(&self) -> bool {
        self.truncated
    }

    /// Why reading stopped before the end of the data section, if it did
    /// (e.g. `record 0x06 at byte 1234 claims 5000 bytes, 300 remain`).
    pub fn stop_reason(&self) -> Option<&str> {
        self.stop_reason.as_deref()
    }

    /// Bytes after the last complete record that could not be read (0 for
    /// a file whose data section ended properly).
    pub fn dropped_bytes(&self) -> u64 {
        self.dropped_bytes
    }

    /// One hash per message (topic, log time, payload with wall-clock fields
    /// zeroed), in file order: equal for two lockstep runs of the same
    /// scenario and seed.
    pub fn message_hashes(&self) -> Vec<[u8; 32]> {
        let mut masks: HashMap<u16, (String, Vec<std::ops::Range<usize>>)> = HashMap::new();
        for c in &self.channels {
            let ranges = type_info_by_schema(&c.schema_name)
                .map(|t| (t.wall_clock)())
                .unwrap_or_default();
            masks.insert(c.id, (c.topic.clone(), ranges));
        }
        let mut out = Vec::with_capacity(self.messages.len());
        let mut buf = Vec::new();
        for m in &self.messages {
            let (topic, ranges) = masks
                .get(&m.channel)
                .map(|(t, r)| (t.as_str(), r.as_slice()))
                .unwrap_or(("", &[]));
            buf.clear();
            buf.extend_from_slice(&m.data);
            let off = CDR_HEADER.len();
            for r in ranges {
                if off + r.end <= buf.len() {
                    buf[off + r.start..off + r.end].fill(0);
                }
            }
            let mut h = Sha256::new();
            h.update(topic.as_bytes());
            h.update(m.log_time.to_le_bytes());
            h.update(&buf);
            out.push(h.finalize().into());
        }
        out
    }

    /// One hash of the whole recording: SHA-256 over [`Self::message_hashes`]
    /// in order, hex. Two lockstep runs of the same scenario and seed give
    /// the same digest (`shoal inspect --digest`).
    pub fn digest(&self) -> String {
        let mut h = Sha256::new();
        for m in self.message_hashes() {
            h.update(m);
        }
        h.finalize().iter().map(|b| format!("{b:02x}")).collect()
    }

    /// What `shoal inspect` prints.
    pub fn inspect(&self) -> InspectReport {
        let mut per: BTreeMap<String, ChannelStats> = BTreeMap::new();
        let mut first = u64::MAX;
        let mut last = 0u64;
        let by_id: HashMap<u16, &ChannelInfo> = self.channels.iter().map(|c| (c.id, c)).collect();
        let mut last_seq: HashMap<u16, u32> = HashMap::new();
        for m in &self.messages {
            let Some(c) = by_id.get(&m.channel) else {
                continue;
            };
            let s = per.entry(c.topic.clone()).or_insert_with(|| ChannelStats {
                topic: c.topic.clone(),
                schema: c.schema_name.clone(),
                messages: 0,
                first_s: m.log_time as f64 * 1e-9,
                last_s: 0.0,
                rate_hz: 0.0,
                gaps: 0,
                max_interval_s: 0.0,
            });
            let t = m.log_time as f64 * 1e-9;
            if s.messages > 0 {
                s.max_interval_s = s.max_interval_s.max(t - s.last_s);
            }
            s.messages += 1;
            s.last_s = t;
            if let Some(prev) = last_seq.get(&m.channel) {
                if m.sequence > prev.wrapping_add(1) {
                    s.gaps += u64::from(m.sequence - prev - 1);
                }
            }
            last_seq.insert(m.channel, m.sequence);
            first = first.min(m.log_time);
            last = last.max(m.log_time);
        }
        // Channels with no message still appear.
        for c in &self.channels {
            per.entry(c.topic.clone()).or_insert_with(|| ChannelStats {
                topic: c.topic.clone(),
                schema: c.schema_name.clone(),
                messages: 0,
                first_s: 0.0,
                last_s: 0.0,
                rate_hz: 0.0,
                gaps: 0,
                max_interval_s: 0.0,
            });
        }
        for s in per.values_mut() {
            let span = s.last_s - s.first_s;
            s.rate_hz = if s.messages > 1 && span > 0.0 {
                (s.messages - 1) as f64 / span
            } else {
                0.0
            };
        }
        InspectReport {
            path: self.path.display().to_string(),
            messages: self.messages.len() as u64,
            start_s: if first == u64::MAX {
                0.0
            } else {
                first as f64 * 1e-9
            },
            end_s: last as f64 * 1e-9,
            truncated: self.truncated,
            dropped_bytes: self.dropped_bytes,
            stop_reason: self.stop_reason.clone(),
            channels: per.into_values().collect(),
            metadata: self.metadata.clone(),
        }
    }
}

/// Per-channel facts.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct ChannelStats {
    /// Topic.
    pub topic: String,
    /// Schema name.
    pub schema: String,
    /// Message count.
    pub messages: u64,
    /// First message, s.
    pub first_s: f64,
    /// Last message, s.
    pub last_s: f64,
    /// Mean rate, Hz.
    pub rate_hz: f64,
    /// Messages missing by sequence number.
    pub gaps: u64,
    /// Longest interval between two messages, s.
    pub max_interval_s: f64,
}

/// What `shoal inspect` prints.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct InspectReport {
    /// The file.
    pub path: String,
    /// Messages in all.
    pub messages: u64,
    /// First message, s.
    pub start_s: f64,
    /// Last message, s.
    pub end_s: f64,
    /// The file was cut short.
    pub truncated: bool,
    /// Bytes after the last complete record that could not be read.
    pub dropped_bytes: u64,
    /// Why reading stopped early, if it did.
    pub stop_reason: Option<String>,
    /// Per channel.
    pub channels: Vec<ChannelStats>,
    /// Metadata records.
    pub metadata: BTreeMap<String, BTreeMap<String, String>>,
}

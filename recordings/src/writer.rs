//! Writing a recording.

use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::{BufWriter, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

use ipc_types::Sample;

use crate::registry::type_info;
use crate::rosbag2;

/// CDR little-endian encapsulation header that precedes every payload.
pub const CDR_HEADER: [u8; 4] = [0x00, 0x01, 0x00, 0x00];

/// Chunk compression.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Compression {
    /// zstd.
    Zstd,
    /// lz4.
    Lz4,
    /// none.
    None,
}

/// Options of a recording.
#[derive(Debug, Clone)]
pub struct WriterOptions {
    /// Chunk compression (default zstd).
    pub compression: Compression,
    /// The zstd level (default 1, the fastest; 0 is zstd's own default, 3).
    pub zstd_level: u32,
    /// Target chunk size, bytes (default 1 MiB).
    pub chunk_bytes: u64,
    /// The keep-last depth each channel's `offered_qos_profiles` states
    /// (the recorder's buffer per channel; default 1).
    pub qos_depth: usize,
}

impl Default for WriterOptions {
    fn default() -> Self {
        Self {
            compression: Compression::Zstd,
            zstd_level: 1,
            chunk_bytes: 1 << 20,
            qos_depth: 1,
        }
    }
}

/// Errors of the writer.
#[derive(Debug, thiserror::Error)]
pub enum WriterError {
    /// The file could not be created.
    #[error("cannot create {path}: {source}")]
    Create {
        /// The path.
        path: PathBuf,
        /// Cause.
        source: std::io::Error,
    },
    /// The MCAP library refused something.
    #[error("mcap: {0}")]
    Mcap(#[from] mcap::McapError),
    /// A schema could not be generated.
    #[error("schema: {0}")]
    Schema(#[from] ipc_types::schema::SchemaError),
    /// A channel id that was never added.
    #[error("unknown channel id {0}")]
    UnknownChannel(u16),
}

/// A buffered file that keeps count of its own position.
///
/// The MCAP writer asks for the stream position once per channel at the end
/// of every chunk (the message index offsets); `BufWriter` answered each
/// question by writing out its buffer and calling lseek(2). Measured with
/// `shoal bench step --syscalls` on the paper scenario: the recorder made
/// 5.6 lseek and 5.0 write calls per step; this answers from the count.
struct Counted<W: Write + Seek> {
    inner: BufWriter<W>,
    pos: u64,
}

impl<W: Write + Seek> Counted<W> {
    fn new(inner: BufWriter<W>) -> Self {
        Self { inner, pos: 0 }
    }
}

impl<W: Write + Seek> Write for Counted<W> {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        let n = self.inner.write(buf)?;
        self.pos += n as u64;
        Ok(n)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.inner.flush()
    }
}

impl<W: Write + Seek> Seek for Counted<W> {
    fn seek(&mut self, to: SeekFrom) -> std::io::Result<u64> {
        if to == SeekFrom::Current(0) {
            return Ok(self.pos);
        }
        self.pos = self.inner.seek(to)?;
        Ok(self.pos)
    }

    fn stream_position(&mut self) -> std::io::Result<u64> {
        Ok(self.pos)
    }
}

/// Writes samples to one MCAP file.
pub struct RecordingWriter {
    writer: mcap::Writer<Counted<File>>,
    schemas: HashMap<&'static str, u16>,
    /// Per channel id: the bag's topic, its message count kept current.
    topics: BTreeMap<u16, rosbag2::Topic>,
    /// First and last log time written, ns.
    span: Option<(u64, u64)>,
    file_name: String,
    qos: String,
    buf: Vec<u8>,
    messages: u64,
    /// Per channel id: its topic and schema, for a live view of the same
    /// channels ([`RecordingWriter::channel_schema`]).
    channel_schemas: BTreeMap<u16, ChannelSchema>,
}

/// A channel as the recording declares it: topic and `ros2msg` schema, the
/// messages `cdr`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ChannelSchema {
    /// Topic, e.g. `/F1/planner_state`.
    pub topic: String,
    /// Schema name, e.g. `shoal_msgs/msg/PlannerState`.
    pub schema_name: String,
    /// The `ros2msg` schema text, dependencies included.
    pub schema_text: String,
}

impl RecordingWriter {
    /// Creates the file. Compression runs on the calling thread (mcap's
    /// default of one thread per CPU is slower on two cores).
    pub fn create(path: &Path, opts: &WriterOptions) -> Result<Self, WriterError> {
        let file = File::create(path).map_err(|source| WriterError::Create {
            path: path.to_path_buf(),
            source,
        })?;
        let (compression, level) = match opts.compression {
            Compression::Zstd => (Some(mcap::Compression::Zstd), opts.zstd_level),
            Compression::Lz4 => (Some(mcap::Compression::Lz4), 0),
            Compression::None => (None, 0),
        };
        let writer = mcap::WriteOptions::new()
            .compression(compression)
            .compression_level(level)
            .compression_threads(0)
            .chunk_size(Some(opts.chunk_bytes))
            .profile("ros2")
            .library(format!("shoal {}", env!("CARGO_PKG_VERSION")))
            .create(Counted::new(BufWriter::with_capacity(1 << 20, file)))?;
        Ok(Self {
            writer,
            schemas: HashMap::new(),
            topics: BTreeMap::new(),
            span: None,
            file_name: path
                .file_name()
                .map_or_else(String::new, |n| n.to_string_lossy().into_owned()),
            qos: rosbag2::offered_qos_profiles(opts.qos_depth),
            buf: Vec::with_capacity(32 * 1024),
            messages: 0,
            channel_schemas: BTreeMap::new(),
        })
    }

    /// Adds a channel carrying samples of type `T` on `topic`; returns its id.
    /// Its offered QoS states the writer's default depth
    /// ([`WriterOptions::qos_depth`]).
    pub fn add_channel<T: Sample>(&mut self, topic: &str) -> Result<u16, WriterError> {
        let qos = self.qos.clone();
        self.add_channel_qos::<T>(topic, qos)
    }

    /// [`RecordingWriter::add_channel`] with the keep-last `depth` this
    /// channel's subscriber really has.
    pub fn add_channel_with_depth<T: Sample>(
        &mut self,
        topic: &str,
        depth: usize,
    ) -> Result<u16, WriterError> {
        self.add_channel_qos::<T>(topic, rosbag2::offered_qos_profiles(depth))
    }

    fn add_channel_qos<T: Sample>(&mut self, topic: &str, qos: String) -> Result<u16, WriterError> {
        let info = type_info::<T>();
        let text = (info.schema)()?;
        let schema_id = match self.schemas.get(info.schema_name) {
            Some(id) => *id,
            None => {
                let id = self
                    .writer
                    .add_schema(info.schema_name, "ros2msg", text.as_bytes())?;
                self.schemas.insert(info.schema_name, id);
                id
            }
        };
        self.add_channel_with_schema(
            topic,
            (schema_id, info.schema_name, &text),
            info.type_name,
            qos,
        )
    }

    /// Adds a follower's camera frames as `sensor_msgs/msg/Image` (see
    /// [`crate::image`]); write them with [`Self::write_raw`], the body from
    /// [`crate::image::encode`]. `depth` is the subscriber's queue.
    pub fn add_image_channel(&mut self, topic: &str, depth: usize) -> Result<u16, WriterError> {
        let name = crate::image::SCHEMA_NAME;
        let schema_id = match self.schemas.get(name) {
            Some(id) => *id,
            None => {
                let id = self.writer.add_schema(
                    name,
                    "ros2msg",
                    crate::image::SCHEMA_TEXT.as_bytes(),
                )?;
                self.schemas.insert(name, id);
                id
            }
        };
        let qos = rosbag2::offered_qos_profiles(depth);
        self.add_channel_with_schema(
            topic,
            (schema_id, name, crate::image::SCHEMA_TEXT),
            ipc_types::Image::TYPE_NAME,
            qos,
        )
    }

    /// Adds a channel whose schema is `(id, name, text)`.
    fn add_channel_with_schema(
        &mut self,
        topic: &str,
        (schema_id, schema_name, schema_text): (u16, &str, &str),
        type_name: &str,
        qos: String,
    ) -> Result<u16, WriterError> {
        let mut meta = BTreeMap::new();
        meta.insert("shoal.type_name".to_string(), type_name.to_string());
        meta.insert(rosbag2::OFFERED_QOS_PROFILES.to_string(), qos.clone());
        let id = self.writer.add_channel(schema_id, topic, "cdr", &meta)?;
        self.topics.insert(
            id,
            rosbag2::Topic {
                name: topic.to_string(),
                type_name: schema_name.to_string(),
                qos,
                messages: 0,
            },
        );
        self.channel_schemas.insert(
            id,
            ChannelSchema {
                topic: topic.to_string(),
                schema_name: schema_name.to_string(),
                schema_text: schema_text.to_string(),
            },
        );
        Ok(id)
    }

    /// The topic and schema of channel `id`, as the recording declares them.
    pub fn channel_schema(&self, id: u16) -> Option<&ChannelSchema> {
        self.channel_schemas.get(&id)
    }

    /// The message body (CDR) the last write put in the file: what a live
    /// view sends, with no second encoding.
    pub fn last_message(&self) -> &[u8] {
        &self.buf
    }

    /// Writes one sample; log and publish time are its simulation time.
    pub fn write<T: Sample>(&mut self, channel: u16, sample: &T) -> Result<(), WriterError> {
        self.write_raw(
            channel,
            sample.header().sim_time_ns,
            sample.header().seq,
            bytemuck::bytes_of(sample),
        )
    }

    /// Writes one sample given as raw bytes.
    pub fn write_raw(
        &mut self,
        channel: u16,
        sim_time_ns: u64,
        seq: u64,
        bytes: &[u8],
    ) -> Result<(), WriterError> {
        // One lookup per message; the count goes up once the write is done.
        let Some(topic) = self.topics.get_mut(&channel) else {
            return Err(WriterError::UnknownChannel(channel));
        };
        self.buf.clear();
        self.buf.extend_from_slice(&CDR_HEADER);
        self.buf.extend_from_slice(bytes);
        let header = mcap::records::MessageHeader {
            channel_id: channel,
            sequence: seq as u32,
            log_time: sim_time_ns,
            publish_time: sim_time_ns,
        };
        self.writer.write_to_known_channel(&header, &self.buf)?;
        self.messages += 1;
        topic.messages += 1;
        self.span = Some(match self.span {
            None => (sim_time_ns, sim_time_ns),
            Some((a, b)) => (a.min(sim_time_ns), b.max(sim_time_ns)),
        });
        Ok(())
    }

    /// Writes a metadata record (name → key/value map).
    pub fn metadata(
        &mut self,
        name: &str,
        values: BTreeMap<String, String>,
    ) -> Result<(), WriterError> {
        self.writer.write_metadata(&mcap::records::Metadata {
            name: name.to_string(),
            metadata: values,
        })?;
        Ok(())
    }

    /// Messages written so far.
    pub fn messages(&self) -> u64 {
        self.messages
    }

    /// Ends the current chunk and flushes it to the file, so a crash loses
    /// at most what came after.
    pub fn flush(&mut self) -> Result<(), WriterError> {
        self.writer.flush()?;
        Ok(())
    }

    /// Writes the `rosbag2` metadata record, the summary and index, and
    /// closes the file.
    pub fn finish(mut self) -> Result<u64, WriterError> {
        let topics: Vec<rosbag2::Topic> = std::mem::take(&mut self.topics).into_values().collect();
        let (start, end) = self.span.unwrap_or((0, 0));
        let yaml = rosbag2::serialized_metadata(&self.file_name, &topics, start, end);
        self.metadata(
            rosbag2::RECORD_NAME,
            BTreeMap::from([(rosbag2::SERIALIZED_METADATA.to_string(), yaml)]),
        )?;
        self.writer.finish()?;
        Ok(self.messages)
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use std::io::Cursor;

    #[test]
    fn a_counted_file_knows_its_position_and_seeks_as_the_file_does() {
        let mut w = Counted::new(BufWriter::new(Cursor::new(Vec::new())));
        w.write_all(b"hello, ").unwrap();
        assert_eq!(w.stream_position().unwrap(), 7);
        w.write_all(b"world").unwrap();
        // The form a writer may ask in, besides `stream_position`.
        #[allow(clippy::seek_from_current)]
        let here = w.seek(SeekFrom::Current(0)).unwrap();
        assert_eq!(here, 12);
        // A header rewritten in place, then back to the end.
        assert_eq!(w.seek(SeekFrom::Start(0)).unwrap(), 0);
        w.write_all(b"H").unwrap();
        assert_eq!(w.stream_position().unwrap(), 1);
        assert_eq!(w.seek(SeekFrom::End(0)).unwrap(), 12);
        w.write_all(b"!").unwrap();
        assert_eq!(w.stream_position().unwrap(), 13);
        w.flush().unwrap();
        assert_eq!(w.inner.get_ref().get_ref().as_slice(), b"Hello, world!");
    }
}

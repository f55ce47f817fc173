//! Writing a recording.

use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use ipc_types::Sample;

use crate::registry::type_info;

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
    /// Target chunk size, bytes (default 1 MiB).
    pub chunk_bytes: u64,
}

impl Default for WriterOptions {
    fn default() -> Self {
        Self {
            compression: Compression::Zstd,
            chunk_bytes: 1 << 20,
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

/// Writes samples to one MCAP file.
pub struct RecordingWriter {
    writer: mcap::Writer<BufWriter<File>>,
    schemas: HashMap<&'static str, u16>,
    channel_sizes: HashMap<u16, usize>,
    buf: Vec<u8>,
    messages: u64,
}

impl RecordingWriter {
    /// Creates the file. Compression runs on the calling thread (mcap's
    /// default of one thread per CPU is slower on two cores).
    pub fn create(path: &Path, opts: &WriterOptions) -> Result<Self, WriterError> {
        let file = File::create(path).map_err(|source| WriterError::Create {
            path: path.to_path_buf(),
            source,
        })?;
        let compression = match opts.compression {
            Compression::Zstd => Some(mcap::Compression::Zstd),
            Compression::Lz4 => Some(mcap::Compression::Lz4),
            Compression::None => None,
        };
        let writer = mcap::WriteOptions::new()
            .compression(compression)
            .compression_threads(0)
            .chunk_size(Some(opts.chunk_bytes))
            .profile("ros2")
            .library(format!("shoal {}", env!("CARGO_PKG_VERSION")))
            .create(BufWriter::with_capacity(1 << 20, file))?;
        Ok(Self {
            writer,
            schemas: HashMap::new(),
            channel_sizes: HashMap::new(),
            buf: Vec::with_capacity(32 * 1024),
            messages: 0,
        })
    }

    /// Adds a channel carrying samples of type `T` on `topic`; returns its id.
    pub fn add_channel<T: Sample>(&mut self, topic: &str) -> Result<u16, WriterError> {
        let info = type_info::<T>();
        let schema_id = match self.schemas.get(info.schema_name) {
            Some(id) => *id,
            None => {
                let text = (info.schema)()?;
                let id = self
                    .writer
                    .add_schema(info.schema_name, "ros2msg", text.as_bytes())?;
                self.schemas.insert(info.schema_name, id);
                id
            }
        };
        let mut meta = BTreeMap::new();
        meta.insert("shoal.type_name".to_string(), info.type_name.to_string());
        let id = self.writer.add_channel(schema_id, topic, "cdr", &meta)?;
        self.channel_sizes.insert(id, info.size);
        Ok(id)
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
        if !self.channel_sizes.contains_key(&channel) {
            return Err(WriterError::UnknownChannel(channel));
        }
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

    /// Writes the summary and index and closes the file.
    pub fn finish(mut self) -> Result<u64, WriterError> {
        self.writer.finish()?;
        Ok(self.messages)
    }
}

//! One pass over the data section of an MCAP file that trusts nothing in it.
//!
//! Top-level records are framed by hand (opcode, length, body), each length
//! checked against the bytes that are really there; the records shoal
//! needs (header, schema, channel, message, metadata, chunk) are parsed by
//! hand with every string and map length checked the same way; a chunk is
//! decompressed by `mcap`'s sans-io reader fed only that chunk's bytes, with
//! a record-length limit derived from the chunk's compressed size, and
//! counts only if every record in it decodes (and its CRC matches). So a
//! corrupted length field can neither index out of bounds nor allocate more
//! than a small multiple of the file's size, and every loop advances.
//!
//! The pass stops at the end of the data section (`DataEnd` or `Footer`),
//! at the first record that is cut short or does not decode, or at the end
//! of the bytes; [`ScanEnd`] says where the last complete record ended.

use std::collections::BTreeMap;

use mcap::sans_io::{LinearReadEvent, LinearReader, LinearReaderOptions};

/// MCAP opcodes this module reads.
mod op {
    pub const HEADER: u8 = 0x01;
    pub const FOOTER: u8 = 0x02;
    pub const SCHEMA: u8 = 0x03;
    pub const CHANNEL: u8 = 0x04;
    pub const MESSAGE: u8 = 0x05;
    pub const CHUNK: u8 = 0x06;
    pub const METADATA: u8 = 0x0C;
    pub const DATA_END: u8 = 0x0F;
}

/// Most bytes one chunk may decompress to, as a multiple of its compressed
/// size (plus [`CHUNK_SLACK`]). shoal's samples compress about 5-20×;
/// beyond this a chunk is treated as corrupt rather than allocated.
const CHUNK_RATIO: usize = 256;
/// Extra bytes a chunk may decompress to beyond [`CHUNK_RATIO`] × compressed.
const CHUNK_SLACK: usize = 1 << 20;

/// A schema record.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct Schema {
    pub id: u16,
    pub name: String,
    pub encoding: String,
    pub data: Vec<u8>,
}

/// A channel record.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct Channel {
    pub id: u16,
    pub schema_id: u16,
    pub topic: String,
    pub message_encoding: String,
    pub metadata: BTreeMap<String, String>,
}

/// A message record.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct Message {
    pub channel_id: u16,
    pub sequence: u32,
    pub log_time: u64,
    pub publish_time: u64,
    pub data: Vec<u8>,
}

/// A record the readers act on.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) enum Item {
    /// The file header's profile.
    Header {
        profile: String,
    },
    Schema(Schema),
    Channel(Channel),
    Message(Message),
    Metadata {
        name: String,
        values: BTreeMap<String, String>,
    },
}

/// How the pass ended.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct ScanEnd {
    /// Byte offset just past the last complete record read (at least 8,
    /// the magic, if the magic was there).
    pub good_end: usize,
    /// The data section ended properly (`DataEnd` or `Footer` reached).
    pub data_end: bool,
    /// Why the pass stopped early, if it did.
    pub error: Option<String>,
    /// Chunk compression seen first (`""` for none).
    pub compression: Option<String>,
    /// Complete chunks read.
    pub chunks: u64,
}

/// A bounds-checked cursor over one record body.
struct Body<'a> {
    b: &'a [u8],
}

impl<'a> Body<'a> {
    fn take(&mut self, n: usize) -> Result<&'a [u8], String> {
        if n > self.b.len() {
            return Err(format!("field of {n} bytes overruns its record"));
        }
        let (head, rest) = self.b.split_at(n);
        self.b = rest;
        Ok(head)
    }
    fn u16(&mut self) -> Result<u16, String> {
        let s = self.take(2)?;
        Ok(u16::from_le_bytes([s[0], s[1]]))
    }
    fn u32(&mut self) -> Result<u32, String> {
        let s = self.take(4)?;
        Ok(u32::from_le_bytes([s[0], s[1], s[2], s[3]]))
    }
    fn u64(&mut self) -> Result<u64, String> {
        let s = self.take(8)?;
        let mut a = [0u8; 8];
        a.copy_from_slice(s);
        Ok(u64::from_le_bytes(a))
    }
    fn bytes32(&mut self) -> Result<&'a [u8], String> {
        let n = self.u32()? as usize;
        self.take(n)
    }
    fn string(&mut self) -> Result<String, String> {
        let b = self.bytes32()?;
        String::from_utf8(b.to_vec()).map_err(|_| "string is not UTF-8".to_string())
    }
    fn string_map(&mut self) -> Result<BTreeMap<String, String>, String> {
        let mut map = Body { b: self.bytes32()? };
        let mut out = BTreeMap::new();
        while !map.b.is_empty() {
            let k = map.string()?;
            let v = map.string()?;
            out.insert(k, v);
        }
        Ok(out)
    }
}

/// Parses one record (outside or inside a chunk). `Ok(None)` for records
/// the readers skip (indexes, statistics, attachments, unknown opcodes).
fn parse(opcode: u8, body: &[u8]) -> Result<Option<Item>, String> {
    let mut b = Body { b: body };
    Ok(Some(match opcode {
        op::HEADER => Item::Header {
            profile: b.string()?,
        },
        op::SCHEMA => Item::Schema(Schema {
            id: b.u16()?,
            name: b.string()?,
            encoding: b.string()?,
            data: b.bytes32()?.to_vec(),
        }),
        op::CHANNEL => Item::Channel(Channel {
            id: b.u16()?,
            schema_id: b.u16()?,
            topic: b.string()?,
            message_encoding: b.string()?,
            metadata: b.string_map()?,
        }),
        op::MESSAGE => Item::Message(Message {
            channel_id: b.u16()?,
            sequence: b.u32()?,
            log_time: b.u64()?,
            publish_time: b.u64()?,
            data: b.b.to_vec(),
        }),
        op::METADATA => Item::Metadata {
            name: b.string()?,
            values: b.string_map()?,
        },
        _ => return Ok(None),
    }))
}

/// Decodes every record of one chunk record (`whole` = opcode, length and
/// body, exactly as in the file). All or nothing.
fn read_chunk(whole: &[u8], body: &[u8]) -> Result<(Vec<Item>, String), String> {
    // The chunk header, to bound what it may decompress to.
    let mut b = Body { b: body };
    let _start = b.u64()?;
    let _end = b.u64()?;
    let uncompressed = b.u64()?;
    let _crc = b.u32()?;
    let compression = b.string()?;
    let compressed = b.u64()?;
    if compressed > b.b.len() as u64 {
        return Err(format!(
            "chunk claims {compressed} compressed bytes, {} are there",
            b.b.len()
        ));
    }
    let bound = (compressed as usize)
        .saturating_mul(CHUNK_RATIO)
        .saturating_add(CHUNK_SLACK);
    if uncompressed > bound as u64 {
        return Err(format!(
            "chunk claims {uncompressed} bytes uncompressed from {compressed}: corrupt"
        ));
    }
    let mut reader = LinearReader::new_with_options(
        LinearReaderOptions::default()
            .with_skip_start_magic(true)
            .with_skip_end_magic(true)
            .with_validate_chunk_crcs(true)
            .with_record_length_limit((uncompressed as usize).max(whole.len())),
    );
    let mut input = whole;
    let mut items = Vec::new();
    let mut total = 0usize;
    let mut starved = false;
    while let Some(event) = reader.next_event() {
        match event.map_err(|e| format!("chunk: {e}"))? {
            LinearReadEvent::ReadRequest(need) => {
                let n = need.min(input.len());
                if n == 0 {
                    // The reader was told the input ended; asking again means it is stuck.
                    if starved {
                        return Err("chunk ends inside a record".into());
                    }
                    starved = true;
                }
                reader.insert(n).copy_from_slice(&input[..n]);
                reader.notify_read(n);
                input = &input[n..];
            }
            LinearReadEvent::Record { opcode, data } => {
                total = total.saturating_add(data.len() + 9);
                if total > bound {
                    return Err("chunk decompresses beyond its bound: corrupt".into());
                }
                if opcode == op::CHUNK {
                    return Err("a chunk inside a chunk".into());
                }
                if let Some(item) = parse(opcode, data).map_err(|e| format!("chunk: {e}"))? {
                    items.push(item);
                }
            }
        }
    }
    Ok((items, compression))
}

/// Reads `bytes` from the start, handing every record of the data section
/// to `visit` in file order; a chunk's records are handed over only once
/// the whole chunk has decoded.
pub(crate) fn scan(bytes: &[u8], mut visit: impl FnMut(Item)) -> ScanEnd {
    let mut end = ScanEnd {
        good_end: 0,
        data_end: false,
        error: None,
        compression: None,
        chunks: 0,
    };
    if bytes.len() < mcap::MAGIC.len() || &bytes[..mcap::MAGIC.len()] != mcap::MAGIC {
        end.error = Some("no MCAP magic at the start".into());
        return end;
    }
    let mut pos = mcap::MAGIC.len();
    end.good_end = pos;
    while pos < bytes.len() {
        let rest = &bytes[pos..];
        if rest.len() < 9 {
            end.error = Some(format!("record header cut short at byte {pos}"));
            break;
        }
        let opcode = rest[0];
        let mut len8 = [0u8; 8];
        len8.copy_from_slice(&rest[1..9]);
        let len = u64::from_le_bytes(len8);
        if len > (rest.len() - 9) as u64 {
            end.error = Some(format!(
                "record 0x{opcode:02x} at byte {pos} claims {len} bytes, {} remain",
                rest.len() - 9
            ));
            break;
        }
        let len = len as usize;
        let whole = &rest[..9 + len];
        let body = &rest[9..9 + len];
        if opcode == op::CHUNK {
            match read_chunk(whole, body) {
                Ok((items, compression)) => {
                    end.compression.get_or_insert(compression);
                    end.chunks += 1;
                    items.into_iter().for_each(&mut visit);
                }
                Err(e) => {
                    end.error = Some(format!("chunk at byte {pos}: {e}"));
                    break;
                }
            }
        } else {
            match parse(opcode, body) {
                Ok(Some(item)) => visit(item),
                Ok(None) => {}
                Err(e) => {
                    end.error = Some(format!("record 0x{opcode:02x} at byte {pos}: {e}"));
                    break;
                }
            }
        }
        pos += 9 + len;
        end.good_end = pos;
        if opcode == op::DATA_END || opcode == op::FOOTER {
            end.data_end = true;
            break;
        }
    }
    end
}

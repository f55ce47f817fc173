//! shoal's recordings: every sample written to MCAP so that the official
//! readers decode it with no shoal code, and read back for `shoal inspect`,
//! metrics, replay and determinism checks.
//!
//! **Encoding.** Each message is the 4-byte CDR little-endian encapsulation
//! header `00 01 00 00` followed by the sample's raw `#[repr(C)]` bytes; the
//! channel's schema is ros2msg text generated from the type
//! ([`ipc_types::schema::ros2msg_schema`]), so `mcap` + `mcap-ros2-support`
//! decode it. Log time and publish time are the sample's simulation time
//! (ns); wall-clock stamps stay inside the payload header.
//!
//! ```no_run
//! use recordings::{RecordingWriter, WriterOptions, Recording};
//! let mut w = RecordingWriter::create("/tmp/r.mcap".as_ref(), &WriterOptions::default()).unwrap();
//! let ch = w.add_channel::<ipc_types::Nav>("/L/nav").unwrap();
//! w.write(ch, &<ipc_types::Nav as ipc_types::Sample>::zeroed()).unwrap();
//! w.finish().unwrap();
//! let rec = Recording::open("/tmp/r.mcap".as_ref()).unwrap();
//! assert_eq!(rec.channels()[0].topic, "/L/nav");
//! ```

mod diff;
pub mod image;
mod reader;
mod recover;
mod registry;
pub mod rosbag2;
mod scan;
mod writer;

pub use diff::first_field_difference;
pub use reader::{ChannelStats, InspectReport, Recording, RecordingError, StoredMessage};
pub use recover::{join_hosts, merge, recover, RecoverError, RecoverReport};
pub use registry::{all_types, type_info_by_schema, TypeInfo};
pub use writer::{
    ChannelSchema, Compression, RecordingWriter, WriterError, WriterOptions, CDR_HEADER,
};

/// Decodes a stored message body (CDR header + raw bytes) into a sample.
pub fn decode<T: ipc_types::Sample>(data: &[u8]) -> Option<T> {
    let body = data.strip_prefix(&CDR_HEADER)?;
    if body.len() != std::mem::size_of::<T>() {
        return None;
    }
    Some(bytemuck::pod_read_unaligned(body))
}

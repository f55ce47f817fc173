//! What the recording knows about each sample type, by schema name.

use std::ops::Range;

use ipc_types::schema::{ros2msg_schema, wall_clock_ranges, SchemaError};
use ipc_types::Sample;

/// Facts about one sample type.
#[derive(Clone, Copy)]
pub struct TypeInfo {
    /// iceoryx2 type name, e.g. `shoal.Nav.v1`.
    pub type_name: &'static str,
    /// ros2msg / MCAP schema name, e.g. `shoal_msgs/msg/Nav`.
    pub schema_name: &'static str,
    /// Size of the raw sample, bytes.
    pub size: usize,
    /// The ros2msg schema text.
    pub schema: fn() -> Result<String, SchemaError>,
    /// Byte ranges of wall-clock fields.
    pub wall_clock: fn() -> Vec<Range<usize>>,
}

impl std::fmt::Debug for TypeInfo {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TypeInfo")
            .field("type_name", &self.type_name)
            .field("schema_name", &self.schema_name)
            .field("size", &self.size)
            .finish()
    }
}

/// The facts of `T`.
pub fn type_info<T: Sample>() -> TypeInfo {
    TypeInfo {
        type_name: T::TYPE_NAME,
        schema_name: <T as ipc_types::Described>::ROS_NAME,
        size: std::mem::size_of::<T>(),
        schema: ros2msg_schema::<T>,
        wall_clock: wall_clock_ranges::<T>,
    }
}

/// Every sample type shoal records ([`ipc_types::SAMPLE_SCHEMAS`] order).
pub fn all_types() -> Vec<TypeInfo> {
    let mut all = Vec::with_capacity(ipc_types::SAMPLE_SCHEMAS.len());
    ipc_types::for_each_sample_type!(T => all.push(type_info::<T>()));
    all
}

/// Looks a type up by its schema name.
pub fn type_info_by_schema(name: &str) -> Option<TypeInfo> {
    let name = ipc_types::schema::canonical_schema_name(name);
    all_types().into_iter().find(|t| t.schema_name == name)
}

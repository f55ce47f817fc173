//! Self-description of sample types, so that the recorder can write a ros2msg
//! schema generated from the `#[repr(C)]` type itself, never by hand.
//!
//! A `#[repr(C)]`, `Pod` struct whose every pad byte is an explicit field has
//! the same byte layout as its XCDR1 little-endian encoding: each primitive is
//! aligned to its own size in both, fixed-size arrays carry no length prefix,
//! and there is no implicit padding. So a sample is written to MCAP as the
//! 4-byte CDR header `00 01 00 00` followed by its raw bytes, with the schema
//! generated here listing the same fields in the same order.

use std::fmt::Write as _;

/// How one field's type is described in ros2msg.
#[derive(Debug, Clone)]
pub enum TypeDesc {
    /// A primitive (`float64`, `uint8`, ...) with its size in bytes.
    Primitive {
        /// ros2msg name of the primitive.
        ros: &'static str,
        /// Size (and CDR alignment) in bytes.
        size: usize,
    },
    /// A nested message type.
    Nested {
        /// ROS 2 resource name, `shoal_msgs/msg/Name`.
        ros: &'static str,
        /// The nested type's fields.
        fields: fn() -> Vec<FieldDesc>,
    },
    /// A fixed-size array (ros2msg `T[N]`).
    Array {
        /// Element type (never itself an array: ros2msg has no nested arrays).
        elem: Box<TypeDesc>,
        /// Number of elements.
        len: usize,
    },
}

/// One field of a described struct.
#[derive(Debug, Clone)]
pub struct FieldDesc {
    /// The ros2msg field name (a Rust `_pad0` becomes `pad0`).
    pub name: String,
    /// The field's type.
    pub ty: TypeDesc,
}

/// A type that can describe itself as a ros2msg field type.
pub trait FieldType {
    /// The description of this type.
    fn describe() -> TypeDesc;
}

/// A struct that describes its fields (every sample type and nested type).
pub trait Described {
    /// ROS 2 resource name, `shoal_msgs/msg/Name` (the MCAP schema name; fields and
    /// the `MSG:` headers name it `shoal_msgs/Name`, as rosbag2 does).
    const ROS_NAME: &'static str;
    /// True for a type that measures the machine rather than the simulation
    /// (the runtime statistics): every field after the first (the header)
    /// counts as wall-clock.
    const MEASURED: bool = false;
    /// The fields in declaration order.
    fn fields() -> Vec<FieldDesc>;
}

macro_rules! primitive {
    ($($t:ty => $ros:literal),* $(,)?) => {
        $(impl FieldType for $t {
            fn describe() -> TypeDesc {
                TypeDesc::Primitive { ros: $ros, size: std::mem::size_of::<$t>() }
            }
        })*
    };
}
primitive!(f64 => "float64", f32 => "float32", u64 => "uint64", i64 => "int64",
    u32 => "uint32", i32 => "int32", u16 => "uint16", i16 => "int16", u8 => "uint8", i8 => "int8");

impl<T: FieldType, const N: usize> FieldType for [T; N] {
    fn describe() -> TypeDesc {
        TypeDesc::Array {
            elem: Box::new(T::describe()),
            len: N,
        }
    }
}

/// The ros2msg field name for a Rust field name: leading underscores dropped.
pub fn ros_field_name(rust: &str) -> String {
    rust.trim_start_matches('_').to_string()
}

/// Why a generated schema is not valid ros2msg.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum SchemaError {
    /// A field name does not match `[a-z][a-z0-9_]*`, or has `__` or a trailing `_`.
    #[error("field `{field}` of `{ty}` is not a valid ros2msg name")]
    BadFieldName {
        /// The type holding the field.
        ty: String,
        /// The offending name.
        field: String,
    },
    /// ros2msg has no arrays of arrays.
    #[error("field `{field}` of `{ty}` is an array of arrays")]
    NestedArray {
        /// The type holding the field.
        ty: String,
        /// The offending field.
        field: String,
    },
}

fn valid_field_name(name: &str) -> bool {
    let mut chars = name.chars();
    matches!(chars.next(), Some('a'..='z'))
        && name
            .chars()
            .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_')
        && !name.contains("__")
        && !name.ends_with('_')
}

/// A schema name as shoal writes it now: `shoal/Nav`, the name recordings
/// used before the ROS 2 package form, is `shoal_msgs/msg/Nav`.
pub fn canonical_schema_name(name: &str) -> std::borrow::Cow<'_, str> {
    match name.strip_prefix("shoal/") {
        Some(rest) if !rest.contains('/') => format!("shoal_msgs/msg/{rest}").into(),
        _ => name.into(),
    }
}

/// How a field names a nested type: `pkg/Type`, the `.msg` field form of
/// the resource name `pkg/msg/Type` (ROS 2 writes the `msg/` only in the
/// `MSG:` headers and the schema name).
pub fn field_type_name(resource: &str) -> String {
    resource.replacen("/msg/", "/", 1)
}

fn type_line(ty: &TypeDesc) -> String {
    match ty {
        TypeDesc::Primitive { ros, .. } => (*ros).to_string(),
        TypeDesc::Nested { ros, .. } => field_type_name(ros),
        TypeDesc::Array { elem, len } => format!("{}[{len}]", type_line(elem)),
    }
}

fn collect_nested(
    owner: &str,
    fields: &[FieldDesc],
    out: &mut Vec<(&'static str, Vec<FieldDesc>)>,
) -> Result<(), SchemaError> {
    for f in fields {
        if !valid_field_name(&f.name) {
            return Err(SchemaError::BadFieldName {
                ty: owner.to_string(),
                field: f.name.clone(),
            });
        }
        let inner = match &f.ty {
            TypeDesc::Array { elem, .. } => {
                if matches!(**elem, TypeDesc::Array { .. }) {
                    return Err(SchemaError::NestedArray {
                        ty: owner.to_string(),
                        field: f.name.clone(),
                    });
                }
                elem.as_ref()
            }
            other => other,
        };
        if let TypeDesc::Nested { ros, fields } = inner {
            if !out.iter().any(|(n, _)| n == ros) {
                let nested = fields();
                out.push((ros, nested.clone()));
                collect_nested(ros, &nested, out)?;
            }
        }
    }
    Ok(())
}

/// The ros2msg schema text of `T`: its fields, then one `MSG:` section per
/// nested type, headed `MSG: pkg/Type` as rosbag2 writes it (Rerun's MCAP importer
/// resolves nested types only by that name; the official MCAP ROS 2 readers and
/// rosbags accept it too).
pub fn ros2msg_schema<T: Described>() -> Result<String, SchemaError> {
    let fields = T::fields();
    let mut nested = Vec::new();
    collect_nested(T::ROS_NAME, &fields, &mut nested)?;
    let mut text = String::new();
    for f in &fields {
        let _ = writeln!(text, "{} {}", type_line(&f.ty), f.name);
    }
    for (name, fields) in nested {
        text.push_str(
            "================================================================================\n",
        );
        let _ = writeln!(text, "MSG: {}", field_type_name(name));
        for f in &fields {
            let _ = writeln!(text, "{} {}", type_line(&f.ty), f.name);
        }
    }
    Ok(text)
}

/// The size in bytes the described layout occupies when packed in CDR with
/// natural alignment, starting at an 8-aligned offset. Tests compare this with
/// `size_of::<T>()` to prove that no implicit padding exists.
pub fn cdr_size<T: Described>() -> usize {
    fn walk(fields: &[FieldDesc], mut off: usize) -> usize {
        for f in fields {
            off = walk_ty(&f.ty, off);
        }
        off
    }
    fn walk_ty(ty: &TypeDesc, off: usize) -> usize {
        match ty {
            TypeDesc::Primitive { size, .. } => off.next_multiple_of(*size) + size,
            TypeDesc::Nested { fields, .. } => walk(&fields(), off),
            TypeDesc::Array { elem, len } => (0..*len).fold(off, |o, _| walk_ty(elem, o)),
        }
    }
    walk(&T::fields(), 0)
}

/// True for a field that holds a wall-clock reading or a duration measured on
/// the machine: a name ending in `_ns` that is not simulated time
/// (`sim_time_ns`, `origin_sim_time_ns`, `tick_ns`). Publish and origin
/// stamps, the MPC's solve time and the runtime statistics' percentiles all
/// follow this naming; everything else is a function of the simulation.
pub fn is_wall_clock_field(name: &str) -> bool {
    name.ends_with("_ns") && !name.ends_with("sim_time_ns") && name != "tick_ns"
}

/// Byte ranges of the fields of `T` that hold wall-clock readings (see
/// [`is_wall_clock_field`], and everything after the header of a
/// [`Described::MEASURED`] type): the only bytes allowed to differ between
/// two lockstep runs of the same scenario and seed.
pub fn wall_clock_ranges<T: Described>() -> Vec<std::ops::Range<usize>> {
    fn walk(
        fields: &[FieldDesc],
        off: &mut usize,
        wall: bool,
        out: &mut Vec<std::ops::Range<usize>>,
    ) {
        for f in fields {
            walk_ty(&f.ty, off, wall || is_wall_clock_field(&f.name), out);
        }
    }
    fn walk_ty(ty: &TypeDesc, off: &mut usize, wall: bool, out: &mut Vec<std::ops::Range<usize>>) {
        match ty {
            TypeDesc::Primitive { size, .. } => {
                *off = off.next_multiple_of(*size);
                if wall {
                    out.push(*off..*off + size);
                }
                *off += size;
            }
            TypeDesc::Nested { fields, .. } => walk(&fields(), off, wall, out),
            TypeDesc::Array { elem, len } => {
                for _ in 0..*len {
                    walk_ty(elem, off, wall, out);
                }
            }
        }
    }
    let mut out = Vec::new();
    let mut off = 0;
    let fields = T::fields();
    let (first, rest) = fields.split_at(1.min(fields.len()));
    walk(first, &mut off, false, &mut out);
    walk(rest, &mut off, T::MEASURED, &mut out);
    out
}

/// True when every `float64` / `float32` of `value` is finite, found by
/// walking `T`'s description over its bytes. This is the reference the
/// generated [`crate::Finite`] check is tested against; it allocates the
/// field lists on every call and is far too slow for a hot path (use
/// [`crate::Sample::is_finite`] there).
pub fn finite_by_schema<T: Described + bytemuck::Pod>(value: &T) -> bool {
    fn walk(bytes: &[u8], ty: &TypeDesc, off: &mut usize) -> bool {
        match ty {
            TypeDesc::Primitive { ros, size } => {
                *off = off.next_multiple_of(*size);
                let Some(b) = bytes.get(*off..*off + size) else {
                    return false;
                };
                *off += size;
                match *ros {
                    "float64" => b
                        .try_into()
                        .map(|a: [u8; 8]| f64::from_ne_bytes(a).is_finite())
                        .unwrap_or(false),
                    "float32" => b
                        .try_into()
                        .map(|a: [u8; 4]| f32::from_ne_bytes(a).is_finite())
                        .unwrap_or(false),
                    _ => true,
                }
            }
            // No short-circuit: the offset must advance over every field.
            TypeDesc::Nested { fields, .. } => fields()
                .iter()
                .fold(true, |ok, f| walk(bytes, &f.ty, off) & ok),
            TypeDesc::Array { elem, len } => {
                (0..*len).fold(true, |ok, _| walk(bytes, elem, off) & ok)
            }
        }
    }
    let bytes = bytemuck::bytes_of(value);
    let mut off = 0;
    T::fields()
        .iter()
        .fold(true, |ok, f| walk(bytes, &f.ty, &mut off) & ok)
}

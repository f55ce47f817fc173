//! The field-by-field difference of two samples of one recorded type, as
//! `shoal replay --rerun` reports it.

use ipc_types::schema::{FieldDesc, TypeDesc};

/// The fields of a recorded schema.
fn fields_of(schema: &str) -> Option<Vec<FieldDesc>> {
    ipc_types::with_sample_type!(schema, T => Some(<T as ipc_types::Described>::fields()), else None)
}

/// The first field (in declaration order) whose bytes differ between `a`
/// and `b`, skipping wall-clock fields: `(path, value in a, value in b)`.
pub fn first_field_difference(
    schema: &str,
    a: &[u8],
    b: &[u8],
) -> Option<(String, String, String)> {
    if a.len() != b.len() {
        return Some(("(size)".into(), a.len().to_string(), b.len().to_string()));
    }
    let Some(fields) = fields_of(schema) else {
        return (a != b).then(|| ("(bytes)".into(), "…".into(), "…".into()));
    };
    fn value(ros: &str, b: &[u8]) -> String {
        let arr8 = |b: &[u8]| <[u8; 8]>::try_from(b).unwrap_or_default();
        let arr4 = |b: &[u8]| <[u8; 4]>::try_from(b).unwrap_or_default();
        match ros {
            "float64" => format!("{:?}", f64::from_ne_bytes(arr8(b))),
            "float32" => format!("{:?}", f32::from_ne_bytes(arr4(b))),
            "uint64" => u64::from_ne_bytes(arr8(b)).to_string(),
            "int64" => i64::from_ne_bytes(arr8(b)).to_string(),
            "uint32" => u32::from_ne_bytes(arr4(b)).to_string(),
            "int32" => i32::from_ne_bytes(arr4(b)).to_string(),
            _ => format!("{b:02x?}"),
        }
    }
    struct Walk<'a> {
        a: &'a [u8],
        b: &'a [u8],
        off: usize,
    }
    fn walk_ty(
        w: &mut Walk,
        ty: &TypeDesc,
        path: String,
        wall: bool,
    ) -> Option<(String, String, String)> {
        match ty {
            TypeDesc::Primitive { ros, size } => {
                w.off = w.off.next_multiple_of(*size);
                let r = w.off..w.off + size;
                w.off += size;
                let (x, y) = (w.a.get(r.clone())?, w.b.get(r)?);
                (!wall && x != y).then(|| (path, value(ros, x), value(ros, y)))
            }
            TypeDesc::Nested { fields, .. } => walk(w, &fields(), &path, wall),
            TypeDesc::Array { elem, len } => {
                (0..*len).find_map(|i| walk_ty(w, elem, format!("{path}[{i}]"), wall))
            }
        }
    }
    fn walk(
        w: &mut Walk,
        fields: &[FieldDesc],
        prefix: &str,
        wall: bool,
    ) -> Option<(String, String, String)> {
        for f in fields {
            let path = if prefix.is_empty() {
                f.name.to_string()
            } else {
                format!("{prefix}.{}", f.name)
            };
            let is_wall = wall || ipc_types::schema::is_wall_clock_field(&f.name);
            if let Some(d) = walk_ty(w, &f.ty, path, is_wall) {
                return Some(d);
            }
        }
        None
    }
    walk(&mut Walk { a, b, off: 0 }, &fields, "", false)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use ipc_types::{Sample, Truth};

    #[test]
    fn the_first_differing_field_is_named_and_wall_clock_fields_are_ignored() {
        let mut a = Truth::zeroed();
        a.position_ned_m = [1.0, 2.0, 3.0];
        a.velocity_body_mps = [0.5, 0.0, 0.0];
        let mut b = a;
        b.header.publish_mono_ns = 99;
        b.thrust_applied_mono_ns = 7;
        assert_eq!(
            first_field_difference(
                "shoal_msgs/msg/Truth",
                bytemuck::bytes_of(&a),
                bytemuck::bytes_of(&b)
            ),
            None
        );
        b.position_ned_m[1] = 2.5;
        b.velocity_body_mps[0] = 0.6;
        let d = first_field_difference(
            "shoal_msgs/msg/Truth",
            bytemuck::bytes_of(&a),
            bytemuck::bytes_of(&b),
        )
        .unwrap();
        assert_eq!(
            d,
            (
                "position_ned_m[1]".to_string(),
                "2.0".to_string(),
                "2.5".to_string()
            )
        );
    }
}

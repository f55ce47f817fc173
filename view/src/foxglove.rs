//! The Foxglove message types `shoal export` writes: Foxglove's own types
//! from the `foxglove` crate (generated from Foxglove's `.proto` schemas,
//! protobuf-encoded, each with its `FileDescriptorSet` as the MCAP schema),
//! and the few helpers the view needs to build them.
//!
//! Protobuf rather than JSON: Foxglove shows both, but Rerun's MCAP importer
//! (and every protobuf reader) decodes only the protobuf form, and it is a
//! third of the size. Times are `Timestamp {sec, nsec}` since the
//! recording's sim-time origin (or the Unix epoch with `--epoch`).

pub use ::foxglove::messages::line_primitive::Type as LineType;
pub use ::foxglove::messages::{
    ArrowPrimitive, Color, CubePrimitive, CylinderPrimitive, FrameTransform, FrameTransforms,
    KeyValuePair, LinePrimitive, Point3, Pose, PoseInFrame, Quaternion, SceneEntity, SceneUpdate,
    SpherePrimitive, TextPrimitive, Timestamp as Time, TriangleListPrimitive, Vector3,
};
pub use ::foxglove::Encode as FoxgloveMessage;

/// A time stamp from nanoseconds. Sim times beyond `u32::MAX` seconds
/// (136 years) saturate.
pub fn time_from_ns(ns: u64) -> Time {
    let sec = u32::try_from(ns / 1_000_000_000).unwrap_or(u32::MAX);
    Time::new(sec, (ns % 1_000_000_000) as u32)
}

/// `foxglove.Vector3` from an array (sizes, translations).
pub fn vector(v: [f64; 3]) -> Vector3 {
    Vector3 {
        x: v[0],
        y: v[1],
        z: v[2],
    }
}

/// `foxglove.Point3` from an array (points of lines and triangles).
pub fn point(v: [f64; 3]) -> Point3 {
    Point3 {
        x: v[0],
        y: v[1],
        z: v[2],
    }
}

/// A pose at `p` with orientation `q`.
pub fn pose(p: [f64; 3], q: Quaternion) -> Option<Pose> {
    Some(Pose {
        position: Some(vector(p)),
        orientation: Some(q),
    })
}

/// A pose at `p` with no rotation.
pub fn pose_at(p: [f64; 3]) -> Option<Pose> {
    pose(p, IDENTITY)
}

/// The identity rotation, `{x, y, z, w}`.
pub const IDENTITY: Quaternion = Quaternion {
    x: 0.0,
    y: 0.0,
    z: 0.0,
    w: 1.0,
};

/// `foxglove.Color` from components in `[0, 1]`.
pub const fn rgba(r: f64, g: f64, b: f64, a: f64) -> Color {
    Color { r, g, b, a }
}

/// An empty entity in `frame_id` that lives until replaced.
pub fn entity(timestamp: Time, frame_id: &str, id: String, frame_locked: bool) -> SceneEntity {
    SceneEntity {
        timestamp: Some(timestamp),
        frame_id: frame_id.to_string(),
        id,
        lifetime: Some(::foxglove::messages::Duration::new(0, 0)),
        frame_locked,
        ..SceneEntity::default()
    }
}

/// Adds a key/value pair to an entity's metadata (shown when it is selected).
pub fn meta(e: &mut SceneEntity, key: &str, value: impl ToString) {
    e.metadata.push(KeyValuePair {
        key: key.to_string(),
        value: value.to_string(),
    });
}

/// A line of `points` joined as `kind`, in the entity's frame.
pub fn line(
    kind: LineType,
    thickness: f64,
    points: Vec<Point3>,
    color: Color,
    colors: Vec<Color>,
) -> LinePrimitive {
    LinePrimitive {
        r#type: kind as i32,
        pose: pose_at([0.0; 3]),
        thickness,
        scale_invariant: false,
        points,
        color: Some(color),
        colors,
        indices: Vec::new(),
    }
}

/// A sphere (an ellipsoid in general) of diameters `size` at `p`.
pub fn sphere(p: [f64; 3], size: [f64; 3], color: Color) -> SpherePrimitive {
    SpherePrimitive {
        pose: pose_at(p),
        size: Some(vector(size)),
        color: Some(color),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn time_splits_nanoseconds() {
        assert_eq!(time_from_ns(12_345_678_901), Time::new(12, 345_678_901));
        assert_eq!(time_from_ns(0), Time::new(0, 0));
        assert_eq!(time_from_ns(u64::MAX).sec(), u32::MAX);
    }

    #[test]
    fn messages_carry_foxglove_protobuf_schemas() {
        for (schema, name) in [
            (SceneUpdate::get_schema(), "foxglove.SceneUpdate"),
            (FrameTransforms::get_schema(), "foxglove.FrameTransforms"),
            (PoseInFrame::get_schema(), "foxglove.PoseInFrame"),
        ] {
            let schema = schema.unwrap();
            assert_eq!(schema.name, name);
            assert_eq!(schema.encoding, "protobuf");
            assert!(!schema.data.is_empty());
        }
        assert_eq!(SceneUpdate::get_message_encoding(), "protobuf");
    }

    #[test]
    fn enums_are_their_schema_numbers() {
        assert_eq!(LineType::LineList as i32, 2);
        assert_eq!(LineType::LineStrip as i32, 0);
    }

    #[test]
    fn an_entity_lives_until_replaced() {
        let mut e = entity(time_from_ns(5), "ned", "x".into(), true);
        meta(&mut e, "k", 1);
        assert_eq!(
            e.lifetime.unwrap(),
            ::foxglove::messages::Duration::new(0, 0)
        );
        assert_eq!(e.metadata[0].value, "1");
        let mut buf = Vec::new();
        SceneUpdate {
            deletions: Vec::new(),
            entities: vec![e.clone()],
        }
        .encode(&mut buf)
        .unwrap();
        let back = <SceneUpdate as ::foxglove::Decode>::decode(buf.as_slice()).unwrap();
        assert_eq!(back.entities[0], e);
    }
}

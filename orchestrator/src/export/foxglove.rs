//! The Foxglove message types `shoal export` writes, as serde structs whose
//! JSON is the Foxglove JSON encoding, and the official JSON schemas they are
//! checked against.
//!
//! The schema texts in `schemas/` are the official Foxglove JSON schemas,
//! copied unchanged from the npm package `@foxglove/schemas` 2.1.0 (MIT,
//! © Foxglove; `dist/jsonschema`, written with `JSON.stringify(s, null, 2)`).
//! Every field those schemas list is required, so every struct here writes
//! every field, empty arrays included. Times are `{sec, nsec}` objects.

use serde::Serialize;

/// A Foxglove message type this exporter writes: its schema name and the
/// official JSON schema text.
pub trait FoxgloveMessage: Serialize {
    /// Schema name, e.g. `foxglove.SceneUpdate`.
    const SCHEMA_NAME: &'static str;
    /// The official JSON schema (schema encoding `jsonschema`).
    const SCHEMA_JSON: &'static str;
}

/// A time stamp, `{sec, nsec}` since the recording's sim-time origin.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct Time {
    /// Whole seconds.
    pub sec: u32,
    /// Nanoseconds, `0..1e9`.
    pub nsec: u32,
}

impl Time {
    /// From nanoseconds. Sim times beyond `u32::MAX` seconds (136 years) saturate.
    pub fn from_ns(ns: u64) -> Self {
        let sec = u32::try_from(ns / 1_000_000_000).unwrap_or(u32::MAX);
        Self {
            sec,
            nsec: (ns % 1_000_000_000) as u32,
        }
    }
}

/// A duration, `{sec, nsec}`; zero means "forever" for an entity's lifetime.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct Duration {
    /// Whole seconds.
    pub sec: i32,
    /// Nanoseconds, `0..1e9`.
    pub nsec: u32,
}

impl Duration {
    /// The zero duration (an entity that lives until replaced or deleted).
    pub const FOREVER: Duration = Duration { sec: 0, nsec: 0 };
}

/// `foxglove.Vector3`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Vector3 {
    /// x.
    pub x: f64,
    /// y.
    pub y: f64,
    /// z.
    pub z: f64,
}

impl Vector3 {
    /// From an array.
    pub fn from_array(v: [f64; 3]) -> Self {
        Self {
            x: v[0],
            y: v[1],
            z: v[2],
        }
    }
}

/// `foxglove.Point3`.
pub type Point3 = Vector3;

/// `foxglove.Quaternion` (note the order: x, y, z, w).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Quaternion {
    /// x.
    pub x: f64,
    /// y.
    pub y: f64,
    /// z.
    pub z: f64,
    /// w.
    pub w: f64,
}

impl Quaternion {
    /// The identity rotation.
    pub const IDENTITY: Quaternion = Quaternion {
        x: 0.0,
        y: 0.0,
        z: 0.0,
        w: 1.0,
    };
}

/// `foxglove.Pose`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Pose {
    /// Position.
    pub position: Vector3,
    /// Orientation.
    pub orientation: Quaternion,
}

impl Pose {
    /// A pose at `p` with no rotation.
    pub fn at(p: [f64; 3]) -> Self {
        Self {
            position: Vector3::from_array(p),
            orientation: Quaternion::IDENTITY,
        }
    }

    /// The identity pose.
    pub fn identity() -> Self {
        Self::at([0.0; 3])
    }
}

/// `foxglove.Color`, components in `[0, 1]`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Color {
    /// Red.
    pub r: f64,
    /// Green.
    pub g: f64,
    /// Blue.
    pub b: f64,
    /// Alpha (1 = opaque).
    pub a: f64,
}

impl Color {
    /// From components.
    pub const fn rgba(r: f64, g: f64, b: f64, a: f64) -> Self {
        Self { r, g, b, a }
    }
}

/// `foxglove.KeyValuePair`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct KeyValuePair {
    /// Key.
    pub key: String,
    /// Value.
    pub value: String,
}

/// `foxglove.ArrowPrimitive`: points along +x of its pose.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ArrowPrimitive {
    /// Tail position and direction.
    pub pose: Pose,
    /// Shaft length, m.
    pub shaft_length: f64,
    /// Shaft diameter, m.
    pub shaft_diameter: f64,
    /// Head length, m.
    pub head_length: f64,
    /// Head diameter, m.
    pub head_diameter: f64,
    /// Colour.
    pub color: Color,
}

/// `foxglove.CubePrimitive`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CubePrimitive {
    /// Centre and orientation.
    pub pose: Pose,
    /// Full size along x, y, z, m.
    pub size: Vector3,
    /// Colour.
    pub color: Color,
}

/// `foxglove.SpherePrimitive` (an ellipsoid in general).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SpherePrimitive {
    /// Centre and orientation.
    pub pose: Pose,
    /// Diameters along x, y, z, m.
    pub size: Vector3,
    /// Colour.
    pub color: Color,
}

/// `foxglove.CylinderPrimitive`: axis along z of its pose.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CylinderPrimitive {
    /// Centre and orientation.
    pub pose: Pose,
    /// Diameters along x and y, height along z, m.
    pub size: Vector3,
    /// Scale of the bottom face (1 = full).
    pub bottom_scale: f64,
    /// Scale of the top face (1 = full).
    pub top_scale: f64,
    /// Colour.
    pub color: Color,
}

/// `foxglove.LineType`: how `points` are joined (every value of the schema,
/// whether or not the view uses it).
#[allow(dead_code)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LineType {
    /// Each point joined to the next.
    Strip = 0,
    /// A strip closed back to the first point.
    Loop = 1,
    /// Pairs of points, one segment each.
    List = 2,
}

impl Serialize for LineType {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_u8(*self as u8)
    }
}

/// `foxglove.LinePrimitive`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LinePrimitive {
    /// How the points are joined.
    #[serde(rename = "type")]
    pub kind: LineType,
    /// Origin of the points.
    pub pose: Pose,
    /// Width, m (or px when `scale_invariant`).
    pub thickness: f64,
    /// Width in pixels rather than metres.
    pub scale_invariant: bool,
    /// Points.
    pub points: Vec<Point3>,
    /// Colour of the whole line when `colors` is empty.
    pub color: Color,
    /// One colour per point, or empty.
    pub colors: Vec<Color>,
    /// Indices into `points`, or empty for all in order.
    pub indices: Vec<u32>,
}

/// `foxglove.TriangleListPrimitive`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TriangleListPrimitive {
    /// Origin of the points.
    pub pose: Pose,
    /// Vertices, three per triangle unless `indices` is given.
    pub points: Vec<Point3>,
    /// Colour of the whole list when `colors` is empty.
    pub color: Color,
    /// One colour per point, or empty.
    pub colors: Vec<Color>,
    /// Indices into `points`, or empty for all in order.
    pub indices: Vec<u32>,
}

/// `foxglove.TextPrimitive`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TextPrimitive {
    /// Where the text is.
    pub pose: Pose,
    /// Always face the camera.
    pub billboard: bool,
    /// Font size (px when `scale_invariant`, else m).
    pub font_size: f64,
    /// Size in pixels rather than metres.
    pub scale_invariant: bool,
    /// Colour.
    pub color: Color,
    /// The text.
    pub text: String,
}

/// `foxglove.ModelPrimitive` (never written; the type keeps `models` honest).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ModelPrimitive {
    /// Origin of the model.
    pub pose: Pose,
    /// Scale.
    pub scale: Vector3,
    /// Colour override.
    pub color: Color,
    /// Use `color` instead of the model's colours.
    pub override_color: bool,
    /// URL of the model.
    pub url: String,
    /// Media type of `data`.
    pub media_type: String,
    /// Embedded model, base64.
    pub data: String,
}

/// `foxglove.SceneEntity`: a group of primitives in one frame.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SceneEntity {
    /// When the entity is valid.
    pub timestamp: Time,
    /// Frame the primitives are expressed in.
    pub frame_id: String,
    /// Identifier; a later entity with the same id replaces this one.
    pub id: String,
    /// How long it is shown; zero = until replaced or deleted.
    pub lifetime: Duration,
    /// Follow the frame as it moves (true) or stay where the frame was at `timestamp`.
    pub frame_locked: bool,
    /// Key/value pairs shown when the entity is selected.
    pub metadata: Vec<KeyValuePair>,
    /// Arrows.
    pub arrows: Vec<ArrowPrimitive>,
    /// Boxes.
    pub cubes: Vec<CubePrimitive>,
    /// Spheres.
    pub spheres: Vec<SpherePrimitive>,
    /// Cylinders.
    pub cylinders: Vec<CylinderPrimitive>,
    /// Lines.
    pub lines: Vec<LinePrimitive>,
    /// Triangle lists.
    pub triangles: Vec<TriangleListPrimitive>,
    /// Texts.
    pub texts: Vec<TextPrimitive>,
    /// Models.
    pub models: Vec<ModelPrimitive>,
}

impl SceneEntity {
    /// An empty entity.
    pub fn new(timestamp: Time, frame_id: &str, id: String, frame_locked: bool) -> Self {
        Self {
            timestamp,
            frame_id: frame_id.to_string(),
            id,
            lifetime: Duration::FOREVER,
            frame_locked,
            metadata: Vec::new(),
            arrows: Vec::new(),
            cubes: Vec::new(),
            spheres: Vec::new(),
            cylinders: Vec::new(),
            lines: Vec::new(),
            triangles: Vec::new(),
            texts: Vec::new(),
            models: Vec::new(),
        }
    }

    /// Adds a metadata pair.
    pub fn meta(&mut self, key: &str, value: impl ToString) {
        self.metadata.push(KeyValuePair {
            key: key.to_string(),
            value: value.to_string(),
        });
    }
}

/// `foxglove.SceneEntityDeletionType` (the view replaces entities by id and
/// writes no deletions; the type keeps `deletions` honest).
#[allow(dead_code)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DeletionType {
    /// Delete the entity with the given id.
    MatchingId = 0,
    /// Delete every entity of the topic.
    All = 1,
}

impl Serialize for DeletionType {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_u8(*self as u8)
    }
}

/// `foxglove.SceneEntityDeletion`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SceneEntityDeletion {
    /// Entities earlier than this are deleted.
    pub timestamp: Time,
    /// Which entities.
    #[serde(rename = "type")]
    pub kind: DeletionType,
    /// The id, for `MatchingId`.
    pub id: String,
}

/// `foxglove.SceneUpdate`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SceneUpdate {
    /// Deletions, applied before `entities`.
    pub deletions: Vec<SceneEntityDeletion>,
    /// Entities to add or replace.
    pub entities: Vec<SceneEntity>,
}

impl FoxgloveMessage for SceneUpdate {
    const SCHEMA_NAME: &'static str = "foxglove.SceneUpdate";
    const SCHEMA_JSON: &'static str = include_str!("schemas/SceneUpdate.json");
}

/// `foxglove.FrameTransform`: the pose of `child_frame_id` in `parent_frame_id`
/// (a point `p` of the child is `rotation · p + translation` in the parent).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FrameTransform {
    /// When the transform holds.
    pub timestamp: Time,
    /// Parent frame.
    pub parent_frame_id: String,
    /// Child frame.
    pub child_frame_id: String,
    /// Child origin in the parent.
    pub translation: Vector3,
    /// Child orientation in the parent.
    pub rotation: Quaternion,
}

/// `foxglove.FrameTransforms`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FrameTransforms {
    /// The transforms.
    pub transforms: Vec<FrameTransform>,
}

impl FoxgloveMessage for FrameTransforms {
    const SCHEMA_NAME: &'static str = "foxglove.FrameTransforms";
    const SCHEMA_JSON: &'static str = include_str!("schemas/FrameTransforms.json");
}

/// `foxglove.PoseInFrame`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PoseInFrame {
    /// When the pose holds.
    pub timestamp: Time,
    /// Frame of the pose.
    pub frame_id: String,
    /// The pose.
    pub pose: Pose,
}

impl FoxgloveMessage for PoseInFrame {
    const SCHEMA_NAME: &'static str = "foxglove.PoseInFrame";
    const SCHEMA_JSON: &'static str = include_str!("schemas/PoseInFrame.json");
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::Value;

    /// Every object in `value` has exactly the properties its schema lists, all required.
    fn same_fields(value: &Value, schema: &Value, path: &str) {
        match value {
            Value::Object(map) => {
                let props = schema["properties"]
                    .as_object()
                    .unwrap_or_else(|| panic!("{path}: schema has no properties"));
                let mut have: Vec<&str> = map.keys().map(String::as_str).collect();
                let mut want: Vec<&str> = props.keys().map(String::as_str).collect();
                have.sort_unstable();
                want.sort_unstable();
                assert_eq!(have, want, "{path}: fields differ from the schema");
                let required: Vec<&str> = schema["required"]
                    .as_array()
                    .map(|a| a.iter().filter_map(Value::as_str).collect())
                    .unwrap_or_default();
                for (k, v) in map {
                    // time/duration objects list no `required`; everything else does.
                    if schema.get("title").and_then(Value::as_str) != Some("time")
                        && schema.get("title").and_then(Value::as_str) != Some("duration")
                    {
                        assert!(required.contains(&k.as_str()), "{path}.{k} not required");
                    }
                    same_fields(v, &props[k], &format!("{path}.{k}"));
                }
            }
            Value::Array(items) => {
                for (i, v) in items.iter().enumerate() {
                    same_fields(v, &schema["items"], &format!("{path}[{i}]"));
                }
            }
            Value::Number(n) => match schema.get("type").and_then(Value::as_str) {
                Some("integer") => assert!(n.is_u64() || n.is_i64(), "{path}: {n} not integer"),
                Some("number") => {}
                None => assert!(schema.get("oneOf").is_some(), "{path}: no type for {n}"),
                Some(t) => panic!("{path}: number where the schema says {t}"),
            },
            Value::Bool(_) => assert_eq!(schema["type"], "boolean", "{path}"),
            Value::String(_) => assert_eq!(schema["type"], "string", "{path}"),
            Value::Null => panic!("{path}: null"),
        }
    }

    fn full_entity() -> SceneEntity {
        let t = Time::from_ns(1_500_000_000);
        let c = Color::rgba(1.0, 0.5, 0.0, 1.0);
        let mut e = SceneEntity::new(t, "ned", "x".into(), true);
        e.meta("k", 1);
        e.arrows.push(ArrowPrimitive {
            pose: Pose::identity(),
            shaft_length: 1.0,
            shaft_diameter: 0.1,
            head_length: 0.3,
            head_diameter: 0.2,
            color: c,
        });
        e.cubes.push(CubePrimitive {
            pose: Pose::identity(),
            size: Vector3::from_array([1.0; 3]),
            color: c,
        });
        e.spheres.push(SpherePrimitive {
            pose: Pose::identity(),
            size: Vector3::from_array([1.0; 3]),
            color: c,
        });
        e.cylinders.push(CylinderPrimitive {
            pose: Pose::identity(),
            size: Vector3::from_array([1.0; 3]),
            bottom_scale: 1.0,
            top_scale: 1.0,
            color: c,
        });
        e.lines.push(LinePrimitive {
            kind: LineType::List,
            pose: Pose::identity(),
            thickness: 0.1,
            scale_invariant: false,
            points: vec![Vector3::from_array([0.0; 3]); 2],
            color: c,
            colors: vec![c; 2],
            indices: vec![0, 1],
        });
        e.triangles.push(TriangleListPrimitive {
            pose: Pose::identity(),
            points: vec![Vector3::from_array([0.0; 3]); 3],
            color: c,
            colors: vec![c; 3],
            indices: vec![0, 1, 2],
        });
        e.texts.push(TextPrimitive {
            pose: Pose::identity(),
            billboard: true,
            font_size: 12.0,
            scale_invariant: true,
            color: c,
            text: "L".into(),
        });
        e.models.push(ModelPrimitive {
            pose: Pose::identity(),
            scale: Vector3::from_array([1.0; 3]),
            color: c,
            override_color: false,
            url: String::new(),
            media_type: String::new(),
            data: String::new(),
        });
        e
    }

    fn check<T: FoxgloveMessage>(msg: &T) {
        let schema: Value = serde_json::from_str(T::SCHEMA_JSON).unwrap();
        assert_eq!(schema["title"], T::SCHEMA_NAME);
        let value = serde_json::to_value(msg).unwrap();
        same_fields(&value, &schema, T::SCHEMA_NAME);
    }

    #[test]
    fn scene_update_fields_match_the_official_schema() {
        check(&SceneUpdate {
            deletions: vec![SceneEntityDeletion {
                timestamp: Time::from_ns(0),
                kind: DeletionType::All,
                id: String::new(),
            }],
            entities: vec![full_entity()],
        });
    }

    #[test]
    fn frame_transforms_and_pose_fields_match_the_official_schema() {
        check(&FrameTransforms {
            transforms: vec![FrameTransform {
                timestamp: Time::from_ns(7),
                parent_frame_id: "world".into(),
                child_frame_id: "ned".into(),
                translation: Vector3::from_array([1.0, 2.0, 3.0]),
                rotation: Quaternion::IDENTITY,
            }],
        });
        check(&PoseInFrame {
            timestamp: Time::from_ns(7),
            frame_id: "ned".into(),
            pose: Pose::at([1.0, 2.0, 3.0]),
        });
    }

    #[test]
    fn enums_are_written_as_their_schema_numbers() {
        let v = serde_json::to_value(LineType::List).unwrap();
        assert_eq!(v, 2);
        let v = serde_json::to_value(DeletionType::MatchingId).unwrap();
        assert_eq!(v, 0);
        let schema: Value = serde_json::from_str(SceneUpdate::SCHEMA_JSON).unwrap();
        let line_types = &schema["properties"]["entities"]["items"]["properties"]["lines"]["items"]
            ["properties"]["type"]["oneOf"];
        let list = line_types
            .as_array()
            .unwrap()
            .iter()
            .find(|o| o["title"] == "LINE_LIST")
            .unwrap();
        assert_eq!(list["const"], 2);
    }

    #[test]
    fn time_splits_nanoseconds() {
        assert_eq!(
            Time::from_ns(12_345_678_901),
            Time {
                sec: 12,
                nsec: 345_678_901
            }
        );
        assert_eq!(Time::from_ns(0), Time { sec: 0, nsec: 0 });
    }
}

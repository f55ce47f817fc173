//! What makes a recording a rosbag2 bag as well as an MCAP file: each
//! channel's `offered_qos_profiles` (the MCAP registry's `ros2` profile asks
//! for it) and the `rosbag2` metadata record whose `serialized_metadata` is
//! the bag's `metadata.yaml`, which `ros2 bag info` and the pure-Python bag
//! readers take in place of a separate file.
//!
//! The layout is rosbag2's version 8 (ROS 2 Iron, read by Jazzy and later):
//! QoS enums as numbers.

use std::fmt::Write as _;

/// The metadata record's name.
pub const RECORD_NAME: &str = "rosbag2";
/// Its one key.
pub const SERIALIZED_METADATA: &str = "serialized_metadata";
/// The channel metadata key the `ros2` profile requires.
pub const OFFERED_QOS_PROFILES: &str = "offered_qos_profiles";
/// rosbag2 metadata version written.
pub const VERSION: u32 = 8;

/// The QoS a shoal channel offers, as rosbag2 serialises it: reliable (a
/// lockstep subscriber never loses a sample it has room for), volatile (no
/// late joiner gets history), keep-last `depth`, no deadline, lifespan or
/// lease (rosbag2 writes "infinite" as the largest `sec`/`nsec`).
pub fn offered_qos_profiles(depth: usize) -> String {
    const INF: &str = "    sec: 9223372036\n    nsec: 854775807\n";
    format!(
        "- history: 1\n  depth: {depth}\n  reliability: 1\n  durability: 2\n  deadline:\n{INF}  lifespan:\n{INF}  liveliness: 1\n  liveliness_lease_duration:\n{INF}  avoid_ros_namespace_conventions: false\n"
    )
}

/// One topic of the bag.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Topic {
    /// Topic name, `/F1/nav`.
    pub name: String,
    /// ROS 2 type, `shoal_msgs/msg/Nav`.
    pub type_name: String,
    /// [`offered_qos_profiles`] text.
    pub qos: String,
    /// Messages on it.
    pub messages: u64,
}

/// A string as a YAML scalar (JSON's double-quoted form is valid YAML).
fn yaml_str(s: &str) -> String {
    serde_json::Value::String(s.to_string()).to_string()
}

/// The `metadata.yaml` text of a one-file bag: `file` (its name), the
/// topics, and the first and last log time (ns).
pub fn serialized_metadata(file: &str, topics: &[Topic], start_ns: u64, end_ns: u64) -> String {
    let total: u64 = topics.iter().map(|t| t.messages).sum();
    let duration = end_ns.saturating_sub(start_ns);
    let mut y = String::new();
    let _ = writeln!(y, "rosbag2_bagfile_information:");
    let _ = writeln!(y, "  version: {VERSION}");
    let _ = writeln!(y, "  storage_identifier: mcap");
    let _ = writeln!(y, "  duration:\n    nanoseconds: {duration}");
    let _ = writeln!(
        y,
        "  starting_time:\n    nanoseconds_since_epoch: {start_ns}"
    );
    let _ = writeln!(y, "  message_count: {total}");
    if topics.is_empty() {
        let _ = writeln!(y, "  topics_with_message_count: []");
    } else {
        let _ = writeln!(y, "  topics_with_message_count:");
    }
    for t in topics {
        let _ = writeln!(y, "    - topic_metadata:");
        let _ = writeln!(y, "        name: {}", yaml_str(&t.name));
        let _ = writeln!(y, "        type: {}", yaml_str(&t.type_name));
        let _ = writeln!(y, "        serialization_format: cdr");
        let _ = writeln!(y, "        offered_qos_profiles: {}", yaml_str(&t.qos));
        let _ = writeln!(y, "        type_description_hash: \"\"");
        let _ = writeln!(y, "      message_count: {}", t.messages);
    }
    let _ = writeln!(y, "  compression_format: \"\"");
    let _ = writeln!(y, "  compression_mode: \"\"");
    let _ = writeln!(y, "  relative_file_paths:\n    - {}", yaml_str(file));
    let _ = writeln!(y, "  files:");
    let _ = writeln!(y, "    - path: {}", yaml_str(file));
    let _ = writeln!(
        y,
        "      starting_time:\n        nanoseconds_since_epoch: {start_ns}"
    );
    let _ = writeln!(y, "      duration:\n        nanoseconds: {duration}");
    let _ = writeln!(y, "      message_count: {total}");
    let _ = writeln!(y, "  custom_data: ~");
    let _ = writeln!(y, "  ros_distro: \"\"");
    y
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_metadata_names_every_topic_with_its_count_and_qos() {
        let topics = vec![
            Topic {
                name: "/L/nav".into(),
                type_name: "shoal_msgs/msg/Nav".into(),
                qos: offered_qos_profiles(4),
                messages: 10,
            },
            Topic {
                name: "/F1/truth".into(),
                type_name: "shoal_msgs/msg/Truth".into(),
                qos: offered_qos_profiles(4),
                messages: 5,
            },
        ];
        let y = serialized_metadata("recording.mcap", &topics, 100, 1100);
        assert!(y.starts_with("rosbag2_bagfile_information:\n  version: 8\n"));
        assert!(y.contains("  message_count: 15\n"));
        assert!(y.contains("nanoseconds: 1000\n"));
        assert!(y.contains("name: \"/F1/truth\""));
        assert!(y.contains("type: \"shoal_msgs/msg/Nav\""));
        assert!(y.contains("offered_qos_profiles: \"- history: 1\\n  depth: 4\\n"));
        assert!(y.contains("- \"recording.mcap\""));
        // No tab, and every line indented by an even number of spaces.
        for line in y.lines() {
            let indent = line.len() - line.trim_start_matches(' ').len();
            assert_eq!(indent % 2, 0, "{line}");
            assert!(!line.contains('\t'));
        }
    }

    #[test]
    fn the_qos_text_is_one_keep_last_profile() {
        let q = offered_qos_profiles(8);
        assert!(q.starts_with("- history: 1\n  depth: 8\n"));
        assert_eq!(q.matches("sec: 9223372036\n").count(), 3);
        assert!(q.ends_with("avoid_ros_namespace_conventions: false\n"));
    }
}

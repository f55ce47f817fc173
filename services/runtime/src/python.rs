//! The contract a process written in Python keeps with a run, generated
//! from the Rust types and functions that define it: every sample type as
//! a `ctypes.Structure` (from `ipc-types`' self-description, as the ros2msg
//! schemas are), each channel's service name and limits, the run's domain,
//! the lockstep doorbell's layout, the `done` event's ids and where the
//! statistics go.
//!
//! The `shoal_node` Python package (`python/` in the repository) imports
//! the module this writes, `python/shoal_node/contract.py`; nothing in it is
//! written by hand. A test keeps the file equal to [`contract_module`]:
//! after a change to a sample type, `SHOAL_BLESS=1 cargo test -p
//! shoal-runtime python` writes it again.

use std::fmt::Write as _;

use ipc_types::{
    for_each_sample_type, run_service_name, service_name, Channel, Described, FieldDesc,
    RunChannel, Sample, TypeDesc,
};

use crate::domain::{domain_prefix, domain_root, ChannelLimits, EXPIRED_CONNECTIONS};
use crate::doorbell::{doorbell_name, LAYOUT};
use crate::stats::{stats_dir, stats_limits, PUBLISH_EVERY_NS};
use crate::{arrival_service_name, ready_event_id};

/// The ctypes name of a ros2msg primitive (every one `ipc-types` has; any
/// other would make the module fail at import, naming it).
fn ctype(ros: &str) -> String {
    match ros {
        "float64" => "ctypes.c_double",
        "float32" => "ctypes.c_float",
        "uint64" => "ctypes.c_uint64",
        "int64" => "ctypes.c_int64",
        "uint32" => "ctypes.c_uint32",
        "int32" => "ctypes.c_int32",
        "uint16" => "ctypes.c_uint16",
        "int16" => "ctypes.c_int16",
        "uint8" => "ctypes.c_uint8",
        "int8" => "ctypes.c_int8",
        other => return format!("unknown_primitive_{other}"),
    }
    .to_string()
}

/// The Python class name of a ROS resource name (`shoal_msgs/msg/Nav` → `Nav`).
fn class_name(ros: &str) -> &str {
    ros.rsplit('/').next().unwrap_or(ros)
}

/// A field's ctypes type; nested types are written first into `classes`.
fn field_type(ty: &TypeDesc, classes: &mut Vec<(String, String)>) -> String {
    match ty {
        TypeDesc::Primitive { ros, .. } => ctype(ros),
        TypeDesc::Nested { ros, fields } => {
            let name = class_name(ros).to_string();
            if !classes.iter().any(|(n, _)| *n == name) {
                let body = structure(&name, ros, &fields(), None, classes);
                classes.push((name.clone(), body));
            }
            name
        }
        TypeDesc::Array { elem, len } => format!("{} * {len}", field_type(elem, classes)),
    }
}

/// One `ctypes.Structure` class; a sample type (`sample`: its iceoryx2 type
/// name and size) also gets `type_name()`, which iceoryx2's Python binding
/// matches against the Rust type's.
fn structure(
    name: &str,
    ros: &str,
    fields: &[FieldDesc],
    sample: Option<(&str, usize)>,
    classes: &mut Vec<(String, String)>,
) -> String {
    let types: Vec<(String, String)> = fields
        .iter()
        .map(|f| (f.name.clone(), field_type(&f.ty, classes)))
        .collect();
    let mut c = format!("class {name}(ctypes.Structure):\n    ROS_NAME = \"{ros}\"\n");
    if let Some((type_name, size)) = sample {
        let _ = writeln!(c, "    TYPE_NAME = \"{type_name}\"\n    SIZE = {size}");
    }
    c.push_str("    _fields_ = [\n");
    for (n, t) in &types {
        let _ = writeln!(c, "        (\"{n}\", {t}),");
    }
    c.push_str("    ]\n");
    if sample.is_some() {
        c.push_str("\n    @staticmethod\n    def type_name() -> str:\n        return ");
        let _ = writeln!(c, "{name}.TYPE_NAME");
    }
    c
}

/// A `Limits(...)` literal.
fn limits(l: &ChannelLimits) -> String {
    format!(
        "Limits(max_publishers={}, max_subscribers={}, max_nodes={}, max_buffer={}, history={})",
        l.max_publishers, l.max_subscribers, l.max_nodes, l.max_buffer, l.history
    )
}

/// Limits that grow linearly with a count, as `(base, per one more)`.
fn linear(f: impl Fn(usize) -> ChannelLimits) -> String {
    let (a, b) = (f(0), f(1));
    let d = ChannelLimits {
        max_publishers: b.max_publishers - a.max_publishers,
        max_subscribers: b.max_subscribers - a.max_subscribers,
        max_nodes: b.max_nodes - a.max_nodes,
        max_buffer: b.max_buffer - a.max_buffer,
        history: b.history - a.history,
    };
    format!("({}, {})", limits(&a), limits(&d))
}

/// The whole generated module.
pub fn contract_module() -> String {
    let mut classes: Vec<(String, String)> = Vec::new();
    for_each_sample_type!(T => {
        let name = class_name(<T as Described>::ROS_NAME).to_string();
        let body = structure(
            &name,
            <T as Described>::ROS_NAME,
            &<T as Described>::fields(),
            Some((<T as Sample>::TYPE_NAME, std::mem::size_of::<T>())),
            &mut classes,
        );
        classes.push((name, body));
    });
    let mut m = String::from(
        "\"\"\"The contract between a shoal run and a process written in Python.\n\n\
         GENERATED by `shoal_runtime::python::contract_module` from the Rust types and\n\
         functions that define it; do not edit. After a change to a sample type:\n\
         `SHOAL_BLESS=1 cargo test -p shoal-runtime python`.\n\"\"\"\n\n\
         # fmt: off\n\
         import ctypes\nfrom typing import NamedTuple\n\n\n\
         class Limits(NamedTuple):\n    \"\"\"An iceoryx2 service's limits: every opener asks for the same.\"\"\"\n\n    \
         max_publishers: int\n    max_subscribers: int\n    max_nodes: int\n    max_buffer: int\n    history: int\n\n\n",
    );
    for (_, body) in &classes {
        m.push_str(body);
        m.push_str("\n\n");
    }
    // Per-vehicle channels: name → (sample class, service name format).
    m.push_str("# Per-vehicle channels: name -> (sample type, service name; format with run_id, vehicle).\n");
    m.push_str("CHANNELS = {\n");
    for ch in Channel::ALL {
        let ty = class_name(ch.schema_name());
        let service = service_name("{run_id}", "{vehicle}", ch);
        let _ = writeln!(m, "    \"{}\": ({ty}, \"{service}\"),", ch.name());
    }
    m.push_str("}\n\n");
    m.push_str("# Run-level channels: name -> (sample type, service name; format with run_id).\n");
    m.push_str("RUN_CHANNELS = {\n");
    for (ch, ty) in [
        (RunChannel::World, <ipc_types::World as Described>::ROS_NAME),
        (RunChannel::Clock, <ipc_types::Clock as Described>::ROS_NAME),
        (
            RunChannel::Stats,
            <ipc_types::ProcessStats as Described>::ROS_NAME,
        ),
        (
            RunChannel::Events,
            <ipc_types::Event as Described>::ROS_NAME,
        ),
    ] {
        let _ = writeln!(
            m,
            "    \"{}\": ({}, \"{}\"),",
            ch.name(),
            class_name(ty),
            run_service_name("{run_id}", ch)
        );
    }
    m.push_str("}\n\n");
    let _ = writeln!(
        m,
        "# The `done` event: a process's ready is event id READY_ID[0]·index + READY_ID[1]·processes.\n\
         DONE_SERVICE = \"{}\"\nREADY_ID = ({}, {})\n",
        run_service_name("{run_id}", RunChannel::Done),
        ready_event_id(1, 0),
        ready_event_id(0, 1),
    );
    let _ = writeln!(
        m,
        "# Dataflow: the event a publisher notifies after each send on a service (format with service).\n\
         ARRIVAL_SERVICE = \"{}\"\n",
        arrival_service_name("{service}"),
    );
    let _ = writeln!(
        m,
        "# Limits: every per-vehicle channel's; a camera frame's; the world's and the stats'\n\
         # as (base, per vehicle) and (base, per process).\n\
         VEHICLE_LIMITS = {}\nIMAGE_LIMITS = {}\nWORLD_LIMITS = {}\nSTATS_LIMITS = {}\n",
        limits(&ChannelLimits::vehicle()),
        limits(&ChannelLimits::image()),
        linear(ChannelLimits::world),
        linear(stats_limits),
    );
    let _ = writeln!(
        m,
        "# The run's iceoryx2 domain (format with run_id) and what its subscribers keep.\n\
         DOMAIN_PREFIX = \"{}\"\nDOMAIN_ROOT = \"{}\"\nEXPIRED_CONNECTIONS = {EXPIRED_CONNECTIONS}\n",
        domain_prefix("{run_id}"),
        domain_root("{run_id}").display(),
    );
    let _ = writeln!(
        m,
        "# Statistics: published every STATS_EVERY_NS of the run's time; the exit file's directory.\n\
         STATS_EVERY_NS = {PUBLISH_EVERY_NS}\nSTATS_DIR = \"{}\"\n",
        stats_dir("{run_id}").display(),
    );
    let _ = writeln!(
        m,
        "# The lockstep doorbell: /dev/shm/<DOORBELL>, SLOT_BYTES per process and EXTRA_SLOTS\n\
         # after them (the tick's count of processes stepping, done's counter).\n\
         DOORBELL = \"{}\"\nSLOT_BYTES = {}\nEXTRA_SLOTS = {}\nSLOT_FIELDS = {{",
        doorbell_name("{run_id}"),
        LAYOUT.slot_bytes,
        LAYOUT.extra_slots,
    );
    for (name, offset) in LAYOUT.fields {
        let _ = writeln!(m, "    \"{name}\": {offset},");
    }
    m.push_str("}\n");
    m
}

/// Where the generated module lives in the repository.
pub fn contract_path() -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../python/shoal_node/contract.py")
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used)]
    use super::*;

    #[test]
    fn the_python_contract_in_the_repository_is_the_generated_one() {
        let want = contract_module();
        let path = contract_path();
        if std::env::var_os("SHOAL_BLESS").is_some() {
            std::fs::write(&path, &want).unwrap();
        }
        let have = std::fs::read_to_string(&path).unwrap_or_default();
        assert!(
            have == want,
            "{} is not the generated contract: run `SHOAL_BLESS=1 cargo test -p shoal-runtime python`",
            path.display()
        );
    }

    #[test]
    fn the_limits_python_computes_linearly_are_the_runtimes_at_any_size() {
        for f in [
            ChannelLimits::world as fn(usize) -> ChannelLimits,
            stats_limits,
        ] {
            let (a, b) = (f(0), f(1));
            for n in [2usize, 5, 100, 1024] {
                let l = f(n);
                assert_eq!(
                    l.max_publishers,
                    a.max_publishers + n * (b.max_publishers - a.max_publishers)
                );
                assert_eq!(
                    l.max_subscribers,
                    a.max_subscribers + n * (b.max_subscribers - a.max_subscribers)
                );
                assert_eq!(l.max_nodes, a.max_nodes + n * (b.max_nodes - a.max_nodes));
                assert_eq!(
                    l.max_buffer,
                    a.max_buffer + n * (b.max_buffer - a.max_buffer)
                );
                assert_eq!(l.history, a.history + n * (b.history - a.history));
            }
        }
        for (i, n) in [(0usize, 5usize), (3, 7), (9, 100)] {
            assert_eq!(
                ready_event_id(i, n),
                i * ready_event_id(1, 0) + n * ready_event_id(0, 1)
            );
        }
    }
}

//! A run spread over several hosts on Zenoh: one agent per host
//! (`shoal host`), a placement of the group over them, the crossing
//! services bridged between iceoryx2 and Zenoh, and a coordinator
//! (`shoal run --hosts FILE`) that drives the lockstep clock across them
//! and joins their recordings into one.
//!
//! | file | answers |
//! |---|---|
//! | [`placement`] | the hosts file; which host runs what; what crosses and its bandwidth |
//! | [`wire`] | key expressions and messages on Zenoh; why the star keeps lockstep exact |
//! | [`bridge`] | iceoryx2 services onto Zenoh and back, on one host |
//! | [`agent`] | `shoal host`: a host's share of a run |
//! | [`coordinator`] | `shoal run --hosts`: the run over the agents |
//! | [`tls`] | certificates, TLS and access control: who may talk to whom |
//! | [`netns`] | hosts that share nothing on one machine, for tests and benches |

pub mod agent;
pub mod bridge;
pub mod coordinator;
pub mod netns;
pub mod placement;
pub mod tls;
pub mod wire;

pub use placement::{HostsFile, Placement};

/// Every file below `dir`, sorted (directories that cannot be read are
/// skipped): a run's files to send back, a host's shared memory to check.
pub(crate) fn files_under(dir: &std::path::Path) -> Vec<std::path::PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        let Ok(entries) = std::fs::read_dir(&d) else {
            continue;
        };
        for e in entries.flatten() {
            let p = e.path();
            if p.is_dir() {
                stack.push(p);
            } else {
                out.push(p);
            }
        }
    }
    out.sort();
    out
}

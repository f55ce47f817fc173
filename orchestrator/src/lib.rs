//! The `shoal` library: runs a group of AUVs in leader–follower formation as
//! real processes over iceoryx2, records every channel to MCAP, and analyses,
//! plots, exports and replays the recordings. The `shoal` binary
//! (`main.rs`) is [`cli::main`].
//!
//! One folder per question:
//!
//! | folder | answers |
//! |---|---|
//! | [`cli`] | what the user typed: one file per command, clap arguments and printing only |
//! | [`preflight`] | may this scenario run here: load, resolve (D_a/D_b), advice, resources against the machine's limits |
//! | [`launch`] | how a run is driven: processes, lockstep and realtime, supervision and restart, the OS calls |
//! | [`hosts`] | a run spread over hosts on Zenoh: agents, placement, bridges, the coordinator |
//! | [`analysis`] | what the run did: trajectories, slot error, passage, the typed `summary.json`, compare |
//! | [`plots`] | the figures of a run and of a comparison |
//! | [`export`] | the recording for other viewers (Foxglove) |
//! | [`replay`] | a recording played back, or one process re-run on it |
//! | [`bench`] | the benchmarks that print figures (`shoal bench`) |
//! | [`gen`] | generated large-group scenarios and obstacle courses (`shoal gen`) |
//! | [`campaign`] | many generated courses × seeds, judged together (`shoal campaign`) |
//! | [`pipeline`] | one scenario from resolution to summary and plots (run, compare, benches) |

pub mod analysis;
pub mod bench;
pub mod campaign;
pub mod cli;
pub mod export;
pub mod gen;
pub mod hosts;
pub mod launch;
pub mod pipeline;
pub mod plots;
pub mod preflight;
pub mod progress;
pub mod replay;
pub mod report;
pub mod top;

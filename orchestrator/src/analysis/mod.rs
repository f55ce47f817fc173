//! What a run did, from its recording: one loader of the true trajectories
//! ([`track`]), one slot error and one passage window ([`formation`]), the
//! typed `summary.json` ([`summary`]) with its figures ([`metrics`]), and
//! the method-vs-baselines table ([`compare`]).

pub mod compare;
pub mod formation;
pub mod from_recording;
pub mod metrics;
pub mod summary;
pub mod track;

//! The benchmarks of `shoal bench`: each prints its figures (never a timed
//! assertion).

pub mod hosts;
pub mod ipc;
pub mod refuse;
pub mod run;
pub mod scale;
pub mod soak;
pub mod step;
pub mod vision;

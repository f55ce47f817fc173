//! What shoal shows in Foxglove and Rerun: pure functions from shoal's
//! samples and scenario to Foxglove's own message types (scene entities,
//! transforms, poses), and the conversion that turns a stream of samples
//! into them, for `shoal export --foxglove` (a recording, into an MCAP
//! file) and `shoal run --live` (a running run, to a WebSocket server).
//!
//! - [`foxglove`]: the message types (the `foxglove` crate's) and helpers;
//! - [`frames`]: the frames of the view (ENU `world`, NED `ned`, each
//!   vehicle's body and level frames);
//! - [`scene`]: obstacles, hulls, slots, sonar beams, lines of sight;
//! - [`track`]: one vehicle's true trajectory;
//! - [`Converter`]: samples in time order → messages on an [`Out`].

mod convert;
pub mod foxglove;
pub mod frames;
pub mod scene;
pub mod track;

pub use convert::{parse_topic, Converter, Out, ViewConfig};

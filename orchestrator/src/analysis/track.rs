//! The true trajectories: one loader for every reader of `/NAME/truth`
//! (the summary, the plots, the Foxglove export).

use std::collections::BTreeMap;

use ipc_types::{Channel, Truth};
use recordings::Recording;
use shoal_scenario::Scenario;
/// One vehicle's trajectory and the quaternion reader live in the view
/// crate (the Foxglove export and the live view use them too).
pub use shoal_view::track::{unit_wxyz, Track, MAX_GAP_NS};

/// Every vehicle's track, in the scenario's order.
#[derive(Debug, Clone)]
pub struct Tracks {
    /// One per vehicle of the scenario, in its order.
    pub tracks: Vec<Track>,
    index: BTreeMap<String, usize>,
}

impl Tracks {
    /// Loads the truth of every vehicle of `scenario` from `rec`.
    pub fn load(scenario: &Scenario, rec: &Recording) -> Self {
        Self::new(
            scenario
                .vehicles
                .iter()
                .map(|v| {
                    let truths = rec.samples::<Truth>(&ipc_types::topic(&v.name, Channel::Truth));
                    Track::from_truths(&v.name, &truths)
                })
                .collect(),
        )
    }

    /// Tracks given directly.
    pub fn new(tracks: Vec<Track>) -> Self {
        let index = tracks
            .iter()
            .enumerate()
            .map(|(i, t)| (t.name.clone(), i))
            .collect();
        Self { tracks, index }
    }

    /// The track of vehicle `name`.
    pub fn get(&self, name: &str) -> Option<&Track> {
        self.index.get(name).map(|&i| &self.tracks[i])
    }

    /// Index of vehicle `name`.
    pub fn index_of(&self, name: &str) -> Option<usize> {
        self.index.get(name).copied()
    }

    /// Time of the last sample of any track, ns.
    pub fn end_ns(&self) -> u64 {
        self.tracks
            .iter()
            .filter_map(Track::end_ns)
            .max()
            .unwrap_or(0)
    }
}

/// A truth sample at `t_ns`, at `p`, facing north (for tests).
#[cfg(test)]
pub(crate) fn truth(t_ns: u64, p: [f64; 3]) -> Truth {
    let mut s = <Truth as ipc_types::Sample>::zeroed();
    s.header.sim_time_ns = t_ns;
    s.position_ned_m = p;
    s.q_body_to_ned_wxyz = [1.0, 0.0, 0.0, 0.0];
    s
}

/// A track through `(t ns, p)` points, facing north (for tests).
#[cfg(test)]
pub(crate) fn track_through(name: &str, pts: &[(u64, [f64; 3])]) -> Track {
    let truths: Vec<Truth> = pts.iter().map(|&(t, p)| truth(t, p)).collect();
    Track::from_truths(name, &truths)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn samples_are_sorted_and_unusable_ones_left_out() {
        let mut bad = truth(5, [0.0; 3]);
        bad.q_body_to_ned_wxyz = [0.0; 4];
        let t = Track::from_truths(
            "A",
            &[
                truth(20, [2.0, 0.0, 0.0]),
                truth(10, [1.0, 0.0, 0.0]),
                bad,
                truth(30, [f64::NAN, 0.0, 0.0]),
            ],
        );
        assert_eq!(t.t_ns, [10, 20]);
        assert_eq!(t.p[0].x, 1.0);
    }

    #[test]
    fn at_interpolates_within_the_gap_and_not_across_it() {
        let s = MAX_GAP_NS;
        let t = Track::from_truths(
            "A",
            &[
                truth(0, [0.0; 3]),
                truth(s, [2.0, 0.0, 0.0]),
                truth(3 * s, [4.0, 0.0, 0.0]),
            ],
        );
        assert_eq!(t.at(s / 2).map(|(p, _)| p.x), Some(1.0));
        assert_eq!(t.at(s).map(|(p, _)| p.x), Some(2.0));
        assert!(t.at(2 * s).is_none(), "two gaps apart: no interpolation");
        assert!(t.at(4 * s).is_none(), "after the end");
        assert_eq!(t.latest(2 * s), Some(1));
        assert_eq!(t.recent(2 * s), Some(1), "exactly one gap old");
        assert_eq!(t.recent(2 * s + 1), None);
    }

    #[test]
    fn tracks_are_found_by_name() {
        let ts = Tracks::new(vec![
            Track::from_truths("L", &[truth(0, [0.0; 3]), truth(7, [0.0; 3])]),
            Track::from_truths("F1", &[truth(0, [0.0; 3])]),
        ]);
        assert_eq!(ts.index_of("F1"), Some(1));
        assert_eq!(ts.get("L").map(Track::len), Some(2));
        assert!(ts.get("F9").is_none());
        assert_eq!(ts.end_ns(), 7);
    }
}

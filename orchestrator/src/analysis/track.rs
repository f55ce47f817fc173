//! The true trajectories: one loader for every reader of `/NAME/truth`
//! (the summary, the plots, the Foxglove export).

use std::collections::BTreeMap;

use ipc_types::{Channel, Truth};
use nalgebra::{Quaternion, UnitQuaternion, Vector3};
use recordings::Recording;
use shoal_scenario::Scenario;

/// Largest gap across which a position is interpolated or a sample still
/// stands for the present, ns.
pub const MAX_GAP_NS: u64 = 250_000_000;

/// One vehicle's true trajectory in time order: position (NED, m) and
/// attitude (body → NED) at each sample's simulation time (ns).
#[derive(Debug, Clone, Default)]
pub struct Track {
    /// The vehicle.
    pub name: String,
    /// Sample times, ns, ascending.
    pub t_ns: Vec<u64>,
    /// Positions, NED, m.
    pub p: Vec<Vector3<f64>>,
    /// Attitudes, body → NED.
    pub q: Vec<UnitQuaternion<f64>>,
}

/// A shoal `[w, x, y, z]` quaternion as a unit nalgebra quaternion
/// (normalised; `None` if it is zero or not finite).
pub fn unit_wxyz(q: [f64; 4]) -> Option<UnitQuaternion<f64>> {
    let raw = Quaternion::new(q[0], q[1], q[2], q[3]);
    let n = raw.norm();
    (n.is_finite() && n > 1e-9).then(|| UnitQuaternion::from_quaternion(raw))
}

impl Track {
    /// An empty track of `name`.
    pub fn new(name: &str) -> Self {
        Self {
            name: name.to_string(),
            ..Self::default()
        }
    }

    /// The track of `name` from its truth samples (sorted by time; a sample
    /// with a non-finite position or a degenerate attitude is left out).
    pub fn from_truths(name: &str, truths: &[Truth]) -> Self {
        let mut order: Vec<&Truth> = truths.iter().collect();
        order.sort_by_key(|s| s.header.sim_time_ns);
        let mut track = Self::new(name);
        for s in order {
            track.push(s);
        }
        track
    }

    /// Appends one truth sample (callers keep time order); returns whether
    /// it was usable.
    pub fn push(&mut self, s: &Truth) -> bool {
        let p = Vector3::from(s.position_ned_m);
        let Some(q) = unit_wxyz(s.q_body_to_ned_wxyz) else {
            return false;
        };
        if !p.iter().all(|x| x.is_finite()) {
            return false;
        }
        self.t_ns.push(s.header.sim_time_ns);
        self.p.push(p);
        self.q.push(q);
        true
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        self.t_ns.len()
    }

    /// True if the track holds no sample.
    pub fn is_empty(&self) -> bool {
        self.t_ns.is_empty()
    }

    /// Position and attitude at `t`: the sample stamped `t` (lockstep: every
    /// plant steps on the same ticks), else interpolated between the samples
    /// around it when they are at most [`MAX_GAP_NS`] apart (realtime: each
    /// plant stamps its own wake-up time). The attitude is the nearer one's.
    pub fn at(&self, t: u64) -> Option<(Vector3<f64>, UnitQuaternion<f64>)> {
        match self.t_ns.binary_search(&t) {
            Ok(i) => Some((self.p[i], self.q[i])),
            Err(0) => None,
            Err(i) if i == self.t_ns.len() => None,
            Err(i) => {
                let (t0, t1) = (self.t_ns[i - 1], self.t_ns[i]);
                if t1 - t0 > MAX_GAP_NS {
                    return None;
                }
                let a = (t - t0) as f64 / (t1 - t0) as f64;
                let q = if a < 0.5 { self.q[i - 1] } else { self.q[i] };
                Some((self.p[i - 1] + (self.p[i] - self.p[i - 1]) * a, q))
            }
        }
    }

    /// Index of the last sample at or before `t`, however old.
    pub fn latest(&self, t: u64) -> Option<usize> {
        self.t_ns.partition_point(|x| *x <= t).checked_sub(1)
    }

    /// Index of the last sample at or before `t` if it is at most
    /// [`MAX_GAP_NS`] old.
    pub fn recent(&self, t: u64) -> Option<usize> {
        self.latest(t).filter(|&i| t - self.t_ns[i] <= MAX_GAP_NS)
    }

    /// Time of the last sample, ns.
    pub fn end_ns(&self) -> Option<u64> {
        self.t_ns.last().copied()
    }
}

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

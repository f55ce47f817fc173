//! The formation's two shared definitions: a follower's slot error and the
//! obstacle passage (when any follower was shifting for an obstacle).

use ipc_types::{Channel, PlannerState};
use nalgebra::Vector3;
use recordings::Recording;
use shoal_scenario::Scenario;

use super::track::Track;

/// How long after the last avoiding sample the formation is still counted
/// as "during" the passage (it is settling back into its slots), ns.
pub const SETTLE_NS: u64 = 20_000_000_000;

/// A follower's slot error at each of its own samples that its parent's
/// track covers: `(t ns, |p − (p_parent + R_parent·slot)|)`, slot in the
/// parent's body frame (FRD, m), the parent's pose interpolated
/// ([`Track::at`]).
pub fn slot_errors(follower: &Track, parent: &Track, slot: [f64; 3]) -> Vec<(u64, f64)> {
    let slot = Vector3::from(slot);
    follower
        .t_ns
        .iter()
        .zip(&follower.p)
        .filter_map(|(&t, p)| {
            let (pp, qp) = parent.at(t)?;
            Some((t, (p - (pp + qp * slot)).norm()))
        })
        .collect()
}

/// One follower's stretch of avoiding.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub struct Span {
    /// First sample that reported avoiding, ns.
    pub start_ns: u64,
    /// Last sample that reported avoiding, ns.
    pub last_ns: u64,
    /// First sample after it that did not (or the last sample if none), ns.
    pub end_ns: u64,
}

/// When the formation was passing an obstacle: the followers' avoiding
/// stretches (`planner_state.avoiding`), merged where they overlap.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Passage {
    /// Merged stretches in time order.
    pub spans: Vec<Span>,
}

/// Which part of a run a time falls in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Phase {
    /// Before any follower avoided (the whole run if none did).
    Before,
    /// From the first avoiding sample to [`SETTLE_NS`] after the last.
    During,
    /// After that.
    After,
}

impl Passage {
    /// The passage of a run from every follower's `planner_state`.
    pub fn load(scenario: &Scenario, rec: &Recording) -> Self {
        let states = scenario
            .vehicles
            .iter()
            .filter(|v| v.parent.is_some())
            .map(|v| {
                let mut s =
                    rec.samples::<PlannerState>(&ipc_types::topic(&v.name, Channel::PlannerState));
                s.sort_by_key(|s| s.header.sim_time_ns);
                s.iter()
                    .map(|s| (s.header.sim_time_ns, s.avoiding != 0))
                    .collect::<Vec<_>>()
            });
        Self::from_followers(states)
    }

    /// The passage from each follower's `(t ns, avoiding)` series, each in
    /// time order.
    pub fn from_followers(followers: impl IntoIterator<Item = Vec<(u64, bool)>>) -> Self {
        let mut spans = Vec::new();
        for series in followers {
            let mut open: Option<(u64, u64)> = None;
            let mut last_t = 0;
            for (t, avoiding) in series {
                open = match (avoiding, open) {
                    (true, None) => Some((t, t)),
                    (true, Some((a, _))) => Some((a, t)),
                    (false, Some((a, l))) => {
                        spans.push(Span {
                            start_ns: a,
                            last_ns: l,
                            end_ns: t,
                        });
                        None
                    }
                    (false, None) => None,
                };
                last_t = t;
            }
            if let Some((a, l)) = open {
                spans.push(Span {
                    start_ns: a,
                    last_ns: l,
                    end_ns: last_t,
                });
            }
        }
        spans.sort_unstable();
        let mut merged: Vec<Span> = Vec::new();
        for s in spans {
            match merged.last_mut() {
                Some(m) if s.start_ns <= m.end_ns => {
                    m.end_ns = m.end_ns.max(s.end_ns);
                    m.last_ns = m.last_ns.max(s.last_ns);
                }
                _ => merged.push(s),
            }
        }
        Self { spans: merged }
    }

    /// First and last avoiding sample of the run, ns.
    pub fn window_ns(&self) -> Option<(u64, u64)> {
        let first = self.spans.first()?.start_ns;
        let last = self.spans.iter().map(|s| s.last_ns).max()?;
        Some((first, last))
    }

    /// The part of the run `t` falls in.
    pub fn phase(&self, t: u64) -> Phase {
        match self.window_ns() {
            None => Phase::Before,
            Some((first, _)) if t < first => Phase::Before,
            Some((_, last)) if t <= last.saturating_add(SETTLE_NS) => Phase::During,
            Some(_) => Phase::After,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::analysis::track::Track;
    use ipc_types::{Sample, Truth};

    fn track(name: &str, pts: &[(u64, [f64; 3])]) -> Track {
        crate::analysis::track::track_through(name, pts)
    }

    #[test]
    fn a_follower_off_its_slot_by_a_known_amount() {
        let parent = track("L", &[(0, [10.0, 0.0, 5.0]), (100, [11.0, 0.0, 5.0])]);
        // Slot 8 m astern, 4 m to starboard; the follower 3 m north and 4 m
        // down of it at t = 0, on it at t = 100.
        let follower = track("F", &[(0, [5.0, 4.0, 9.0]), (100, [3.0, 4.0, 5.0])]);
        let e = slot_errors(&follower, &parent, [-8.0, 4.0, 0.0]);
        assert_eq!(e.len(), 2);
        approx::assert_relative_eq!(e[0].1, 5.0, epsilon = 1e-12);
        approx::assert_relative_eq!(e[1].1, 0.0, epsilon = 1e-12);
    }

    #[test]
    fn the_slot_turns_with_the_parent() {
        // Parent heading east (yaw 90°): its starboard is south.
        let mut s = <Truth as Sample>::zeroed();
        s.q_body_to_ned_wxyz = [
            std::f64::consts::FRAC_PI_4.cos(),
            0.0,
            0.0,
            std::f64::consts::FRAC_PI_4.sin(),
        ];
        let parent = Track::from_truths("L", &[s]);
        let follower = track("F", &[(0, [-4.0, -8.0, 0.0])]);
        let e = slot_errors(&follower, &parent, [-8.0, 4.0, 0.0]);
        approx::assert_relative_eq!(e[0].1, 0.0, epsilon = 1e-12);
    }

    #[test]
    fn no_error_where_the_parent_has_a_gap() {
        let gap = crate::analysis::track::MAX_GAP_NS;
        let parent = track("L", &[(0, [0.0; 3]), (3 * gap, [0.0; 3])]);
        let follower = track("F", &[(0, [0.0; 3]), (gap, [0.0; 3]), (3 * gap, [0.0; 3])]);
        let e = slot_errors(&follower, &parent, [0.0; 3]);
        assert_eq!(e.iter().map(|x| x.0).collect::<Vec<_>>(), [0, 3 * gap]);
    }

    #[test]
    fn overlapping_stretches_merge_and_phases_follow_the_window() {
        let a = vec![(0, false), (10, true), (20, true), (30, false)];
        let b = vec![(0, false), (25, true), (35, false), (45, true)];
        let p = Passage::from_followers([a, b]);
        assert_eq!(
            p.spans,
            [
                Span {
                    start_ns: 10,
                    last_ns: 25,
                    end_ns: 35
                },
                Span {
                    start_ns: 45,
                    last_ns: 45,
                    end_ns: 45
                }
            ]
        );
        assert_eq!(p.window_ns(), Some((10, 45)));
        assert_eq!(p.phase(9), Phase::Before);
        assert_eq!(p.phase(10), Phase::During);
        assert_eq!(p.phase(45 + SETTLE_NS), Phase::During);
        assert_eq!(p.phase(46 + SETTLE_NS), Phase::After);
        let none = Passage::from_followers([vec![(0, false), (10, false)]]);
        assert_eq!(none.window_ns(), None);
        assert_eq!(none.phase(u64::MAX), Phase::Before);
    }
}

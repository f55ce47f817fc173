//! One vehicle's true trajectory, as the view (and the analysis) read it.

use ipc_types::Truth;
use nalgebra::{Quaternion, UnitQuaternion, Vector3};

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

    /// Forgets the samples before `t_ns` but the last of them, so that
    /// [`Track::latest`] at `t_ns` or later answers as before (a live
    /// view's memory stays bounded).
    pub fn forget_before(&mut self, t_ns: u64) {
        let n = self.t_ns.partition_point(|x| *x < t_ns).saturating_sub(1);
        if n > 0 {
            self.t_ns.drain(..n);
            self.p.drain(..n);
            self.q.drain(..n);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use bytemuck::Zeroable as _;

    #[test]
    fn forgetting_keeps_the_latest_answer_from_then_on() {
        let mut t = Track::new("L");
        for i in 0..10u64 {
            let mut s = Truth::zeroed();
            s.header.sim_time_ns = i * 100;
            s.position_ned_m = [i as f64, 0.0, 0.0];
            s.q_body_to_ned_wxyz = [1.0, 0.0, 0.0, 0.0];
            assert!(t.push(&s));
        }
        let before: Vec<Option<usize>> = (450..1000).step_by(50).map(|x| t.latest(x)).collect();
        t.forget_before(450);
        assert_eq!(t.len(), 6);
        for (k, x) in (450..1000).step_by(50).enumerate() {
            let i = t.latest(x).unwrap();
            assert_eq!(t.p[i].x as usize, before[k].unwrap());
        }
    }
}

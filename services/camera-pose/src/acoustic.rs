//! The acoustic baseline the paper argues against: instead of seeing its
//! parent, a follower receives the parent's pose over an acoustic modem.
//!
//! The parent broadcasts one packet every `packet_bits / bit_rate_bps`
//! seconds (default 256 bit at 80 bit/s: one update every 3.2 s). A packet
//! carries the parent's pose relative to the follower at the moment it was
//! sent (as a USBL fix on the receiver would give it), with Gaussian noise;
//! it arrives `range / sound_speed` later, or never (loss probability). The
//! follower's planner gets it as a `leader_pose` stamped with the send time.

use std::collections::VecDeque;

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use rand::Rng;
use rand_distr::{Distribution, StandardNormal};
use serde::{Deserialize, Serialize};

/// The modem (`[acoustic]` in a scenario).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct AcousticConfig {
    /// Link bit rate, bit/s (default 80).
    pub bit_rate_bps: f64,
    /// Bits per pose packet: position, heading, time, id, CRC (default 256).
    pub packet_bits: f64,
    /// Speed of sound in water, m/s (default 1500).
    pub sound_speed_mps: f64,
    /// Probability that a packet is lost (default 0.1).
    pub loss_probability: f64,
    /// Position noise of a fix, 1σ per axis, m (default 0.3).
    pub position_noise_m: f64,
    /// Heading noise of a fix, 1σ, deg (default 2).
    pub heading_noise_deg: f64,
}

impl Default for AcousticConfig {
    fn default() -> Self {
        Self {
            bit_rate_bps: 80.0,
            packet_bits: 256.0,
            sound_speed_mps: 1500.0,
            loss_probability: 0.1,
            position_noise_m: 0.3,
            heading_noise_deg: 2.0,
        }
    }
}

impl AcousticConfig {
    /// Checks every key; the error names it.
    pub fn validate(&self) -> Result<(), String> {
        let pos = |k: &str, v: f64| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(format!("acoustic.{k} must be > 0, got {v}"))
            }
        };
        pos("bit_rate_bps", self.bit_rate_bps)?;
        pos("packet_bits", self.packet_bits)?;
        pos("sound_speed_mps", self.sound_speed_mps)?;
        if !(0.0..1.0).contains(&self.loss_probability) {
            return Err(format!(
                "acoustic.loss_probability must be in [0, 1), got {}",
                self.loss_probability
            ));
        }
        for (k, v) in [
            ("position_noise_m", self.position_noise_m),
            ("heading_noise_deg", self.heading_noise_deg),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(format!("acoustic.{k} must be >= 0, got {v}"));
            }
        }
        Ok(())
    }

    /// Time between two packets, s.
    pub fn period_s(&self) -> f64 {
        self.packet_bits / self.bit_rate_bps
    }
}

/// A packet in flight.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Packet {
    /// When it was sent, s.
    pub sent_s: f64,
    /// When it arrives, s.
    pub arrival_s: f64,
    /// The parent's pose in the follower's body frame at `sent_s`, with noise.
    pub parent_in_body: Isometry3<f64>,
    /// Wall-clock stamp of the send, ns (for latency).
    pub sent_mono_ns: u64,
}

/// One follower's receiving modem.
#[derive(Debug, Clone)]
pub struct Modem {
    cfg: AcousticConfig,
    next_send_s: f64,
    in_flight: VecDeque<Packet>,
}

impl Modem {
    /// A modem whose first packet goes out at `first_send_s`.
    pub fn new(cfg: &AcousticConfig, first_send_s: f64) -> Result<Self, String> {
        cfg.validate()?;
        Ok(Self {
            cfg: cfg.clone(),
            next_send_s: first_send_s,
            in_flight: VecDeque::with_capacity(4),
        })
    }

    /// Advances to `t_s`: sends a packet if one is due (from the true
    /// relative pose), and returns the newest packet that has arrived.
    pub fn step<R: Rng>(
        &mut self,
        t_s: f64,
        now_mono_ns: u64,
        truth_parent_in_body: &Isometry3<f64>,
        rng: &mut R,
    ) -> Option<Packet> {
        if t_s >= self.next_send_s {
            self.next_send_s += self.cfg.period_s();
            // Draw every random number whether or not the packet is lost, so
            // one loss does not shift the noise of later packets.
            let lost = rng.random::<f64>() < self.cfg.loss_probability;
            let n: [f64; 4] = std::array::from_fn(|_| StandardNormal.sample(rng));
            if !lost {
                let range = truth_parent_in_body.translation.vector.norm();
                let noise = Vector3::new(n[0], n[1], n[2]) * self.cfg.position_noise_m;
                let yaw = n[3] * self.cfg.heading_noise_deg.to_radians();
                let pose = Isometry3::from_parts(
                    Translation3::from(truth_parent_in_body.translation.vector + noise),
                    UnitQuaternion::from_euler_angles(0.0, 0.0, yaw)
                        * truth_parent_in_body.rotation,
                );
                self.in_flight.push_back(Packet {
                    sent_s: t_s,
                    arrival_s: t_s + range / self.cfg.sound_speed_mps,
                    parent_in_body: pose,
                    sent_mono_ns: now_mono_ns,
                });
            }
        }
        let mut delivered = None;
        while self.in_flight.front().is_some_and(|p| p.arrival_s <= t_s) {
            delivered = self.in_flight.pop_front();
        }
        delivered
    }

    /// The covariance the receiver reports with a fix (position, rotation vector).
    pub fn covariance(&self) -> nalgebra::Matrix6<f64> {
        let p = self.cfg.position_noise_m.powi(2).max(1e-6);
        let h = self.cfg.heading_noise_deg.to_radians().powi(2).max(1e-8);
        nalgebra::Matrix6::from_diagonal(&nalgebra::Vector6::new(p, p, p, h, h, h))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    fn rel(x: f64) -> Isometry3<f64> {
        Isometry3::translation(x, 0.0, 0.0)
    }

    #[test]
    fn packets_arrive_at_the_bit_rate_after_the_propagation_delay() {
        let cfg = AcousticConfig {
            loss_probability: 0.0,
            position_noise_m: 0.0,
            heading_noise_deg: 0.0,
            ..Default::default()
        };
        let mut m = Modem::new(&cfg, 0.0).unwrap();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
        let mut got = Vec::new();
        let dt = 0.001;
        for k in 0..10_000 {
            let t = k as f64 * dt;
            if let Some(p) = m.step(t, 0, &rel(150.0), &mut rng) {
                got.push((t, p));
            }
        }
        // 10 s at one packet per 3.2 s: sent at 0, 3.2, 6.4 and 9.6 s, each
        // arriving 0.1 s later, all inside the 10 s window.
        assert_eq!(got.len(), 4);
        for (t, p) in &got {
            assert!(
                (p.arrival_s - p.sent_s - 0.1).abs() < 1e-9,
                "150 m at 1500 m/s is 0.1 s"
            );
            assert!(*t >= p.arrival_s && *t < p.arrival_s + 2.0 * dt);
            assert!((p.parent_in_body.translation.x - 150.0).abs() < 1e-12);
        }
        assert!((got[1].1.sent_s - got[0].1.sent_s - 3.2).abs() < 2.0 * dt);
    }

    #[test]
    fn lost_packets_never_arrive() {
        let cfg = AcousticConfig {
            loss_probability: 0.5,
            ..Default::default()
        };
        let mut m = Modem::new(&cfg, 0.0).unwrap();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(2);
        let mut n = 0;
        for k in 0..32_000 {
            if m.step(k as f64 * 0.1, 0, &rel(10.0), &mut rng).is_some() {
                n += 1;
            }
        }
        // 1000 packets sent, about half arrive.
        assert!((400..600).contains(&n), "{n}");
    }

    #[test]
    fn bad_config_names_the_key() {
        let cfg = AcousticConfig {
            bit_rate_bps: 0.0,
            ..Default::default()
        };
        assert!(cfg
            .validate()
            .unwrap_err()
            .contains("acoustic.bit_rate_bps"));
    }
}

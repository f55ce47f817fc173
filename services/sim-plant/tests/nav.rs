//! Navigation sensor tests: determinism, noise levels, leader-only position.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use approx::assert_relative_eq;
use nalgebra::{UnitQuaternion, Vector3, Vector6};
use sim_plant::nav::{NavConfig, NavSensor};
use sim_plant::PlantState;

fn truth() -> PlantState {
    PlantState {
        position_ned_m: Vector3::new(10.0, -5.0, 12.0),
        attitude: UnitQuaternion::from_euler_angles(0.1, -0.2, 1.0),
        nu: Vector6::new(1.5, 0.1, -0.05, 0.01, 0.02, -0.03),
    }
}

#[test]
fn same_seed_same_readings_other_seed_other_readings() {
    let cfg = NavConfig::default();
    let mut a = NavSensor::new(&cfg, 7).unwrap();
    let mut b = NavSensor::new(&cfg, 7).unwrap();
    let mut c = NavSensor::new(&cfg, 8).unwrap();
    for _ in 0..10 {
        let (ma, mb, mc) = (
            a.measure(&truth(), true),
            b.measure(&truth(), true),
            c.measure(&truth(), true),
        );
        assert_eq!(ma, mb);
        assert_ne!(ma, mc);
    }
}

#[test]
fn zero_noise_reads_the_truth() {
    let cfg = NavConfig {
        attitude_noise_rad: 0.0,
        rate_noise_radps: 0.0,
        velocity_noise_mps: 0.0,
        depth_noise_m: 0.0,
        position_noise_m: 0.0,
    };
    let mut s = NavSensor::new(&cfg, 1).unwrap();
    let t = truth();
    let m = s.measure(&t, true);
    assert_relative_eq!(m.attitude, t.attitude, epsilon = 1e-15);
    assert_eq!(m.velocity_body_mps, Vector3::new(1.5, 0.1, -0.05));
    assert_eq!(m.rates_body_radps, Vector3::new(0.01, 0.02, -0.03));
    assert_eq!(m.depth_m, 12.0);
    assert_eq!(m.position_ned_m, Some(t.position_ned_m));
}

#[test]
fn absolute_position_only_when_asked_and_other_readings_unchanged() {
    let cfg = NavConfig::default();
    let mut leader = NavSensor::new(&cfg, 3).unwrap();
    let mut follower = NavSensor::new(&cfg, 3).unwrap();
    let l = leader.measure(&truth(), true);
    let f = follower.measure(&truth(), false);
    assert!(l.position_ned_m.is_some());
    assert!(f.position_ned_m.is_none());
    assert_eq!(l.velocity_body_mps, f.velocity_body_mps);
    assert_eq!(l.depth_m, f.depth_m);
}

#[test]
fn noise_has_the_configured_spread() {
    let cfg = NavConfig::default();
    let mut s = NavSensor::new(&cfg, 42).unwrap();
    let t = truth();
    let n = 20_000;
    let (mut sv, mut sd, mut sa) = (0.0, 0.0, 0.0);
    for _ in 0..n {
        let m = s.measure(&t, false);
        sv += (m.velocity_body_mps.x - t.nu[0]).powi(2);
        sd += (m.depth_m - t.position_ned_m.z).powi(2);
        sa += t.attitude.angle_to(&m.attitude).powi(2);
    }
    let nf = f64::from(n);
    assert_relative_eq!(
        (sv / nf).sqrt(),
        cfg.velocity_noise_mps,
        max_relative = 0.05
    );
    assert_relative_eq!((sd / nf).sqrt(), cfg.depth_noise_m, max_relative = 0.05);
    // The rotation angle of a 3-axis isotropic perturbation has RMS σ·√3.
    assert_relative_eq!(
        (sa / nf).sqrt(),
        cfg.attitude_noise_rad * 3f64.sqrt(),
        max_relative = 0.05
    );
}

#[test]
fn negative_noise_is_refused_with_its_key() {
    let cfg = NavConfig {
        depth_noise_m: -0.1,
        ..NavConfig::default()
    };
    let e = NavSensor::new(&cfg, 0).unwrap_err().to_string();
    assert!(e.contains("nav.depth_noise_m"), "{e}");
}

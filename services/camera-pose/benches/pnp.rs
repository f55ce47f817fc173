//! PnP time per call for the default 4-beacon layout (target < 20 µs).
//!
//! - `pnp_4_beacons_cold`: no previous estimate (POSIT + P3P starts, each
//!   refined), as at acquisition or after `reset`.
//! - `pnp_4_beacons_tracking`: a sequence of frames of a parent moving 6-9 m
//!   ahead at 10 Hz with 1 px noise, each solved with the previous estimate
//!   (the steady state of the camera-pose process).
//!
//! Run: `cargo bench -p camera-pose --bench pnp` (criterion prints the time
//! per call).

#![allow(clippy::unwrap_used)] // a bench, like a test, may stop on a broken setup

use camera_pose::{
    BeaconLayout, BeaconObservation, Camera, CameraConfig, PoseConfig, PoseEstimator,
};
use criterion::{criterion_group, criterion_main, Criterion};
use nalgebra::{Isometry3, Vector3};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use std::hint::black_box;

fn bench_pnp(c: &mut Criterion) {
    let cam_cfg = CameraConfig::default();
    let layout = BeaconLayout::default();
    let camera = Camera::new(&cam_cfg).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(42);
    let follower = Isometry3::identity();

    // One frame for the cold solve.
    let parent = Isometry3::new(Vector3::new(8.0, 1.0, 0.5), Vector3::new(0.05, -0.1, 0.3));
    let obs = camera.observe(&follower, &parent, &layout, &[], &mut rng);
    assert_eq!(obs.visible_count(), 4);
    let mut est = PoseEstimator::new(&PoseConfig::default(), &cam_cfg, &layout).unwrap();
    assert!(est.estimate(&obs).valid);
    c.bench_function("pnp_4_beacons_cold", |b| {
        b.iter(|| {
            est.reset();
            black_box(est.estimate(black_box(&obs)))
        })
    });

    // A 20 s track at 10 Hz: the parent weaves 6-9 m ahead.
    let frames: Vec<BeaconObservation> = (0..200)
        .map(|k| {
            let t = f64::from(k) * 0.1;
            let p = Isometry3::new(
                Vector3::new(
                    1.4 + 7.5 + 1.5 * (0.3 * t).sin(),
                    1.5 * (0.2 * t).sin(),
                    0.3,
                ),
                Vector3::new(0.0, 0.0, 0.3 * (0.2 * t).cos()),
            );
            let o = camera.observe(&follower, &p, &layout, &[], &mut rng);
            assert_eq!(o.visible_count(), 4);
            o
        })
        .collect();
    est.reset();
    let mut k = 0;
    c.bench_function("pnp_4_beacons_tracking", |b| {
        b.iter(|| {
            let e = est.estimate(black_box(&frames[k]));
            k = (k + 1) % frames.len();
            black_box(e)
        })
    });
}

criterion_group!(benches, bench_pnp);
criterion_main!(benches);

//! PnP time per call for the default 4-beacon layout (target < 20 µs).
//!
//! `cold`: no previous estimate (P3P start, up to 4 refinements);
//! `warm`: tracking, with the previous estimate as an extra start.
//! Run: `cargo bench -p camera-pose --bench pnp`.

#![allow(clippy::unwrap_used)] // a bench, like a test, may stop on a broken setup

use camera_pose::{BeaconLayout, Camera, CameraConfig, PoseConfig, PoseEstimator};
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
    c.bench_function("pnp_4_beacons_warm", |b| {
        b.iter(|| black_box(est.estimate(black_box(&obs))))
    });
}

criterion_group!(benches, bench_pnp);
criterion_main!(benches);

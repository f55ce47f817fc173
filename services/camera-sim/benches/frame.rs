//! Cost of one camera frame, per stage (goal: render and detect together
//! ≤ 1 ms per 512×512 frame on one core).
//!
//! - `render_512`: the renderer on the paper's geometry (parent 9 m ahead,
//!   a second vehicle's lamps and hull beside it).
//! - `render_512_crowd_100`: the same in the middle of a 10 × 10 grid of
//!   vehicles 8 m apart.
//! - `detect_512`: thresholds, connected components and centroids on that frame.
//! - `identify_4`: which blob is which beacon (tracking gate).
//! - `frame_512`: all three plus the PnP, as the two processes do per frame.
//!
//! Run: `cargo bench -p camera-sim --bench frame` (criterion prints the time per call).

#![allow(clippy::unwrap_used)] // a bench, like a test, may stop on a broken setup

use camera_pose::{
    BeaconLayout, CameraConfig, DetectConfig, Detector, HullConfig, Identifier, PoseConfig,
    PoseEstimator,
};
use camera_sim::{OpticsConfig, Renderer};
use criterion::{criterion_group, criterion_main, Criterion};
use nalgebra::{Isometry3, Vector3};
use std::hint::black_box;

fn bench_frame(c: &mut Criterion) {
    let cam_cfg = CameraConfig::default();
    let layout = BeaconLayout::default();
    let mut r = Renderer::new(
        &cam_cfg,
        &layout,
        &HullConfig::default(),
        &OpticsConfig::default(),
    )
    .unwrap();
    let pose = |x: f64, y: f64| Isometry3::new(Vector3::new(x, y, 10.0), Vector3::zeros());
    let scene = [pose(0.0, 0.0), pose(8.0, 4.0), pose(8.0, -4.0)];
    let (w, h) = (r.width(), r.height());
    let mut img = vec![0u8; w * h];
    c.bench_function("render_512", |b| {
        let mut seed = 0;
        b.iter(|| {
            seed += 1;
            black_box(r.render(black_box(&scene), 0, Some(1), seed, &mut img))
        })
    });
    // A crowd: the camera in the middle of a 10 × 10 grid 8 m apart (a
    // 100-vehicle formation), every hull and lamp in reach drawn.
    let crowd: Vec<Isometry3<f64>> = (0..100)
        .map(|i| {
            pose(
                8.0 * f64::from(i / 10) - 40.0,
                8.0 * f64::from(i % 10) - 36.0,
            )
        })
        .collect();
    c.bench_function("render_512_crowd_100", |b| {
        let mut seed = 0;
        b.iter(|| {
            seed += 1;
            black_box(r.render(black_box(&crowd), 44, Some(54), seed, &mut img))
        })
    });
    let cfg = DetectConfig::default();
    let mut det = Detector::new(&cfg).unwrap();
    r.render(&scene, 0, Some(1), 1, &mut img);
    assert_eq!(det.detect(&img, w, h).len(), 8);
    c.bench_function("detect_512", |b| {
        b.iter(|| black_box(det.detect(black_box(&img), w, h).len()))
    });
    let id = Identifier::new(&cfg, &layout, r.camera(), 4);
    let truth = scene[0].inverse() * scene[1];
    let blobs = det.detect(&img, w, h).to_vec();
    assert!(id
        .identify(&blobs, &truth, camera_pose::Prior::Tracking)
        .failure
        .is_none());
    c.bench_function("identify_4", |b| {
        b.iter(|| black_box(id.identify(black_box(&blobs), &truth, camera_pose::Prior::Tracking)))
    });
    let mut est = PoseEstimator::new(&PoseConfig::default(), &cam_cfg, &layout).unwrap();
    c.bench_function("frame_512", |b| {
        let mut seed = 0;
        b.iter(|| {
            seed += 1;
            r.render(&scene, 0, Some(1), seed, &mut img);
            let blobs = det.detect(&img, w, h);
            let got = id.identify(blobs, &truth, camera_pose::Prior::Tracking);
            black_box(est.estimate(&got.observation))
        })
    });
}

criterion_group!(benches, bench_frame);
criterion_main!(benches);

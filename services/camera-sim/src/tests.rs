//! The renderer alone, and the whole chain it feeds: render → detect →
//! identify → PnP, checked against the scene's truth.

use camera_pose::{
    BeaconLayout, CameraConfig, DetectConfig, Detector, HullConfig, Identifier, NoMatch,
    PoseConfig, PoseEstimator,
};
use nalgebra::{Isometry3, Vector3};
use proptest::prelude::*;

use crate::{OpticsConfig, Renderer};

const W: usize = 512;

fn renderer(optics: &OpticsConfig) -> Renderer {
    Renderer::new(
        &CameraConfig::default(),
        &BeaconLayout::default(),
        &HullConfig::default(),
        optics,
    )
    .unwrap()
}

fn pose(x: f64, y: f64, z: f64, yaw_deg: f64) -> Isometry3<f64> {
    Isometry3::new(Vector3::new(x, y, z), Vector3::z() * yaw_deg.to_radians())
}

/// Where the camera sees each of the parent's beacons (noise-free).
fn truth_pixels(follower: &Isometry3<f64>, parent: &Isometry3<f64>) -> Vec<Option<[f64; 2]>> {
    let cam = camera_pose::Camera::new(&CameraConfig::default()).unwrap();
    let cw = cam.camera_in_world(follower);
    BeaconLayout::default()
        .points()
        .map(|b| cam.project(&cw.inverse_transform_point(&(parent * b))))
        .collect()
}

#[test]
fn rendering_is_deterministic_for_a_seed_and_noisy_across_seeds() {
    let mut r = renderer(&OpticsConfig::default());
    let poses = [pose(0.0, 0.0, 10.0, 0.0), pose(9.0, 2.0, 10.0, 0.0)];
    let (mut a, mut b, mut c) = (vec![0u8; W * W], vec![0u8; W * W], vec![0u8; W * W]);
    r.render(&poses, 0, Some(1), 5, &mut a);
    r.render(&poses, 0, Some(1), 5, &mut b);
    r.render(&poses, 0, Some(1), 6, &mut c);
    assert_eq!(a, b);
    assert_ne!(a, c);
    // The background is the veiling light with noise, brighter at the top.
    let mean = |rows: std::ops::Range<usize>| {
        let px = &a[rows.start * W..rows.end * W];
        px.iter().map(|&p| f64::from(p)).sum::<f64>() / px.len() as f64
    };
    let (top, bottom) = (mean(0..32), mean(480..512));
    assert!(top > bottom + 4.0, "top {top}, bottom {bottom}");
    assert!((mean(240..272) - 18.0).abs() < 2.0);
}

#[test]
fn lamps_land_where_the_pinhole_puts_them() {
    let mut r = renderer(&OpticsConfig::default());
    let follower = pose(0.0, 0.0, 10.0, 0.0);
    let parent = pose(8.0, 2.5, 10.5, 5.0);
    let mut img = vec![0u8; W * W];
    let stats = r.render(&[follower, parent], 0, Some(1), 1, &mut img);
    assert_eq!(stats.target_lamps, 4);
    let mut det = Detector::new(&DetectConfig::default()).unwrap();
    let blobs = det.detect(&img, W, W).to_vec();
    assert_eq!(blobs.len(), 4, "{blobs:?}");
    for px in truth_pixels(&follower, &parent).into_iter().flatten() {
        let d = blobs
            .iter()
            .map(|b| (b.centroid[0] - px[0]).hypot(b.centroid[1] - px[1]))
            .fold(f64::INFINITY, f64::min);
        assert!(d < 0.3, "centroid {d} px from the projection {px:?}");
    }
}

#[test]
fn visibility_comes_from_the_optics_not_a_cut_off() {
    // The paper's water: 12 m. Lamps at 10 m are found, at 17 m they are not.
    let mut r = renderer(&OpticsConfig::default());
    let mut det = Detector::new(&DetectConfig::default()).unwrap();
    let follower = pose(0.0, 0.0, 10.0, 0.0);
    let mut img = vec![0u8; W * W];
    r.render(
        &[follower, pose(10.0, 0.0, 10.0, 0.0)],
        0,
        Some(1),
        2,
        &mut img,
    );
    assert_eq!(det.detect(&img, W, W).len(), 4);
    r.render(
        &[follower, pose(17.0, 0.0, 10.0, 0.0)],
        0,
        Some(1),
        2,
        &mut img,
    );
    assert_eq!(det.detect(&img, W, W).len(), 0);
    // Murkier water (6 m): the same 10 m lamps vanish.
    let murky = Renderer::new(
        &CameraConfig {
            visibility_range_m: 6.0,
            ..CameraConfig::default()
        },
        &BeaconLayout::default(),
        &HullConfig::default(),
        &OpticsConfig::default(),
    );
    let mut murky = murky.unwrap();
    assert!(murky.attenuation_per_m() > r.attenuation_per_m());
    murky.render(
        &[follower, pose(10.0, 0.0, 10.0, 0.0)],
        0,
        Some(1),
        2,
        &mut img,
    );
    assert_eq!(det.detect(&img, W, W).len(), 0);
}

#[test]
fn a_hull_in_between_hides_the_lamps_and_shows_dark() {
    let mut r = renderer(&OpticsConfig::default());
    let follower = pose(0.0, 0.0, 10.0, 0.0);
    let parent = pose(10.0, 0.0, 10.0, 0.0);
    // A third vehicle across the line of sight, 5 m ahead.
    let blocker = pose(5.0, 0.0, 10.0, 90.0);
    let mut img = vec![0u8; W * W];
    let stats = r.render(&[follower, parent, blocker], 0, Some(1), 3, &mut img);
    assert_eq!(stats.hulls, 2);
    assert_eq!(stats.target_lamps, 0);
    // The blocker's own lamps face aft (west here, across the view): not seen.
    let centre = img[256 * W + 256];
    assert!(
        centre < 12,
        "the hull's pixel at the image centre is {centre}"
    );
}

#[test]
fn another_vehicles_lamps_next_to_the_parents_make_the_frame_ambiguous_or_are_gated_out() {
    let mut r = renderer(&OpticsConfig::default());
    let follower = pose(0.0, 0.0, 10.0, 0.0);
    let parent = pose(8.0, 0.0, 10.0, 0.0);
    let cam_cfg = CameraConfig::default();
    let cam = camera_pose::Camera::new(&cam_cfg).unwrap();
    let layout = BeaconLayout::default();
    let cfg = DetectConfig::default();
    let id = Identifier::new(&cfg, &layout, &cam, 4);
    let mut det = Detector::new(&cfg).unwrap();
    let mut img = vec![0u8; W * W];
    let truth_rel = follower.inverse() * parent;

    // A distractor far to the side: outside the tracking gate, identified.
    let far = pose(8.0, 3.5, 10.0, 0.0);
    r.render(&[follower, parent, far], 0, Some(1), 4, &mut img);
    let blobs = det.detect(&img, W, W).to_vec();
    assert_eq!(blobs.len(), 8);
    let got = id.identify(&blobs, &truth_rel, camera_pose::Prior::Tracking);
    assert_eq!(got.failure, None);
    assert_eq!(got.observation.visible_count(), 4);
    for (k, px) in truth_pixels(&follower, &parent).into_iter().enumerate() {
        let px = px.unwrap();
        let m = got.observation.pixels[k];
        assert!((m[0] - px[0]).hypot(m[1] - px[1]) < 0.5, "beacon {k}");
    }

    // A distractor as near to the prediction as the parent (the prior is
    // halfway between them): ambiguous, never a guess.
    let twin = pose(8.0, 1.2, 10.0, 0.0);
    r.render(&[follower, parent, twin], 0, Some(1), 4, &mut img);
    let blobs = det.detect(&img, W, W).to_vec();
    assert_eq!(blobs.len(), 8);
    let halfway = follower.inverse() * pose(8.0, 0.6, 10.0, 0.0);
    assert_eq!(
        id.identify(&blobs, &halfway, camera_pose::Prior::Nominal)
            .failure,
        Some(NoMatch::Ambiguous)
    );

    // Nothing there: too few.
    r.render(
        &[follower, pose(30.0, 0.0, 10.0, 0.0)],
        0,
        Some(1),
        4,
        &mut img,
    );
    let blobs = det.detect(&img, W, W).to_vec();
    assert_eq!(
        id.identify(&blobs, &truth_rel, camera_pose::Prior::Tracking)
            .failure,
        Some(NoMatch::TooFew)
    );
}

/// The whole chain on one frame; returns the position error, m, if a fix came out.
fn chain_error(
    follower: &Isometry3<f64>,
    parent: &Isometry3<f64>,
    prior: &Isometry3<f64>,
    seed: u64,
) -> Option<f64> {
    let cam_cfg = CameraConfig::default();
    let layout = BeaconLayout::default();
    let mut r = renderer(&OpticsConfig::default());
    let cam = camera_pose::Camera::new(&cam_cfg).unwrap();
    let cfg = DetectConfig::default();
    let mut det = Detector::new(&cfg).unwrap();
    let id = Identifier::new(&cfg, &layout, &cam, 4);
    let mut est = PoseEstimator::new(&PoseConfig::default(), &cam_cfg, &layout).unwrap();
    let mut img = vec![0u8; W * W];
    r.render(&[*follower, *parent], 0, Some(1), seed, &mut img);
    let blobs = det.detect(&img, W, W).to_vec();
    let got = id.identify(&blobs, prior, camera_pose::Prior::Nominal);
    got.failure.is_none().then_some(())?;
    let e = est.estimate_among(&got.observation, &got.runners_up[..got.runners_up_count]);
    if !e.valid {
        return None;
    }
    let truth = follower.inverse() * parent;
    Some((e.parent_in_body.translation.vector - truth.translation.vector).norm())
}

#[test]
fn the_chain_from_pixels_to_pose_is_accurate_at_the_papers_ranges() {
    // F1 behind L in the paper: 8 m back, 4 m to port; the prior is the
    // nominal slot, half a metre off in each axis and 5° off in heading.
    let follower = pose(0.0, 0.0, 10.0, 0.0);
    let parent = pose(8.0, 4.0, 10.0, 3.0);
    let prior = follower.inverse() * pose(7.5, 4.5, 10.5, -2.0);
    let mut errs: Vec<f64> = (0..20)
        .map(|s| chain_error(&follower, &parent, &prior, s).expect("a fix on every frame"))
        .collect();
    errs.sort_by(f64::total_cmp);
    let p50 = errs[errs.len() / 2];
    assert!(p50 < 0.15, "median position error {p50} m over {errs:?}");
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    /// Anywhere the parent is in view within the water's visibility, with
    /// a prior a metre off, the chain finds it or says it cannot; a fix it
    /// gives is within 0.1 m per metre of range.
    #[test]
    fn the_chain_never_guesses_far_off(
        x in 3.0f64..11.0, y in -3.0f64..3.0, z in -1.5f64..1.5, yaw in -30.0f64..30.0,
        dx in -1.0f64..1.0, dy in -1.0f64..1.0, seed in 0u64..1000,
    ) {
        let follower = pose(0.0, 0.0, 10.0, 0.0);
        let parent = pose(x, y, 10.0 + z, yaw);
        let prior = follower.inverse() * pose(x + dx, y + dy, 10.0 + z, yaw + 5.0);
        if let Some(err) = chain_error(&follower, &parent, &prior, seed) {
            let range = (x * x + y * y + z * z).sqrt();
            prop_assert!(err < 0.1 * range, "error {} m at {} m", err, range);
        }
    }
}

/// Found by `the_chain_never_guesses_far_off`, with a prior a metre off:
/// four lamps in a near parallelogram, whose half-turn fits as well as the
/// pattern (taken, 2.3 m off at 5.6 m); and a close parent seen from aside,
/// one beacon just outside its gate around the prior, where a wrong
/// identity fitted best (0.56 m off at 4.5 m); and a parent level with
/// the camera, three lamps on one image row, two of them swapped by the
/// prior's view (0.66 m off at 6.4 m; the 2D fit prefers the swap, the 3D
/// layout does not).
#[test]
fn the_chain_never_guesses_far_off_on_the_cases_it_once_did() {
    let follower = pose(0.0, 0.0, 10.0, 0.0);
    for (x, y, z, yaw, dx, dy, must_fix) in [
        (5.331, -0.879, -1.327, 23.05, -0.431, -0.475, true),
        (4.2367, 1.0878, -1.1233, 8.624, 0.7466, -0.4520, false),
        (5.994, 2.191, 0.0, -26.648, 0.902, -0.282, false),
    ] {
        let parent = pose(x, y, 10.0 + z, yaw);
        let prior = follower.inverse() * pose(x + dx, y + dy, 10.0 + z, yaw + 5.0);
        let range = (x * x + y * y + z * z).sqrt();
        match chain_error(&follower, &parent, &prior, 0) {
            Some(err) => assert!(err < 0.1 * range, "error {err} m at {range} m"),
            None => assert!(!must_fix, "no fix at {range} m in plain view"),
        }
    }
}

//! The camera's image model end to end, with real processes: camera-sim
//! renders each follower's frames, camera-pose finds its parent in them, the
//! recorder keeps them as `sensor_msgs/msg/Image`; OpenCV (a client nobody
//! here wrote) agrees with camera-pose's centroids and poses on the recorded
//! frames, and a re-run of camera-pose against them reproduces its outputs.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use shoal_tests::*;

/// An image run of the small formation recording every frame, 12 s.
fn image_run(dir: &std::path::Path) -> std::path::PathBuf {
    image_run_for(dir, "run", 12.0)
}

/// An image run of `duration_s` recording every frame, into `dir/name`.
fn image_run_for(dir: &std::path::Path, name: &str, duration_s: f64) -> std::path::PathBuf {
    let text = small_image_scenario("vision", duration_s)
        .replace("model = \"image\"", "model = \"image\"\nrecord_hz = 10.0");
    let sc = write_scenario(dir, &format!("{name}.toml"), &text);
    let out = dir.join(name);
    run_shoal_ok(&[
        "run",
        "--quiet",
        sc.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    out
}

#[test]
fn camera_pose_finds_its_parent_in_rendered_frames_and_opencv_agrees() {
    let tmp = tempfile::tempdir().unwrap();
    let out = image_run(tmp.path());
    let s = summary(&out);
    assert_eq!(s["verdict"]["pass"], true, "{s}");
    // World and recorder; the leader's four; six per follower (camera-sim
    // and camera-pose among them).
    assert_eq!(s["processes"], 2 + 4 + 2 * 6, "a camera-sim per follower");
    for f in ["F1", "F2"] {
        let fraction = s["perception"]["leader_visible_fraction"][f]
            .as_f64()
            .unwrap();
        assert!(
            fraction > 0.95,
            "{f} saw its parent in {fraction} of the frames"
        );
    }
    // Fixes from images are far better than the point model's 1 px noise gives.
    let p95 = s["perception"]["pose_error_m"]["p95"].as_f64().unwrap();
    assert!(p95 < 0.1, "pose error p95 {p95} m");

    let rec = out.join("recording.mcap");
    for f in ["F1", "F2"] {
        let o = python()
            .arg(repo_root().join("tests/python/check_vision.py"))
            .arg(&rec)
            .arg(f)
            .output()
            .unwrap();
        assert!(
            o.status.success(),
            "OpenCV disagrees with camera-pose on {f}: {}{}",
            String::from_utf8_lossy(&o.stdout),
            String::from_utf8_lossy(&o.stderr)
        );
        let report: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        assert_eq!(report["frames"], 120, "{report}");
    }
}

#[test]
fn reruns_of_camera_pose_and_camera_sim_on_every_recorded_frame_reproduce_them() {
    let tmp = tempfile::tempdir().unwrap();
    let out = image_run(tmp.path());
    let rec = out.join("recording.mcap");
    let o = run_shoal_ok(&[
        "replay",
        rec.to_str().unwrap(),
        "--rerun",
        "camera-pose",
        "--vehicle",
        "F2",
    ]);
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(
        text.contains("no differences over 120 steps"),
        "{text}{}",
        String::from_utf8_lossy(&o.stderr)
    );
    // The renderer too: the same frames, byte for byte, from the recorded world.
    let o = run_shoal_ok(&[
        "replay",
        rec.to_str().unwrap(),
        "--rerun",
        "camera-sim",
        "--vehicle",
        "F1",
    ]);
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(
        text.contains("no differences over 120 steps (/F1/image: 120)"),
        "{text}{}",
        String::from_utf8_lossy(&o.stderr)
    );
    // And the whole recording plays back onto shared memory, frames included.
    let o = run_shoal_ok(&["replay", rec.to_str().unwrap(), "--speed", "0", "--quiet"]);
    assert!(String::from_utf8_lossy(&o.stdout).contains("replayed"));
}

#[test]
fn rendering_is_deterministic_in_lockstep() {
    let tmp = tempfile::tempdir().unwrap();
    let hashes: Vec<_> = ["a", "b"]
        .iter()
        .map(|n| {
            let out = image_run_for(tmp.path(), n, 5.0);
            recordings::Recording::open(&out.join("recording.mcap"))
                .unwrap()
                .message_hashes()
        })
        .collect();
    let rec = recordings::Recording::open(&tmp.path().join("a/recording.mcap")).unwrap();
    let frames = rec
        .inspect()
        .channels
        .iter()
        .filter(|c| c.topic.ends_with("/image"))
        .map(|c| c.messages)
        .sum::<u64>();
    assert_eq!(frames, 2 * 50, "every frame of both followers recorded");
    assert_eq!(hashes[0].len(), hashes[1].len());
    let first = hashes[0].iter().zip(&hashes[1]).position(|(a, b)| a != b);
    assert_eq!(
        first, None,
        "same seed, a different message (frames included) at {first:?}"
    );
}

//! `shoal bench vision`: the camera chain from rendered images against the
//! point model, frame by frame, with no processes: how often each gives a
//! fix and how far it is from the truth, over ranges and turbidities, and
//! what a frame costs (render, detect, identify and PnP).

use std::time::Instant;

use anyhow::Context;
use camera_pose::{
    BeaconLayout, Camera, CameraConfig, DetectConfig, Detector, HullConfig, Identifier, PoseConfig,
    PoseEstimator,
};
use camera_sim::{OpticsConfig, Renderer};
use nalgebra::{Isometry3, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Options of `shoal bench vision`.
#[derive(Debug, clap::Args)]
pub struct VisionCmd {
    /// Frames per range and visibility.
    #[arg(long, default_value_t = 200, value_parser = clap::value_parser!(u32).range(1..))]
    pub frames: u32,
    /// Ranges from the camera to the parent's stern lamps, m.
    #[arg(long, value_delimiter = ',', default_value = "3,5,7,9,11,13,15")]
    pub ranges: Vec<f64>,
    /// Water visibilities (each sets the attenuation, see `[optics]`), m.
    #[arg(long, value_delimiter = ',', default_value = "8,12,16")]
    pub visibility: Vec<f64>,
    /// Seed of the scene's random offsets and the noise.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
}

/// What one (range, visibility) cell measured for one model.
#[derive(Debug, Default, Clone)]
struct Cell {
    fixes: usize,
    frames: usize,
    errors_m: Vec<f64>,
}

impl Cell {
    fn add(&mut self, err: Option<f64>) {
        self.frames += 1;
        if let Some(e) = err {
            self.fixes += 1;
            self.errors_m.push(e);
        }
    }

    fn row(&mut self) -> String {
        self.errors_m.sort_by(f64::total_cmp);
        let q = |p: f64| {
            if self.errors_m.is_empty() {
                "-".to_string()
            } else {
                let i = ((self.errors_m.len() - 1) as f64 * p).round() as usize;
                format!("{:.3}", self.errors_m[i])
            }
        };
        format!(
            "{:>5.0} % {:>7} {:>7}",
            100.0 * self.fixes as f64 / self.frames.max(1) as f64,
            q(0.5),
            q(0.95)
        )
    }
}

/// Runs the benchmark and prints its tables.
pub fn run(cmd: VisionCmd) -> anyhow::Result<()> {
    let layout = BeaconLayout::default();
    let hull = HullConfig::default();
    let optics = OpticsConfig::default();
    let pose_cfg = PoseConfig::default();
    let det_cfg = DetectConfig::default();
    println!(
        "# camera chain: images (render → detect → identify → PnP) against the point model, {} frames per cell",
        cmd.frames
    );
    println!("# fix = frames with a valid fix; error = |parent position − truth|, m (p50, p95);");
    println!("# the beacons are identified from a prediction 0.2 m and 3° off the truth (tracking gate);");
    println!(
        "# the point model has the scenario default's 1 px noise and a hard visibility cut-off"
    );
    println!();
    println!(
        "| visibility m | c 1/m | range m | images: fix    p50     p95 | point: fix    p50     p95 |"
    );
    println!("|---|---|---|---|---|");
    let mut costs: Vec<(f64, f64)> = Vec::new();
    for &vis in &cmd.visibility {
        let cam_cfg = CameraConfig {
            visibility_range_m: vis,
            ..CameraConfig::default()
        };
        let mut renderer = Renderer::new(&cam_cfg, &layout, &hull, &optics)
            .with_context(|| format!("visibility {vis} m"))?;
        let camera = Camera::new(&cam_cfg)?;
        let (w, h) = (renderer.width(), renderer.height());
        let mut img = vec![0u8; w * h];
        let mut detector = Detector::new(&det_cfg)?;
        let identifier = Identifier::new(&det_cfg, &layout, &camera, pose_cfg.min_beacons);
        for &range in &cmd.ranges {
            let mut rng = ChaCha8Rng::seed_from_u64(cmd.seed ^ (range * 1e3) as u64);
            let mut from_images = Cell::default();
            let mut from_points = Cell::default();
            let mut est_img = PoseEstimator::new(&pose_cfg, &cam_cfg, &layout)?;
            let mut est_pt = PoseEstimator::new(&pose_cfg, &cam_cfg, &layout)?;
            for frame in 0..cmd.frames {
                // The parent ahead, its stern lamps about `range` from the
                // camera, a little off the axis and turned a little.
                let lateral: f64 = rng.random_range(-0.15..0.15) * range;
                let vertical: f64 = rng.random_range(-0.08..0.08) * range;
                let yaw: f64 = rng.random_range(-10.0f64..10.0).to_radians();
                let x = 1.4
                    + 1.25
                    + (range * range - lateral * lateral - vertical * vertical)
                        .max(1.0)
                        .sqrt();
                let follower = Isometry3::translation(0.0, 0.0, 10.0);
                let parent = Isometry3::new(
                    Vector3::new(x, lateral, 10.0 + vertical),
                    Vector3::z() * yaw,
                );
                let truth = follower.inverse() * parent;
                let scene = [follower, parent];
                // What camera-pose would predict from its previous fix: the
                // truth, off by up to 0.2 m in each axis and 3° in heading.
                let off = Vector3::new(
                    rng.random_range(-0.2..0.2),
                    rng.random_range(-0.2..0.2),
                    rng.random_range(-0.2..0.2),
                );
                let prior = truth
                    * Isometry3::new(
                        off,
                        Vector3::z() * rng.random_range(-3.0f64..3.0).to_radians(),
                    );

                let t0 = Instant::now();
                renderer.render(
                    &scene,
                    0,
                    Some(1),
                    cmd.seed.wrapping_add(u64::from(frame)),
                    &mut img,
                );
                let t1 = Instant::now();
                let blobs = detector.detect(&img, w, h);
                let got = identifier.identify(blobs, &prior, camera_pose::Prior::Tracking);
                let fix = if got.failure.is_none() {
                    let e = est_img.estimate(&got.observation);
                    e.valid.then(|| {
                        (e.parent_in_body.translation.vector - truth.translation.vector).norm()
                    })
                } else {
                    None
                };
                let t2 = Instant::now();
                costs.push(((t1 - t0).as_secs_f64() * 1e6, (t2 - t1).as_secs_f64() * 1e6));
                from_images.add(fix);

                let obs = camera.observe(&follower, &parent, &layout, &[], &mut rng);
                let e = est_pt.estimate(&obs);
                from_points.add(e.valid.then(|| {
                    (e.parent_in_body.translation.vector - truth.translation.vector).norm()
                }));
            }
            println!(
                "| {vis:>4.0} | {:.3} | {range:>4.0} | {} | {} |",
                renderer.attenuation_per_m(),
                from_images.row(),
                from_points.row()
            );
        }
    }
    let median = |mut v: Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v.get(v.len() / 2).copied().unwrap_or(0.0)
    };
    let render = median(costs.iter().map(|c| c.0).collect());
    let rest = median(costs.iter().map(|c| c.1).collect());
    println!();
    println!(
        "# cost per 512×512 frame on one core (median of {} frames)",
        costs.len()
    );
    println!("render {render:.0} µs; detect + identify + PnP {rest:.0} µs; together {:.0} µs (goal ≤ 1000)", render + rest);
    Ok(())
}

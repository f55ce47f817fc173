//! The renderer: one 8-bit mono frame of the scene, written in place.

use camera_pose::{BeaconLayout, Camera, CameraConfig, HullConfig};
use nalgebra::{Isometry3, Point3};
use rand::rngs::SmallRng;
use rand::{RngCore, SeedableRng};

use crate::optics::{OpticsConfig, OpticsError};

/// Entries of the noise tables (a 10-bit index per pixel).
const NOISE_LEVELS: usize = 1024;
/// Horizontal bands of the backscatter gradient (one noise table each).
const BANDS: usize = 16;
/// Largest half-width of a lamp's patch, px (a glow is cut at 3.5 σ or this).
const MAX_PATCH_RADIUS: i64 = 48;

/// What one frame shows (counts for logs and tests; no truth reaches the
/// image sample itself).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct FrameStats {
    /// Lamps drawn (every vehicle's, in view, shining towards the camera, unoccluded).
    pub lamps: u32,
    /// Lamps of the vehicle the caller named as the target (the parent).
    pub target_lamps: u32,
    /// Hulls drawn.
    pub hulls: u32,
    /// Pixels at 255.
    pub saturated: u32,
}

/// A pixel rectangle `[u0, u1) × [v0, v1)` that holds signal.
#[derive(Debug, Clone, Copy)]
struct Rect {
    u0: usize,
    u1: usize,
    v0: usize,
    v1: usize,
}

/// Renders the follower's camera frame (see [`OpticsConfig`] for the model).
///
/// Deterministic: the same scene and seed give the same bytes. Allocation
/// happens in [`Renderer::new`] only.
#[derive(Debug, Clone)]
pub struct Renderer {
    camera: Camera,
    layout: BeaconLayout,
    hull: HullConfig,
    optics: OpticsConfig,
    /// The water's attenuation, 1/m.
    c: f64,
    width: usize,
    height: usize,
    /// Noise-free backscatter of each band, DN.
    band_dn: [f64; BANDS],
    /// Per band: the quantised background plus noise, by noise index.
    band_lut: Vec<[u8; NOISE_LEVELS]>,
    /// Standard-normal quantiles, by noise index.
    z: Vec<f32>,
    /// Signal above (or, for hulls, below) the background, DN; zero outside `dirty`.
    signal: Vec<f32>,
    dirty: Vec<Rect>,
    /// Scratch: the occluding hulls of one frame (vehicle, axis ends).
    capsules: Vec<(usize, Point3<f64>, Point3<f64>)>,
    /// Scratch: the separable Gaussian weights of one patch.
    gu: Vec<f64>,
    gv: Vec<f64>,
    cos_half: f64,
    cos_soft: f64,
}

impl Renderer {
    /// Builds the renderer for a camera, the beacon layout every vehicle
    /// carries, the hull shape and the optics.
    pub fn new(
        camera: &CameraConfig,
        layout: &BeaconLayout,
        hull: &HullConfig,
        optics: &OpticsConfig,
    ) -> Result<Self, OpticsError> {
        optics.validate()?;
        let c = optics.attenuation(camera.visibility_range_m)?;
        let cam = Camera::new(camera).map_err(|e| OpticsError::InvalidConfig {
            key: "camera",
            reason: e.to_string(),
        })?;
        let width = camera.width_px as usize;
        let height = camera.height_px as usize;
        let z: Vec<f32> = (0..NOISE_LEVELS)
            .map(|k| inverse_normal_cdf((k as f64 + 0.5) / NOISE_LEVELS as f64) as f32)
            .collect();
        let mut band_dn = [0.0; BANDS];
        let mut band_lut = vec![[0u8; NOISE_LEVELS]; BANDS];
        for (b, lut) in band_lut.iter_mut().enumerate() {
            // Band centre from the top (−1) to the bottom (+1).
            let y = (b as f64 + 0.5) / BANDS as f64 * 2.0 - 1.0;
            let dn = optics.backscatter_dn * (1.0 - optics.backscatter_gradient * y);
            band_dn[b] = dn;
            let sd = optics.noise_sigma_dn(dn);
            for (k, v) in lut.iter_mut().enumerate() {
                *v = quantise(dn + sd * f64::from(z[k]));
            }
        }
        let half = layout.emission_half_angle_deg.to_radians();
        let soft = optics.cone_soft_deg.to_radians().min(half);
        Ok(Self {
            camera: cam,
            layout: layout.clone(),
            hull: hull.clone(),
            optics: optics.clone(),
            c,
            width,
            height,
            band_dn,
            band_lut,
            z,
            signal: vec![0.0; width * height],
            dirty: Vec::with_capacity(64),
            capsules: Vec::with_capacity(ipc_types::MAX_VEHICLES),
            gu: vec![0.0; 2 * MAX_PATCH_RADIUS as usize + 1],
            gv: vec![0.0; 2 * MAX_PATCH_RADIUS as usize + 1],
            cos_half: half.cos(),
            cos_soft: (half - soft).cos(),
        })
    }

    /// The water's attenuation coefficient `c`, 1/m.
    pub fn attenuation_per_m(&self) -> f64 {
        self.c
    }

    /// Image width, px.
    pub fn width(&self) -> usize {
        self.width
    }

    /// Image height, px.
    pub fn height(&self) -> usize {
        self.height
    }

    /// The camera.
    pub fn camera(&self) -> &Camera {
        &self.camera
    }

    /// Renders the frame of the camera on vehicle `own` (body → NED poses of
    /// every vehicle in `vehicles`) into `out` (`width × height` bytes, row
    /// by row), with noise drawn from `seed`. `target` names the vehicle
    /// whose lamps are counted in [`FrameStats::target_lamps`].
    ///
    /// # Panics
    /// Never; `out` shorter than the image is filled as far as it goes.
    pub fn render(
        &mut self,
        vehicles: &[Isometry3<f64>],
        own: usize,
        target: Option<usize>,
        seed: u64,
        out: &mut [u8],
    ) -> FrameStats {
        let mut stats = FrameStats::default();
        let Some(me) = vehicles.get(own) else {
            return stats;
        };
        let cam_world = self.camera.camera_in_world(me);
        let centre = Point3::from(cam_world.translation.vector);
        // Beyond this the water hides a hull completely (contrast < 1 %)
        // and a lamp is far below the noise.
        let reach = if self.c > 0.0 {
            (4.6 / self.c).min(200.0)
        } else {
            200.0
        };

        // 1. Hulls: dark silhouettes against the veiling light.
        for (i, pose) in vehicles.iter().enumerate() {
            if i == own
                || (pose.translation.vector - centre.coords).norm() > reach + self.hull.length_m
            {
                continue;
            }
            if self.draw_hull(&cam_world, pose) {
                stats.hulls += 1;
            }
        }
        // 2. Lamps: every vehicle's (the target's and the distractors').
        let half_len = 0.5 * self.hull.length_m;
        let mut capsules = std::mem::take(&mut self.capsules);
        capsules.clear();
        capsules.extend(
            vehicles
                .iter()
                .enumerate()
                .filter(|(i, p)| {
                    *i != own
                        && (p.translation.vector - centre.coords).norm()
                            < reach + self.hull.length_m
                })
                .map(|(i, p)| {
                    (
                        i,
                        p * Point3::new(half_len, 0.0, 0.0),
                        p * Point3::new(-half_len, 0.0, 0.0),
                    )
                }),
        );
        let r2 = self.hull.radius_m * self.hull.radius_m;
        for (i, pose) in vehicles.iter().enumerate() {
            if i == own {
                continue;
            }
            let viewer = pose.inverse_transform_point(&centre);
            for k in 0..self
                .layout
                .positions_body_m
                .len()
                .min(camera_pose::MAX_BEACONS)
            {
                let b = Point3::from(self.layout.positions_body_m[k]);
                let w = pose * b;
                let range = (w - centre).norm();
                if range > reach || range < 0.05 {
                    continue;
                }
                let cone = self.cone(&b, &viewer);
                if cone <= 0.0 {
                    continue;
                }
                let p_cam = cam_world.inverse_transform_point(&w);
                let Some(px) = self.camera.project(&p_cam) else {
                    continue;
                };
                // Hidden by another vehicle's hull (a lamp's own hull does
                // not hide it: it stands proud of it).
                if capsules.iter().any(|(j, a, bb)| {
                    *j != i && camera_pose::segment_distance_sq(&centre, &w, a, bb) < r2
                }) {
                    continue;
                }
                if self.splat(px, range, cone) {
                    stats.lamps += 1;
                    if target == Some(i) {
                        stats.target_lamps += 1;
                    }
                }
            }
        }
        self.capsules = capsules;
        // 3. The frame: background with noise, then the signal's pixels.
        stats.saturated = self.compose(seed, out);
        stats
    }

    /// The lamp's relative emission towards `viewer` (both in its body
    /// frame): 1 inside the cone, fading to 0 over its soft edge.
    fn cone(&self, beacon: &Point3<f64>, viewer: &Point3<f64>) -> f64 {
        let d = viewer - beacon;
        let n = d.norm();
        if n <= 0.0 {
            return 0.0;
        }
        if self.cos_half <= -1.0 + 1e-12 {
            return 1.0;
        }
        let cos = self.layout.facing_unit().dot(&d) / n;
        if cos >= self.cos_soft {
            1.0
        } else if cos <= self.cos_half {
            0.0
        } else {
            let a = cos.clamp(-1.0, 1.0).acos();
            let (half, soft) = (self.cos_half.acos(), self.cos_soft.acos());
            ((half - a) / (half - soft)).clamp(0.0, 1.0)
        }
    }

    /// Adds one lamp at pixel `px` (range `r_m`, relative emission `cone`)
    /// into the signal. False if none of it falls on the image.
    fn splat(&mut self, px: [f64; 2], r_m: f64, cone: f64) -> bool {
        let o = &self.optics;
        let e = o.beacon_power * cone * (-self.c * r_m).exp() / (r_m * r_m);
        let f = o.core_fraction(r_m);
        let sc = o.core_sigma_px;
        let sg = o.glow_sigma_px(self.c, r_m);
        let tau = std::f64::consts::TAU;
        let a_core = e * f / (tau * sc * sc);
        let a_glow = e * (1.0 - f) / (tau * sg * sg);
        // Out to where the glow is 0.05 DN, within the patch limit.
        let reach = |a: f64, s: f64| {
            if a > 0.05 {
                s * (2.0 * (a / 0.05).ln()).sqrt()
            } else {
                0.0
            }
        };
        let rad = reach(a_core, sc).max(reach(a_glow, sg)).ceil() as i64;
        let rad = rad.clamp(1, MAX_PATCH_RADIUS);
        // Pixel centres are at integer + 0.5.
        let cu = px[0] - 0.5;
        let cv = px[1] - 0.5;
        let (iu, iv) = (cu.round() as i64, cv.round() as i64);
        let u0 = (iu - rad).max(0);
        let u1 = (iu + rad + 1).min(self.width as i64);
        let v0 = (iv - rad).max(0);
        let v1 = (iv + rad + 1).min(self.height as i64);
        if u0 >= u1 || v0 >= v1 {
            return false;
        }
        let (u0, u1, v0, v1) = (u0 as usize, u1 as usize, v0 as usize, v1 as usize);
        // Separable Gaussians: core and glow weights per column and row.
        let n_u = u1 - u0;
        let n_v = v1 - v0;
        let (ic, ig) = (0.5 / (sc * sc), 0.5 / (sg * sg));
        let mut gu_c = [0.0f64; 2 * MAX_PATCH_RADIUS as usize + 1];
        let mut gv_c = [0.0f64; 2 * MAX_PATCH_RADIUS as usize + 1];
        for (j, (c, g)) in gu_c[..n_u].iter_mut().zip(&mut self.gu[..n_u]).enumerate() {
            let d = (u0 + j) as f64 - cu;
            *c = (-d * d * ic).exp();
            *g = (-d * d * ig).exp();
        }
        for (j, (c, g)) in gv_c[..n_v].iter_mut().zip(&mut self.gv[..n_v]).enumerate() {
            let d = (v0 + j) as f64 - cv;
            *c = (-d * d * ic).exp();
            *g = (-d * d * ig).exp();
        }
        for (jv, v) in (v0..v1).enumerate() {
            let row = &mut self.signal[v * self.width + u0..v * self.width + u1];
            let (cvw, gvw) = (a_core * gv_c[jv], a_glow * self.gv[jv]);
            for (ju, s) in row.iter_mut().enumerate() {
                *s += (cvw * gu_c[ju] + gvw * self.gu[ju]) as f32;
            }
        }
        self.dirty.push(Rect { u0, u1, v0, v1 });
        true
    }

    /// Darkens the pixels through which the hull of a vehicle at `pose` is
    /// seen. False if it is not in view.
    fn draw_hull(&mut self, cam_world: &Isometry3<f64>, pose: &Isometry3<f64>) -> bool {
        let half = 0.5 * self.hull.length_m;
        let r = self.hull.radius_m;
        let a = cam_world.inverse_transform_point(&(pose * Point3::new(half, 0.0, 0.0)));
        let b = cam_world.inverse_transform_point(&(pose * Point3::new(-half, 0.0, 0.0)));
        let near = 0.05;
        if a.z - r <= near || b.z - r <= near {
            // Too close to draw as a silhouette (it would fill the frame):
            // not drawn; its lamps are still hidden behind it.
            return false;
        }
        // Bounding box of the capsule's projection: the projections of its
        // axis ends grown by the radius seen at the nearest end.
        let (Some(pa), Some(pb)) = (self.camera.project(&a), self.camera.project(&b)) else {
            return false;
        };
        let grow = self.camera.focal_px() * r / (a.z.min(b.z) - r) + 1.0;
        let u0 = (pa[0].min(pb[0]) - grow).floor().max(0.0) as usize;
        let u1 = ((pa[0].max(pb[0]) + grow).ceil().max(0.0) as usize).min(self.width);
        let v0 = (pa[1].min(pb[1]) - grow).floor().max(0.0) as usize;
        let v1 = ((pa[1].max(pb[1]) + grow).ceil().max(0.0) as usize).min(self.height);
        if u0 >= u1 || v0 >= v1 {
            return false;
        }
        // Per pixel, the silhouette test in the image: the pixel's distance
        // to the projected axis against the radius projected at that point's
        // depth (a capsule's outline under perspective, to within the
        // foreshortening of its ends); the water in front of the hull is
        // the distance to that point of the axis, less the radius.
        let f = self.camera.focal_px();
        let d = [pb[0] - pa[0], pb[1] - pa[1]];
        let dd = (d[0] * d[0] + d[1] * d[1]).max(1e-12);
        let mut any = false;
        for v in v0..v1 {
            let band = self.band_dn[band_of(v, self.height)];
            let y = v as f64 + 0.5;
            for u in u0..u1 {
                let x = u as f64 + 0.5;
                let t = (((x - pa[0]) * d[0] + (y - pa[1]) * d[1]) / dd).clamp(0.0, 1.0);
                let (qx, qy) = (pa[0] + t * d[0], pa[1] + t * d[1]);
                let axis = a + (b - a) * t;
                let radius_px = f * r / axis.z;
                let (ex, ey) = (x - qx, y - qy);
                if ex * ex + ey * ey < radius_px * radius_px {
                    let water = band * (1.0 - (-self.c * (axis.coords.norm() - r).max(0.0)).exp());
                    self.signal[v * self.width + u] += (water - band) as f32;
                    any = true;
                }
            }
        }
        if any {
            self.dirty.push(Rect { u0, u1, v0, v1 });
        }
        any
    }

    /// Writes the frame: the noisy background everywhere, then the pixels
    /// that hold signal; clears the signal. Returns the saturated pixels.
    fn compose(&mut self, seed: u64, out: &mut [u8]) -> u32 {
        let mut rng = SmallRng::seed_from_u64(seed);
        let (w, h) = (self.width, self.height);
        let mask = (NOISE_LEVELS - 1) as u64;
        for v in 0..h {
            let lut = &self.band_lut[band_of(v, h)];
            let Some(row) = out.get_mut(v * w..(v + 1) * w) else {
                break;
            };
            for chunk in row.chunks_mut(6) {
                let mut bits = rng.next_u64();
                for p in chunk {
                    *p = lut[(bits & mask) as usize];
                    bits >>= 10;
                }
            }
        }
        let mut saturated = 0;
        for rect in std::mem::take(&mut self.dirty) {
            for v in rect.v0..rect.v1 {
                let bg = self.band_dn[band_of(v, h)];
                for u in rect.u0..rect.u1 {
                    let i = v * w + u;
                    let s = self.signal[i];
                    if s == 0.0 {
                        continue;
                    }
                    self.signal[i] = 0.0;
                    let level = bg + f64::from(s);
                    let z = f64::from(self.z[(rng.next_u32() as u64 & mask) as usize]);
                    let q = quantise(level + self.optics.noise_sigma_dn(level) * z);
                    if let Some(p) = out.get_mut(i) {
                        *p = q;
                        saturated += u32::from(q == 255);
                    }
                }
            }
        }
        saturated
    }
}

/// The backscatter band of image row `v`.
fn band_of(v: usize, height: usize) -> usize {
    (v * BANDS / height.max(1)).min(BANDS - 1)
}

fn quantise(dn: f64) -> u8 {
    dn.round().clamp(0.0, 255.0) as u8
}

/// The standard normal quantile function (Acklam's rational
/// approximation, relative error < 1.2e-9), for `p` in (0, 1).
pub fn inverse_normal_cdf(p: f64) -> f64 {
    const A: [f64; 6] = [
        -3.969_683_028_665_376e1,
        2.209_460_984_245_205e2,
        -2.759_285_104_469_687e2,
        1.383_577_518_672_69e2,
        -3.066_479_806_614_716e1,
        2.506_628_277_459_239,
    ];
    const B: [f64; 5] = [
        -5.447_609_879_822_406e1,
        1.615_858_368_580_409e2,
        -1.556_989_798_598_866e2,
        6.680_131_188_771_972e1,
        -1.328_068_155_288_572e1,
    ];
    const C: [f64; 6] = [
        -7.784_894_002_430_293e-3,
        -3.223_964_580_411_365e-1,
        -2.400_758_277_161_838,
        -2.549_732_539_343_734,
        4.374_664_141_464_968,
        2.938_163_982_698_783,
    ];
    const D: [f64; 4] = [
        7.784_695_709_041_462e-3,
        3.224_671_290_700_398e-1,
        2.445_134_137_142_996,
        3.754_408_661_907_416,
    ];
    let p = p.clamp(1e-300, 1.0 - 1e-16);
    let tail = |q: f64| {
        (((((C[0] * q + C[1]) * q + C[2]) * q + C[3]) * q + C[4]) * q + C[5])
            / ((((D[0] * q + D[1]) * q + D[2]) * q + D[3]) * q + 1.0)
    };
    if p < 0.02425 {
        tail((-2.0 * p.ln()).sqrt())
    } else if p > 1.0 - 0.02425 {
        -tail((-2.0 * (1.0 - p).ln()).sqrt())
    } else {
        let q = p - 0.5;
        let r = q * q;
        (((((A[0] * r + A[1]) * r + A[2]) * r + A[3]) * r + A[4]) * r + A[5]) * q
            / (((((B[0] * r + B[1]) * r + B[2]) * r + B[3]) * r + B[4]) * r + 1.0)
    }
}

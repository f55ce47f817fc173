//! Beacons in the image: blobs (threshold, connected components,
//! intensity-weighted sub-pixel centroids, rejection by size and shape),
//! then which blob is which of the parent's beacons.

use nalgebra::{Isometry3, Point3};
use serde::{Deserialize, Serialize};

use crate::{BeaconLayout, BeaconObservation, Camera, CameraError, MAX_BEACONS};

/// Row bands in which the background is estimated (the water's veiling
/// light is brighter towards the surface).
const BANDS: usize = 16;
/// Most blobs kept per frame (the brightest).
pub const MAX_BLOBS: usize = 64;

/// Detection and identification settings (`[detect]`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DetectConfig {
    /// A blob's seed pixel stands this many noise σ above its band's
    /// background. Default 6.
    pub threshold_sigma: f64,
    /// ... and at least this many DN. Default 8.
    pub min_contrast_dn: f64,
    /// A blob grows over its neighbours above this fraction of the seed
    /// threshold's height over the background (hysteresis). Default 0.5.
    pub grow_fraction: f64,
    /// Smallest blob, px. Default 2.
    pub min_area_px: u32,
    /// Largest blob, px. Default 3000.
    pub max_area_px: u32,
    /// Largest ratio of a blob's long to short axis (two merged lamps, a
    /// streak). Default 2.5.
    pub max_elongation: f64,
    /// While tracking: how far the parent's beacons may be from where the
    /// previous fix puts them, px. Default 30.
    pub gate_tracking_px: f64,
    /// Without a recent fix (acquisition, from the nominal slot): the same, px. Default 150.
    pub gate_acquire_px: f64,
    /// After a lost frame the gate grows by this much per second since the
    /// last fix (up to `gate_acquire_px`), px/s. Default 60.
    pub gate_growth_px_per_s: f64,
    /// A fix younger than this predicts the pattern's shape (a similarity
    /// fit); an older one only its place (an affine fit), s. Default 1.
    pub rigid_for_s: f64,
    /// A new fix farther than this from the last one (plus
    /// `max_relative_speed_mps` per second since it) is refused: the lamps
    /// of another vehicle, not the parent, m. Default 0.5.
    pub max_jump_m: f64,
    /// How fast the parent may move relative to the follower, m/s. Default 2.
    pub max_relative_speed_mps: f64,
    /// Residuals below this are as good as equal when two identifications
    /// are compared, px. Default 0.75.
    pub residual_floor_px: f64,
    /// Two different identifications whose residuals are within this ratio
    /// (of the better one or `residual_floor_px`) are ambiguous: the frame
    /// gives no fix. Default 2.
    pub ambiguity_ratio: f64,
    /// Accepted ratio of the parent's pattern's size in the image to the
    /// predicted one (the scale of a similarity fit; the square root of an
    /// affine one's area ratio), either way: a farther vehicle's smaller
    /// pattern is not the parent. Default 1.6.
    pub max_scale_ratio: f64,
    /// Largest roll of the parent's pattern in the image against the
    /// predicted one (the rotation of the fitted map), degrees. Vehicles
    /// keep level, so a pattern turned further is a wrong identity: four
    /// lamps in a near parallelogram fit their own half-turn as well as
    /// themselves. Default 30.
    pub max_roll_deg: f64,
    /// Identifications that explain as many beacons, with a residual
    /// beyond `ambiguity_ratio` but within this ratio of the best one's,
    /// are handed on as runners-up for the pose solver to judge with the
    /// parent's 3D layout: the 2D fit cannot tell a pattern seen edge-on
    /// from its neighbour's order swapped. Default 4.
    pub verify_ratio: f64,
}

impl Default for DetectConfig {
    fn default() -> Self {
        Self {
            threshold_sigma: 6.0,
            min_contrast_dn: 8.0,
            grow_fraction: 0.5,
            min_area_px: 2,
            max_area_px: 3000,
            max_elongation: 2.5,
            gate_tracking_px: 30.0,
            gate_acquire_px: 150.0,
            gate_growth_px_per_s: 60.0,
            rigid_for_s: 1.0,
            max_jump_m: 0.5,
            max_relative_speed_mps: 2.0,
            residual_floor_px: 0.75,
            ambiguity_ratio: 2.0,
            max_scale_ratio: 1.6,
            max_roll_deg: 30.0,
            verify_ratio: 4.0,
        }
    }
}

fn invalid(key: &'static str, reason: String) -> CameraError {
    CameraError::InvalidConfig { key, reason }
}

impl DetectConfig {
    /// Checks every field; the error names the key.
    pub fn validate(&self) -> Result<(), CameraError> {
        let pos = |key: &'static str, v: f64| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(invalid(key, format!("must be > 0 and finite, got {v}")))
            }
        };
        pos("detect.threshold_sigma", self.threshold_sigma)?;
        pos("detect.min_contrast_dn", self.min_contrast_dn)?;
        pos("detect.gate_tracking_px", self.gate_tracking_px)?;
        pos("detect.gate_acquire_px", self.gate_acquire_px)?;
        pos("detect.gate_growth_px_per_s", self.gate_growth_px_per_s)?;
        pos("detect.rigid_for_s", self.rigid_for_s)?;
        pos("detect.max_jump_m", self.max_jump_m)?;
        pos("detect.max_relative_speed_mps", self.max_relative_speed_mps)?;
        pos("detect.residual_floor_px", self.residual_floor_px)?;
        if !(self.max_roll_deg > 0.0 && self.max_roll_deg <= 180.0) {
            return Err(invalid(
                "detect.max_roll_deg",
                format!("must be in (0, 180], got {}", self.max_roll_deg),
            ));
        }
        if !(self.grow_fraction > 0.0 && self.grow_fraction <= 1.0) {
            return Err(invalid(
                "detect.grow_fraction",
                format!("must be in (0, 1], got {}", self.grow_fraction),
            ));
        }
        if self.min_area_px == 0 || self.max_area_px < self.min_area_px {
            return Err(invalid(
                "detect.max_area_px",
                format!(
                    "must be >= min_area_px >= 1, got {} and {}",
                    self.max_area_px, self.min_area_px
                ),
            ));
        }
        for (key, v) in [
            ("detect.max_elongation", self.max_elongation),
            ("detect.ambiguity_ratio", self.ambiguity_ratio),
            ("detect.max_scale_ratio", self.max_scale_ratio),
            ("detect.verify_ratio", self.verify_ratio),
        ] {
            if !(v.is_finite() && v >= 1.0) {
                return Err(invalid(key, format!("must be >= 1 and finite, got {v}")));
            }
        }
        Ok(())
    }
}

/// One bright blob.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Blob {
    /// Intensity-weighted centroid `(u, v)`, px (pixel centres at `i + 0.5`).
    pub centroid: [f64; 2],
    /// Pixels in the blob.
    pub area: u32,
    /// Sum of the pixels' height over the background, DN.
    pub flux: f64,
    /// Brightest pixel.
    pub peak: u8,
    /// Long to short axis ratio, from the second moments.
    pub elongation: f64,
}

/// Finds blobs in 8-bit mono frames. Holds its scratch buffers, so a frame
/// allocates nothing once the first one has been seen.
#[derive(Debug, Clone)]
pub struct Detector {
    cfg: DetectConfig,
    mark: Vec<bool>,
    visited: Vec<u32>,
    stack: Vec<u32>,
    blobs: Vec<Blob>,
    /// Blobs refused for their size or shape in the last frame.
    pub rejected: u32,
}

impl Detector {
    /// A detector with these settings.
    pub fn new(cfg: &DetectConfig) -> Result<Self, CameraError> {
        cfg.validate()?;
        Ok(Self {
            cfg: cfg.clone(),
            mark: Vec::new(),
            visited: Vec::new(),
            stack: Vec::new(),
            blobs: Vec::with_capacity(MAX_BLOBS),
            rejected: 0,
        })
    }

    /// The blobs of a `width × height` frame stored row by row in `img`,
    /// brightest first (at most [`MAX_BLOBS`]).
    pub fn detect(&mut self, img: &[u8], width: usize, height: usize) -> &[Blob] {
        self.blobs.clear();
        self.rejected = 0;
        let n = width * height;
        if width == 0 || height == 0 || img.len() < n {
            return &self.blobs;
        }
        if self.mark.len() != n {
            self.mark = vec![false; n];
        }
        let (bg, seed_thr, grow_thr) = self.thresholds(img, width, height);
        for v in 0..height {
            let band = v * BANDS / height;
            let t = seed_thr[band];
            let row = &img[v * width..(v + 1) * width];
            let mut u = 0;
            while u < width {
                // Skip the dark run quickly.
                match row[u..].iter().position(|&p| p > t) {
                    None => break,
                    Some(k) => u += k,
                }
                let i = v * width + u;
                if !self.mark[i] {
                    self.grow(img, width, height, i, &bg, &grow_thr);
                }
                u += 1;
            }
        }
        for i in self.visited.drain(..) {
            self.mark[i as usize] = false;
        }
        self.blobs.sort_by(|a, b| {
            b.flux
                .partial_cmp(&a.flux)
                .unwrap_or(std::cmp::Ordering::Equal)
        });
        self.blobs.truncate(MAX_BLOBS);
        &self.blobs
    }

    /// Per band: the background (median), the seed threshold and the grow
    /// threshold, from every 4th pixel of every 2nd row.
    fn thresholds(
        &self,
        img: &[u8],
        width: usize,
        height: usize,
    ) -> ([f64; BANDS], [u8; BANDS], [u8; BANDS]) {
        let mut hist = [[0u32; 256]; BANDS];
        for v in (0..height).step_by(2) {
            let h = &mut hist[v * BANDS / height];
            for &p in img[v * width..(v + 1) * width].iter().step_by(4) {
                h[p as usize] += 1;
            }
        }
        let mut bg = [0.0; BANDS];
        let mut seed = [255u8; BANDS];
        let mut grow = [255u8; BANDS];
        for b in 0..BANDS {
            let h = &hist[b];
            let total: u32 = h.iter().sum();
            if total == 0 {
                // A band with no sampled row (tiny images): use the neighbour's.
                if b > 0 {
                    (bg[b], seed[b], grow[b]) = (bg[b - 1], seed[b - 1], grow[b - 1]);
                }
                continue;
            }
            let median = quantile(h, total, 0.5);
            // Noise from the lower half only (lamps sit in the upper tail):
            // the median minus the 15.9 % quantile is 1 σ of a Gaussian.
            let lo = quantile(h, total, 0.1587);
            let sigma = (median - lo).max(0.5);
            let height_dn = (self.cfg.threshold_sigma * sigma).max(self.cfg.min_contrast_dn);
            bg[b] = median;
            seed[b] = (median + height_dn).floor().clamp(0.0, 254.0) as u8;
            grow[b] = (median + self.cfg.grow_fraction * height_dn)
                .floor()
                .clamp(0.0, 254.0) as u8;
        }
        (bg, seed, grow)
    }

    /// Flood-fills the blob holding pixel `start` (8-connected, over pixels
    /// above their band's grow threshold) and keeps it if it passes.
    fn grow(
        &mut self,
        img: &[u8],
        width: usize,
        height: usize,
        start: usize,
        bg: &[f64; BANDS],
        grow_thr: &[u8; BANDS],
    ) {
        self.stack.clear();
        self.stack.push(start as u32);
        self.mark[start] = true;
        self.visited.push(start as u32);
        let (mut s, mut su, mut sv, mut suu, mut svv, mut suv) = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
        let mut area = 0u32;
        let mut peak = 0u8;
        let limit = self.cfg.max_area_px.saturating_mul(4);
        while let Some(i) = self.stack.pop() {
            let i = i as usize;
            let (u, v) = (i % width, i / width);
            let p = img[i];
            let band = v * BANDS / height;
            let w = (f64::from(p) - bg[band]).max(0.0);
            let (x, y) = (u as f64 + 0.5, v as f64 + 0.5);
            s += w;
            su += w * x;
            sv += w * y;
            suu += w * x * x;
            svv += w * y * y;
            suv += w * x * y;
            area += 1;
            peak = peak.max(p);
            if area > limit {
                // A glare that fills the frame: stop growing, refuse it below.
                continue;
            }
            for dv in [-1i64, 0, 1] {
                let nv = v as i64 + dv;
                if nv < 0 || nv >= height as i64 {
                    continue;
                }
                let nb = nv as usize * BANDS / height;
                for du in [-1i64, 0, 1] {
                    let nu = u as i64 + du;
                    if (du == 0 && dv == 0) || nu < 0 || nu >= width as i64 {
                        continue;
                    }
                    let j = nv as usize * width + nu as usize;
                    if !self.mark[j] && img[j] > grow_thr[nb] {
                        self.mark[j] = true;
                        self.visited.push(j as u32);
                        self.stack.push(j as u32);
                    }
                }
            }
        }
        if s <= 0.0 {
            return;
        }
        let (cu, cv) = (su / s, sv / s);
        let cuu = (suu / s - cu * cu).max(0.0);
        let cvv = (svv / s - cv * cv).max(0.0);
        let cuv = suv / s - cu * cv;
        let tr = cuu + cvv;
        let det = cuu * cvv - cuv * cuv;
        let disc = (0.25 * tr * tr - det).max(0.0).sqrt();
        let (l1, l2) = (0.5 * tr + disc, (0.5 * tr - disc).max(1e-3));
        let elongation = (l1 / l2).sqrt();
        let ok = area >= self.cfg.min_area_px
            && area <= self.cfg.max_area_px
            && elongation <= self.cfg.max_elongation;
        if !ok {
            self.rejected += 1;
            return;
        }
        self.blobs.push(Blob {
            centroid: [cu, cv],
            area,
            flux: s,
            peak,
            elongation,
        });
    }
}

/// The `q`-quantile of a histogram of `total` counts.
fn quantile(h: &[u32; 256], total: u32, q: f64) -> f64 {
    let want = (q * f64::from(total)).max(1.0);
    let mut acc = 0.0;
    for (k, &c) in h.iter().enumerate() {
        acc += f64::from(c);
        if acc >= want {
            return k as f64;
        }
    }
    255.0
}

/// How good the predicted pose handed to [`Identifier::identify`] is.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Prior {
    /// The previous frame's fix: the tracking gate, and the pattern must
    /// match up to a shift, scale and roll.
    Tracking,
    /// An older fix, `age_s` old: the gate grows with the age (up to the
    /// acquisition gate), and past `rigid_for_s` the pattern may distort.
    Aged {
        /// Seconds since the fix.
        age_s: f64,
    },
    /// No fix yet: the formation's nominal slot, the acquisition gate.
    Nominal,
}

/// Why identification gave no observation.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NoMatch {
    /// The predicted pose puts fewer than the needed beacons in view.
    NotInView,
    /// Too few blobs matched the parent's pattern.
    TooFew,
    /// Two different identifications fit about as well.
    Ambiguous,
}

/// The outcome of identifying the parent's beacons among the blobs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Identification {
    /// The identified beacons (index `i` is beacon `i` of the layout).
    pub observation: BeaconObservation,
    /// Blob index of each identified beacon, `u8::MAX` where none.
    pub blob_of: [u8; MAX_BEACONS],
    /// `None` when the observation is usable; the reason otherwise (then
    /// `observation` has nothing visible).
    pub failure: Option<NoMatch>,
    /// Other identifications the 2D fit could not rule out (best first),
    /// the first `runners_up_count` of them: the pose solver judges them
    /// with the identification ([`crate::PoseEstimator::estimate_among`]).
    pub runners_up: [BeaconObservation; RUNNERS_UP],
    /// How many of `runners_up` are set.
    pub runners_up_count: usize,
}

/// Most runners-up an identification hands on.
pub const RUNNERS_UP: usize = 2;

/// Identifies the parent's beacons by the layout's geometry: the beacons
/// are projected with a predicted pose (the previous fix, or the nominal
/// slot), and the blobs that reproduce their pattern near that place, up to
/// a common shift, are taken; an equally good second pattern (another
/// vehicle's lamps inside the gate) makes the frame ambiguous.
#[derive(Debug, Clone)]
pub struct Identifier {
    cfg: DetectConfig,
    layout: BeaconLayout,
    camera: Camera,
    min_beacons: usize,
}

impl Identifier {
    /// True if a fix at `fix_m` (the parent's position in the body frame)
    /// can follow one at `last_m` made `age_s` earlier: farther means
    /// another vehicle's lamps were taken for the parent's.
    pub fn plausible(
        &self,
        last_m: &nalgebra::Vector3<f64>,
        fix_m: &nalgebra::Vector3<f64>,
        age_s: f64,
    ) -> bool {
        (fix_m - last_m).norm()
            <= self.cfg.max_jump_m + self.cfg.max_relative_speed_mps * age_s.max(0.0)
    }

    /// An identifier for the parent's `layout` seen by `camera`, needing
    /// `min_beacons` beacons (the pose solver's minimum).
    pub fn new(
        cfg: &DetectConfig,
        layout: &BeaconLayout,
        camera: &Camera,
        min_beacons: usize,
    ) -> Self {
        Self {
            cfg: cfg.clone(),
            layout: layout.clone(),
            camera: camera.clone(),
            min_beacons: min_beacons.max(3),
        }
    }

    /// Identifies the beacons among `blobs` given the parent's predicted pose
    /// in the follower body frame, as good as `prior` says.
    pub fn identify(
        &self,
        blobs: &[Blob],
        predicted_parent_in_body: &Isometry3<f64>,
        prior: Prior,
    ) -> Identification {
        let mut out = Identification {
            observation: BeaconObservation {
                count: self.layout.positions_body_m.len().min(MAX_BEACONS),
                ..BeaconObservation::default()
            },
            blob_of: [u8::MAX; MAX_BEACONS],
            failure: None,
            runners_up: [BeaconObservation::default(); RUNNERS_UP],
            runners_up_count: 0,
        };
        // Predicted pixels of the beacons that should be in view.
        let body_to_cam = self.camera.camera_in_body().inverse();
        let parent_in_cam = body_to_cam * predicted_parent_in_body;
        let viewer = parent_in_cam.inverse_transform_point(&Point3::origin());
        let mut pred = [[0.0f64; 2]; MAX_BEACONS];
        let mut in_view = [false; MAX_BEACONS];
        let mut k_in = 0;
        for (k, b) in self.layout.points().enumerate() {
            if !self.layout.shines_towards(&b, &viewer) {
                continue;
            }
            if let Some(px) = self.camera.project(&(parent_in_cam * b)) {
                pred[k] = px;
                in_view[k] = true;
                k_in += 1;
            }
        }
        if k_in < self.min_beacons {
            out.failure = Some(NoMatch::NotInView);
            return out;
        }
        let ks: Vec<usize> = (0..MAX_BEACONS).filter(|&k| in_view[k]).collect();
        let (gate, rigid) = match prior {
            Prior::Tracking => (self.cfg.gate_tracking_px, true),
            Prior::Aged { age_s } => (
                (self.cfg.gate_tracking_px + self.cfg.gate_growth_px_per_s * age_s)
                    .min(self.cfg.gate_acquire_px),
                age_s <= self.cfg.rigid_for_s,
            ),
            Prior::Nominal => (self.cfg.gate_acquire_px, false),
        };
        // Which blobs may be which beacon. A recent fix predicts the
        // pattern's shape: those within the gate of its predicted pixel. An
        // old or nominal one predicts its place only, and its view of the
        // pattern may differ enough that a beacon lands outside its own
        // gate while the pattern as a whole is inside (a wrong identity
        // then fits best): the gate bounds the pattern's shift, and a
        // beacon may be as far again as the pattern's radius.
        let radius = if rigid {
            0.0
        } else {
            let shown: Vec<[f64; 2]> = ks.iter().map(|&k| pred[k]).collect();
            let c = centroid(&shown);
            shown.iter().map(|&p| dist(p, c)).fold(0.0, f64::max)
        };
        let mut options: [Vec<u8>; MAX_BEACONS] = Default::default();
        for &k in &ks {
            options[k] = blobs
                .iter()
                .enumerate()
                .take(u8::MAX as usize)
                .filter(|(_, b)| dist(b.centroid, pred[k]) <= gate + radius)
                .map(|(j, _)| j as u8)
                .collect();
        }
        // Every assignment of distinct gated blobs to the beacons (a beacon
        // may go unmatched while enough remain), scored by how well one
        // affine map takes the predicted pattern onto the blobs: it absorbs
        // what the prior gets wrong (shift, range, a few degrees of view),
        // not a wrong identity (which breaks the pattern) nor a mirror image
        // (refused by the map's orientation).
        let mut search = Search {
            blobs,
            pred: &pred,
            ks: &ks,
            options: &options,
            min: self.min_beacons,
            bounds: MapBounds {
                max_scale: self.cfg.max_scale_ratio,
                max_roll: self.cfg.max_roll_deg.to_radians(),
                max_shift: gate,
            },
            rigid,
            assign: [u8::MAX; MAX_BEACONS],
            best: Vec::new(),
            leaves: 0,
        };
        search.walk(0, 0);
        if search.leaves > MAX_LEAVES {
            out.failure = Some(NoMatch::Ambiguous);
            return out;
        }
        let mut cands = search.best;
        cands.sort_by(|a, b| b.0.cmp(&a.0).then(a.1.total_cmp(&b.1)));
        let Some(&(matched, residual, assign)) = cands.first() else {
            out.failure = Some(NoMatch::TooFew);
            return out;
        };
        // Another assignment that explains as many beacons about as well
        // (another vehicle's lamps in the gate, a stray blob): we cannot
        // tell which is the parent.
        let floor = self.cfg.residual_floor_px;
        let rival = cands[1..].iter().any(|&(m2, r2, _)| {
            m2 == matched && r2 <= self.cfg.ambiguity_ratio * residual.max(floor)
        });
        if rival {
            out.failure = Some(NoMatch::Ambiguous);
            return out;
        }
        let count = out.observation.count;
        let observe = |assign: &[u8; MAX_BEACONS]| {
            let mut o = BeaconObservation {
                count,
                ..BeaconObservation::default()
            };
            for k in 0..MAX_BEACONS {
                if assign[k] != u8::MAX {
                    o.visible[k] = true;
                    o.pixels[k] = blobs[assign[k] as usize].centroid;
                }
            }
            o
        };
        out.observation = observe(&assign);
        out.blob_of = assign;
        for &(_, _, a) in cands[1..]
            .iter()
            .filter(|&&(m2, r2, _)| {
                m2 == matched && r2 <= self.cfg.verify_ratio * residual.max(floor)
            })
            .take(RUNNERS_UP)
        {
            out.runners_up[out.runners_up_count] = observe(&a);
            out.runners_up_count += 1;
        }
        out
    }
}

/// Most assignments tried in one frame; more means a crowd of blobs in
/// the gate, which is ambiguous anyway.
const MAX_LEAVES: usize = 20_000;

/// The depth-first search over assignments of blobs to beacons.
struct Search<'a> {
    blobs: &'a [Blob],
    pred: &'a [[f64; 2]; MAX_BEACONS],
    ks: &'a [usize],
    options: &'a [Vec<u8>; MAX_BEACONS],
    min: usize,
    /// What the fitted map may do.
    bounds: MapBounds,
    /// Fit a similarity (shift, scale, roll: the prediction is recent and
    /// good) rather than an affine map (an old or nominal prediction).
    rigid: bool,
    assign: [u8; MAX_BEACONS],
    /// (matched, affine RMS residual px, assignment) of every complete one.
    best: Vec<(usize, f64, [u8; MAX_BEACONS])>,
    leaves: usize,
}

impl Search<'_> {
    fn walk(&mut self, depth: usize, matched: usize) {
        if self.leaves > MAX_LEAVES {
            return;
        }
        if depth == self.ks.len() {
            self.leaves += 1;
            if matched >= self.min {
                if let Some(r) = self.fit() {
                    self.best.push((matched, r, self.assign));
                }
            }
            return;
        }
        let k = self.ks[depth];
        for &j in &self.options[k] {
            if self.assign.contains(&j) {
                continue;
            }
            self.assign[k] = j;
            self.walk(depth + 1, matched + 1);
            self.assign[k] = u8::MAX;
        }
        // This beacon unmatched, if enough can still be.
        if matched + (self.ks.len() - depth - 1) >= self.min {
            self.walk(depth + 1, matched);
        }
    }

    /// RMS residual of the best affine map from the predicted pixels to the
    /// assigned blobs, px; `None` if the map mirrors the pattern or scales
    /// it out of bounds.
    fn fit(&self) -> Option<f64> {
        let mut p = [[0.0f64; 2]; MAX_BEACONS];
        let mut q = [[0.0f64; 2]; MAX_BEACONS];
        let mut n = 0;
        for &k in self.ks {
            let j = self.assign[k];
            if j != u8::MAX {
                p[n] = self.pred[k];
                q[n] = self.blobs[j as usize].centroid;
                n += 1;
            }
        }
        if self.rigid {
            similarity_residual(&p[..n], &q[..n], &self.bounds)
        } else {
            affine_residual(&p[..n], &q[..n], &self.bounds)
        }
    }
}

/// What a fitted map from the predicted pattern to the blobs may do.
struct MapBounds {
    /// Largest size ratio either way.
    max_scale: f64,
    /// Largest rotation, rad.
    max_roll: f64,
    /// Largest shift of the matched beacons' centroid from its
    /// prediction, px.
    max_shift: f64,
}

/// The centroid of `x` (not empty).
fn centroid(x: &[[f64; 2]]) -> [f64; 2] {
    let n = x.len() as f64;
    let s = x.iter().fold([0.0, 0.0], |a, v| [a[0] + v[0], a[1] + v[1]]);
    [s[0] / n, s[1] / n]
}

/// RMS residual of the least-squares similarity (shift, scale, rotation)
/// taking `p` onto `q`, px; `None` if it is degenerate, shifts by more
/// than `max_shift`, scales by more than `max_scale` either way or turns by
/// more than `max_roll`.
fn similarity_residual(p: &[[f64; 2]], q: &[[f64; 2]], bounds: &MapBounds) -> Option<f64> {
    let max_scale = bounds.max_scale;
    let n = p.len();
    if n < 2 {
        return None;
    }
    let (mp, mq) = (centroid(p), centroid(q));
    if dist(mp, mq) > bounds.max_shift {
        return None;
    }
    let (mut spp, mut a, mut b) = (0.0, 0.0, 0.0);
    for i in 0..n {
        let (x, y) = (p[i][0] - mp[0], p[i][1] - mp[1]);
        let (u, v) = (q[i][0] - mq[0], q[i][1] - mq[1]);
        spp += x * x + y * y;
        a += x * u + y * v;
        b += x * v - y * u;
    }
    if spp < 1e-9 {
        return None;
    }
    let (a, b) = (a / spp, b / spp);
    let scale = a.hypot(b);
    if !(scale <= max_scale && scale >= 1.0 / max_scale) || b.atan2(a).abs() > bounds.max_roll {
        return None;
    }
    let mut ss = 0.0;
    for i in 0..n {
        let (x, y) = (p[i][0] - mp[0], p[i][1] - mp[1]);
        let du = q[i][0] - mq[0] - (a * x - b * y);
        let dv = q[i][1] - mq[1] - (b * x + a * y);
        ss += du * du + dv * dv;
    }
    Some((ss / n as f64).sqrt())
}

/// RMS residual of the least-squares affine map taking `p` onto `q`, px;
/// `None` if it is degenerate, shifts by more than `max_shift`, mirrors,
/// scales area by more than
/// `max_scale²` either way, or turns by more than `max_roll` (the angle of
/// the rotation in its polar decomposition).
fn affine_residual(p: &[[f64; 2]], q: &[[f64; 2]], bounds: &MapBounds) -> Option<f64> {
    let max_scale = bounds.max_scale;
    let n = p.len();
    if n < 3 {
        return None;
    }
    let (mp, mq) = (centroid(p), centroid(q));
    if dist(mp, mq) > bounds.max_shift {
        return None;
    }
    // Centred: q − mq = A (p − mp); normal equations A = (Σ q pᵀ)(Σ p pᵀ)⁻¹.
    let (mut sxx, mut sxy, mut syy) = (0.0, 0.0, 0.0);
    let (mut ux, mut uy, mut vx, mut vy) = (0.0, 0.0, 0.0, 0.0);
    for i in 0..n {
        let (x, y) = (p[i][0] - mp[0], p[i][1] - mp[1]);
        let (u, v) = (q[i][0] - mq[0], q[i][1] - mq[1]);
        sxx += x * x;
        sxy += x * y;
        syy += y * y;
        ux += u * x;
        uy += u * y;
        vx += v * x;
        vy += v * y;
    }
    let det = sxx * syy - sxy * sxy;
    if det.abs() < 1e-9 * (sxx * syy).max(1e-12) {
        return None;
    }
    let (i11, i12, i22) = (syy / det, -sxy / det, sxx / det);
    let (a, b) = (ux * i11 + uy * i12, ux * i12 + uy * i22);
    let (c, d) = (vx * i11 + vy * i12, vx * i12 + vy * i22);
    let area = a * d - b * c;
    let s2 = max_scale * max_scale;
    if !(area > 0.0 && area <= s2 && area >= 1.0 / s2) {
        return None;
    }
    // With a positive determinant, the nearest rotation to [[a, b], [c, d]]
    // turns by atan2(c − b, a + d).
    if (c - b).atan2(a + d).abs() > bounds.max_roll {
        return None;
    }
    let mut ss = 0.0;
    for i in 0..n {
        let (x, y) = (p[i][0] - mp[0], p[i][1] - mp[1]);
        let du = q[i][0] - mq[0] - (a * x + b * y);
        let dv = q[i][1] - mq[1] - (c * x + d * y);
        ss += du * du + dv * dv;
    }
    Some((ss / n as f64).sqrt())
}

fn dist(a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - b[0]).hypot(a[1] - b[1])
}

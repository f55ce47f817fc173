//! The parent's pose from beacon pixels: PnP (eq. 2), then eqs. (3) and (1).

use nalgebra::{
    Isometry3, Matrix3, Matrix6, Point3, Rotation3, Translation3, UnitQuaternion, Vector3, Vector6,
};

use crate::config::cone_contains;
use crate::poly::{real_roots, MAX_ROOTS};
use crate::{BeaconLayout, BeaconObservation, CameraConfig, CameraError, PoseConfig, MAX_BEACONS};

/// Most P3P triples tried per call ([`PoseConfig::p3p_triples`]).
pub const MAX_P3P_TRIPLES: usize = 4;

/// Most starts refined per call: four P3P poses per triple, the POSIT pose
/// and the previous estimate.
const MAX_STARTS: usize = MAX_P3P_TRIPLES * MAX_ROOTS + 2;

/// The parent's pose as the follower's camera measured it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseEstimate {
    /// True if the fit is trustworthy: enough beacons, converged, reprojection
    /// error under the limit, unambiguous. When false, the pose fields are the
    /// identity / zero (never a guess) and `covariance` is zero; `beacons_used`,
    /// `reprojection_rms_px` and `iterations` still describe the attempt.
    pub valid: bool,
    /// Eq. (2): the parent's body frame in the camera frame, `T_L^C`
    /// (parent body → camera), i.e. `R_L^C` and `X_L^C`.
    pub parent_in_camera: Isometry3<f64>,
    /// Eq. (3): the parent in the follower body frame, `T_L^F` (parent body →
    /// follower body): `X_L^F = R_C^F X_L^C + X_C^F`, `R_L^F = R_C^F R_L^C`.
    pub parent_in_body: Isometry3<f64>,
    /// Eq. (1): the follower's position in the parent's body frame,
    /// `X_F^L = −(R_L^F)ᵀ X_L^F`, m.
    pub follower_in_parent_m: Vector3<f64>,
    /// Visible beacons the fit used.
    pub beacons_used: usize,
    /// Root-mean-square reprojection error over the used beacons' pixel
    /// coordinates (`sqrt(Σ|r_i|² / n)` with `r_i` the 2-D residual), px.
    pub reprojection_rms_px: f64,
    /// Covariance of `[position (m), rotation vector (rad)]` of the parent in
    /// the follower body frame, from `(JᵀJ)⁻¹σ²`. The rotation vector `δθ`
    /// perturbs on the left: `R_L^F ← exp([δθ]×) R_L^F`.
    pub covariance: Matrix6<f64>,
    /// Levenberg–Marquardt iterations of the chosen fit.
    pub iterations: u32,
}

impl PoseEstimate {
    fn invalid(beacons_used: usize, rms: f64, iterations: u32) -> Self {
        Self {
            valid: false,
            parent_in_camera: Isometry3::identity(),
            parent_in_body: Isometry3::identity(),
            follower_in_parent_m: Vector3::zeros(),
            beacons_used,
            reprojection_rms_px: if rms.is_finite() { rms } else { 0.0 },
            covariance: Matrix6::zeros(),
            iterations,
        }
    }
}

/// Eq. (3): `T_L^F = T_C^F · T_L^C`, i.e. `X_L^F = R_C^F X_L^C + X_C^F` and
/// `R_L^F = R_C^F R_L^C`.
pub fn parent_in_body(
    camera_in_body: &Isometry3<f64>,
    parent_in_camera: &Isometry3<f64>,
) -> Isometry3<f64> {
    let r_cf = camera_in_body.rotation;
    let x_cf = camera_in_body.translation.vector;
    let x_lc = parent_in_camera.translation.vector;
    Isometry3::from_parts(
        Translation3::from(r_cf * x_lc + x_cf),
        r_cf * parent_in_camera.rotation,
    )
}

/// Eq. (1): the follower's position in the parent's frame,
/// `X_F^L = −(R_L^F)ᵀ X_L^F`, from the parent's pose in the follower's body
/// frame.
pub fn follower_in_parent(parent_in_body: &Isometry3<f64>) -> Vector3<f64> {
    -(parent_in_body.rotation.inverse() * parent_in_body.translation.vector)
}

/// A pose candidate in the camera frame: `X^C = R B + t`.
#[derive(Debug, Clone, Copy)]
struct Fit {
    q: UnitQuaternion<f64>,
    t: Vector3<f64>,
    /// Sum of squared pixel residuals, px².
    cost: f64,
    iterations: u32,
    converged: bool,
}

/// Solves the parent's pose from beacon pixels.
///
/// # Method
///
/// Eq. (2) of the paper binds each beacon's pixel `P_i` to the parent's pose
/// in the camera frame, `X_Bi^C = R_L^C B_i + X_L^C`, `P_i = π(X_Bi^C)` with
/// `π` the pinhole projection. The pose minimises the sum of squared
/// reprojection errors `Σ |π(R B_i + t) − P_i|²` (the maximum-likelihood
/// estimate under Gaussian pixel noise), found numerically as the paper says:
///
/// 1. **Global starts.** (a) *Exhaustive P3P*: the three visible beacons that
///    span the largest triangle in the image give, by Grunert's elimination,
///    a quartic whose real roots are all the poses (up to four) that fit
///    those three exactly (derivation on the private `p3p` function; roots by a bracketing solver that cannot
///    lose a root to cancellation). (b) *POSIT* (scaled orthographic, then
///    corrected for perspective) when four or more non-coplanar beacons are
///    visible: P3P's quartic degenerates for a distant target (all bearings
///    nearly parallel), which is where POSIT is best. (c) The previous
///    estimate, refined first: while tracking, if its fit's cost is within
///    the ambiguity margin (step 3) the global starts are skipped, since no
///    other minimum could then change the choice. If nothing converges to an
///    acceptable fit, P3P is repeated on the next-largest triangles (up to
///    [`MAX_P3P_TRIPLES`]).
/// 2. **Refinement — damped Newton (Levenberg–Marquardt form)** on the
///    reprojection error of *every* visible beacon, from each start. The
///    parameters are the translation and a rotation vector `ω` applied on
///    the left, `R ← exp([ω]×) R`, about the centroid of the visible beacons
///    (which decouples rotation from translation). The exact Hessian (not
///    only Gauss–Newton's `JᵀJ`) keeps convergence quadratic in the flat,
///    curved valleys of long-range fits, where Gauss–Newton crawls.
/// 3. **Choice.** A converged fit is *acceptable* if it puts the camera
///    inside every used beacon's emission cone (widened by
///    `emission_margin_deg`): lights that shine aft cannot be seen from in
///    front. Among acceptable fits the lowest cost wins, except that fits
///    whose costs differ by less than `ambiguity_chi2 · σ²` cannot be told
///    apart by the pixels: among those, the one nearest the previous
///    estimate is taken. These two rules reject the mirrored / flipped
///    solution. With exactly three beacons every P3P pose fits exactly, so
///    without a previous estimate more than one candidate means invalid.
///
/// The covariance of `[position, rotation vector]` is `(JᵀJ)⁻¹ σ²` at the
/// solution (Gauss–Newton approximation), `σ = max(camera.noise_px,
/// pose.pixel_sigma_floor_px)`, rotated into the follower body frame.
///
/// Holds the previous valid estimate (to reject flipped solutions and to
/// warm-start) and fixed-size scratch; `estimate` does not allocate.
#[derive(Debug, Clone)]
pub struct PoseEstimator {
    cfg: PoseConfig,
    focal_px: f64,
    principal_px: [f64; 2],
    camera_in_body: Isometry3<f64>,
    sigma_px: f64,
    layout: [Point3<f64>; MAX_BEACONS],
    layout_count: usize,
    /// Unit direction the lights shine towards (parent body frame).
    facing: Vector3<f64>,
    /// Cosine of the emission half-angle plus the margin.
    cone_cos: f64,
    previous: Option<(UnitQuaternion<f64>, Vector3<f64>)>,
    // Scratch: the visible beacons of the current call, relative to their
    // centroid `centroid` (parent body frame).
    obj: [Point3<f64>; MAX_BEACONS],
    centroid: Vector3<f64>,
    pix: [[f64; 2]; MAX_BEACONS],
    n: usize,
}

impl PoseEstimator {
    /// Validates the three configs and builds the solver.
    pub fn new(
        pose: &PoseConfig,
        camera: &CameraConfig,
        layout: &BeaconLayout,
    ) -> Result<Self, CameraError> {
        pose.validate()?;
        camera.validate()?;
        layout.validate()?;
        if layout.positions_body_m.len() < pose.min_beacons {
            return Err(CameraError::InvalidConfig {
                key: "pose.min_beacons",
                reason: format!(
                    "must not exceed the {} beacons of the layout, got {}",
                    layout.positions_body_m.len(),
                    pose.min_beacons
                ),
            });
        }
        let mut pts = [Point3::origin(); MAX_BEACONS];
        let mut count = 0;
        for (slot, p) in pts.iter_mut().zip(layout.points()) {
            *slot = p;
            count += 1;
        }
        Ok(Self {
            cfg: pose.clone(),
            focal_px: camera.focal_px(),
            principal_px: camera.principal_point_px(),
            camera_in_body: camera.camera_in_body(),
            sigma_px: camera.noise_px.max(pose.pixel_sigma_floor_px),
            layout: pts,
            layout_count: count,
            facing: layout.facing_unit(),
            cone_cos: (layout.emission_half_angle_deg + pose.emission_margin_deg)
                .min(180.0)
                .to_radians()
                .cos(),
            previous: None,
            obj: [Point3::origin(); MAX_BEACONS],
            centroid: Vector3::zeros(),
            pix: [[0.0; 2]; MAX_BEACONS],
            n: 0,
        })
    }

    /// Forgets the previous estimate (after a long loss of sight, or a jump).
    pub fn reset(&mut self) {
        self.previous = None;
    }

    /// True if a previous valid estimate is held.
    pub fn has_previous(&self) -> bool {
        self.previous.is_some()
    }

    /// Copies the visible beacons into the scratch arrays, relative to their
    /// centroid (rotating about the centroid rather than the parent's origin,
    /// 1.25 m away for the default layout, decouples rotation from
    /// translation and removes the long curved valley that otherwise slows
    /// Levenberg–Marquardt at long range).
    fn load(&mut self, obs: &BeaconObservation) {
        self.n = 0;
        let count = obs.count.min(self.layout_count);
        let mut sum = Vector3::zeros();
        for i in 0..count {
            let [u, v] = obs.pixels[i];
            if obs.visible[i] && u.is_finite() && v.is_finite() {
                self.obj[self.n] = self.layout[i];
                self.pix[self.n] = [u, v];
                sum += self.layout[i].coords;
                self.n += 1;
            }
        }
        self.centroid = if self.n > 0 {
            sum / self.n as f64
        } else {
            Vector3::zeros()
        };
        for p in &mut self.obj[..self.n] {
            *p -= self.centroid;
        }
    }

    /// Parent-origin pose `(R, t)` from a centred one `(R, t')`: `t = t' − R c`.
    fn to_origin(&self, q: &UnitQuaternion<f64>, t_c: &Vector3<f64>) -> Vector3<f64> {
        t_c - q * self.centroid
    }

    /// Estimates the parent's pose from each of several identifications of
    /// one frame (the identifier's choice first, then its runners-up) and
    /// keeps the one the parent's 3D layout explains best. When the best
    /// two explain it within the ambiguity margin (`ambiguity_chi2` σ² of
    /// summed squared reprojection error) of each other, the pixels cannot
    /// tell them apart: no fix, and the previous estimate stays as it was.
    /// With one identification this is [`Self::estimate`].
    pub fn estimate_among<'a>(
        &mut self,
        first: &BeaconObservation,
        others: impl IntoIterator<Item = &'a BeaconObservation>,
    ) -> PoseEstimate {
        let mut others = others.into_iter().peekable();
        if others.peek().is_none() {
            return self.estimate(first);
        }
        let start = self.clone();
        let cost = |e: &PoseEstimate| e.reprojection_rms_px.powi(2) * e.beacons_used as f64;
        let first_estimate = self.estimate(first);
        // The best valid one (its estimate and the solver state after it),
        // and the cost of the runner-up.
        let mut best: Option<(PoseEstimate, Option<PoseEstimator>)> =
            first_estimate.valid.then_some((first_estimate, None));
        let mut second = f64::INFINITY;
        for obs in others {
            let mut solver = start.clone();
            let e = solver.estimate(obs);
            if !e.valid {
                continue;
            }
            match &best {
                Some((b, _)) if cost(b) <= cost(&e) => second = second.min(cost(&e)),
                Some((b, _)) => {
                    second = second.min(cost(b));
                    best = Some((e, Some(solver)));
                }
                None => best = Some((e, Some(solver))),
            }
        }
        let Some((e, solver)) = best else {
            return first_estimate;
        };
        let margin = self.cfg.ambiguity_chi2 * self.sigma_px * self.sigma_px;
        if second - cost(&e) < margin {
            *self = start;
            return PoseEstimate::invalid(e.beacons_used, e.reprojection_rms_px, e.iterations);
        }
        if let Some(solver) = solver {
            *self = solver;
        }
        e
    }

    /// Estimates the parent's pose from one observation. Beacons are matched
    /// by index with the layout; non-finite pixels are ignored.
    pub fn estimate(&mut self, obs: &BeaconObservation) -> PoseEstimate {
        self.load(obs);
        let n = self.n;
        if n < self.cfg.min_beacons {
            return PoseEstimate::invalid(n, 0.0, 0);
        }

        // Starts, in stages: (0) the previous estimate; (1) POSIT (good in
        // the far field, where P3P is ill-conditioned) and P3P on the
        // largest image triangles; (2) P3P on further triangles, only if
        // nothing fitted. Stage 1 is skipped while tracking when the warm
        // fit's cost is within the ambiguity margin: no other minimum could
        // then be better by more than the margin, so the choice below would
        // keep the fit nearest the previous estimate anyway.
        let margin = self.cfg.ambiguity_chi2 * self.sigma_px * self.sigma_px;
        let mut starts = [(UnitQuaternion::identity(), Vector3::zeros()); MAX_STARTS];
        let mut n_starts = 0;
        if let Some((q, t)) = self.previous {
            starts[0] = (q, t + q * self.centroid);
            n_starts = 1;
        }
        let mut triangles = [(0, 1, 2); MAX_P3P_TRIPLES];
        let n_triangles = self.largest_triangles(&mut triangles);
        let mut next_triangle = 0;
        let mut n_p3p = 0;

        let mut fits = [Fit {
            q: UnitQuaternion::identity(),
            t: Vector3::zeros(),
            cost: f64::INFINITY,
            iterations: 0,
            converged: false,
        }; MAX_STARTS];
        let mut usable = [false; MAX_STARTS];
        let mut best: Option<usize> = None;
        let mut refined = 0;
        let mut stage = 0;
        loop {
            for k in refined..n_starts {
                let (q, t) = starts[k];
                fits[k] = self.refine(q, t);
                fits[k].t = self.to_origin(&fits[k].q, &fits[k].t);
                let f = &fits[k];
                usable[k] = f.converged && f.cost.is_finite() && self.sees_the_lights(f);
                if usable[k] && best.is_none_or(|b| f.cost < fits[b].cost) {
                    best = Some(k);
                }
            }
            refined = n_starts;
            let stage_end = match stage {
                0 if best.is_some_and(|b| fits[b].cost <= margin) => break,
                0 => {
                    if let Some(start) = self.posit() {
                        starts[n_starts] = start;
                        n_starts += 1;
                    }
                    self.cfg.p3p_triples.min(n_triangles)
                }
                1 if best.is_none() && next_triangle < n_triangles => n_triangles,
                _ => break,
            };
            stage += 1;
            while next_triangle < stage_end {
                let got = self.p3p_starts(triangles[next_triangle], &mut starts[n_starts..]);
                n_starts += got;
                n_p3p += got;
                next_triangle += 1;
            }
        }
        let Some(best) = best else {
            let (cost, iters) = fits[..n_starts].iter().filter(|f| f.cost.is_finite()).fold(
                (f64::INFINITY, 0),
                |a, f| {
                    if f.cost < a.0 {
                        (f.cost, f.iterations)
                    } else {
                        a
                    }
                },
            );
            return PoseEstimate::invalid(n, (cost / n as f64).sqrt(), iters);
        };

        // Fits that the pixels cannot tell apart from the best one.
        let best_fit = fits[best];
        let mut chosen = best;
        let mut n_alternatives = 0;
        let mut nearest = f64::INFINITY;
        for (k, f) in fits[..n_starts].iter().enumerate() {
            if !(usable[k] && f.cost <= best_fit.cost + margin) {
                continue;
            }
            if k != best && pose_distance(f, &best_fit.q, &best_fit.t) > 1e-6 {
                n_alternatives += 1;
            }
            if let Some((pq, pt)) = &self.previous {
                let d = pose_distance(f, pq, pt);
                if d < nearest {
                    nearest = d;
                    chosen = k;
                }
            }
        }
        // With three beacons (zero redundancy) and no history, several exact
        // solutions are a coin toss: refuse rather than guess.
        if self.previous.is_none() && n == 3 && n_alternatives > 0 && n_p3p > 1 {
            return PoseEstimate::invalid(
                n,
                (best_fit.cost / n as f64).sqrt(),
                best_fit.iterations,
            );
        }
        let fit = fits[chosen];
        let rms = (fit.cost / n as f64).sqrt();
        if rms > self.cfg.max_reprojection_rms_px {
            return PoseEstimate::invalid(n, rms, fit.iterations);
        }

        // Covariance (JᵀJ)⁻¹σ² in the camera frame, then in the body frame.
        // Parameters of the fit: centred translation t' and ω; the origin's
        // translation is t = t' − R c, so δt = δt' + [R c]× δω.
        let rc = fit.q * self.centroid;
        let Some(model) = self.normal_equations(&fit.q, &(fit.t + rc)) else {
            return PoseEstimate::invalid(n, rms, fit.iterations);
        };
        let Some(chol) = model.jtj.cholesky() else {
            return PoseEstimate::invalid(n, rms, fit.iterations);
        };
        let cov_centred = chol.inverse() * (self.sigma_px * self.sigma_px);
        let r_cf = self.camera_in_body.rotation.to_rotation_matrix();
        let mut g = Matrix6::zeros();
        g.fixed_view_mut::<3, 3>(0, 0).copy_from(r_cf.matrix());
        g.fixed_view_mut::<3, 3>(0, 3)
            .copy_from(&(r_cf.matrix() * rc.cross_matrix()));
        g.fixed_view_mut::<3, 3>(3, 3).copy_from(r_cf.matrix());
        let covariance = g * cov_centred * g.transpose();
        if !covariance.iter().all(|c| c.is_finite()) {
            return PoseEstimate::invalid(n, rms, fit.iterations);
        }

        let parent_in_camera = Isometry3::from_parts(Translation3::from(fit.t), fit.q);
        let in_body = parent_in_body(&self.camera_in_body, &parent_in_camera);
        self.previous = Some((fit.q, fit.t));
        PoseEstimate {
            valid: true,
            parent_in_camera,
            parent_in_body: in_body,
            follower_in_parent_m: follower_in_parent(&in_body),
            beacons_used: n,
            reprojection_rms_px: rms,
            covariance,
            iterations: fit.iterations,
        }
    }

    /// The visible triples with the largest image triangles, largest first
    /// (at most [`MAX_P3P_TRIPLES`]); returns how many.
    fn largest_triangles(&self, out: &mut [(usize, usize, usize); MAX_P3P_TRIPLES]) -> usize {
        let n = self.n;
        let mut area_of = [-1.0_f64; MAX_P3P_TRIPLES];
        let mut count = 0;
        for i in 0..n {
            for j in i + 1..n {
                for k in j + 1..n {
                    let [ui, vi] = self.pix[i];
                    let [uj, vj] = self.pix[j];
                    let [uk, vk] = self.pix[k];
                    let area = ((uj - ui) * (vk - vi) - (uk - ui) * (vj - vi)).abs();
                    let mut slot = count.min(MAX_P3P_TRIPLES);
                    while slot > 0 && area > area_of[slot - 1] {
                        slot -= 1;
                    }
                    if slot < MAX_P3P_TRIPLES {
                        for m in (slot + 1..MAX_P3P_TRIPLES).rev() {
                            out[m] = out[m - 1];
                            area_of[m] = area_of[m - 1];
                        }
                        out[slot] = (i, j, k);
                        area_of[slot] = area;
                        count = (count + 1).min(MAX_P3P_TRIPLES);
                    }
                }
            }
        }
        count
    }

    /// P3P on one triple of visible beacons; writes up to four poses
    /// (centred coordinates) into `out` and returns how many.
    fn p3p_starts(
        &self,
        (i, j, k): (usize, usize, usize),
        out: &mut [(UnitQuaternion<f64>, Vector3<f64>)],
    ) -> usize {
        let f = [self.bearing(i), self.bearing(j), self.bearing(k)];
        let p = [self.obj[i], self.obj[j], self.obj[k]];
        let mut poses = [(UnitQuaternion::identity(), Vector3::zeros()); MAX_ROOTS];
        let got = p3p(&p, &f, &mut poses).min(out.len());
        out[..got].copy_from_slice(&poses[..got]);
        got
    }

    /// POSIT (DeMenthon & Davis, IJCV 1995): pose from a scaled orthographic
    /// projection, corrected iteratively for perspective. Needs four or more
    /// beacons not in one plane; returns a pose in centred coordinates.
    ///
    /// P3P's quartic degenerates as the bearings become parallel (a distant
    /// target seen under a small angle, where every depth ratio tends to 1);
    /// POSIT is at its best exactly there, so the two starts complement each
    /// other.
    fn posit(&self) -> Option<(UnitQuaternion<f64>, Vector3<f64>)> {
        let n = self.n;
        if n < 4 {
            return None;
        }
        let m0 = self.obj[0].coords;
        let mut ata = Matrix3::zeros();
        for p in &self.obj[1..n] {
            let a = p.coords - m0;
            ata += a * a.transpose();
        }
        // Refuse (nearly) coplanar beacons: the object matrix is singular.
        let eig = ata.symmetric_eigenvalues();
        let (lo, hi) = (eig.min(), eig.max());
        if !(lo > 1e-6 * hi && hi > 0.0) {
            return None;
        }
        let ata_inv = ata.try_inverse()?;
        let norm = |i: usize| {
            [
                (self.pix[i][0] - self.principal_px[0]) / self.focal_px,
                (self.pix[i][1] - self.principal_px[1]) / self.focal_px,
            ]
        };
        let [x0, y0] = norm(0);
        let mut eps = [0.0; MAX_BEACONS];
        let mut rows = (Vector3::x(), Vector3::y(), Vector3::z());
        let mut z0 = 1.0;
        for _ in 0..50 {
            let mut bi = Vector3::zeros();
            let mut bj = Vector3::zeros();
            for (m, e) in eps.iter().enumerate().take(n).skip(1) {
                let a = self.obj[m].coords - m0;
                let [x, y] = norm(m);
                bi += a * (x * (1.0 + e) - x0);
                bj += a * (y * (1.0 + e) - y0);
            }
            let vi = ata_inv * bi;
            let vj = ata_inv * bj;
            let (ni, nj) = (vi.norm(), vj.norm());
            if !(ni > 0.0 && nj > 0.0 && ni.is_finite() && nj.is_finite()) {
                return None;
            }
            let i = vi / ni;
            let j = (vj - i * vj.dot(&i)).try_normalize(1e-12)?;
            let k = i.cross(&j);
            z0 = 1.0 / (ni * nj).sqrt();
            rows = (i, j, k);
            let mut change: f64 = 0.0;
            for (p, e) in self.obj.iter().zip(eps.iter_mut()).take(n).skip(1) {
                let new = (p.coords - m0).dot(&k) / z0;
                change = change.max((new - *e).abs());
                *e = new;
            }
            if change < 1e-12 {
                break;
            }
        }
        let r = Matrix3::from_rows(&[rows.0.transpose(), rows.1.transpose(), rows.2.transpose()]);
        let rot = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(r));
        let t = Vector3::new(x0 * z0, y0 * z0, z0) - rot * m0;
        t.iter().all(|c| c.is_finite()).then_some((rot, t))
    }

    /// True if the camera, at the pose `fit` implies, is within every used
    /// beacon's emission cone widened by `emission_margin_deg`.
    fn sees_the_lights(&self, fit: &Fit) -> bool {
        if self.cone_cos <= -1.0 + 1e-12 {
            return true;
        }
        // Camera centre in the parent frame: −Rᵀ t (as eq. 1).
        let viewer = -(fit.q.inverse() * fit.t);
        self.obj[..self.n].iter().all(|b| {
            let d = viewer - (b.coords + self.centroid);
            cone_contains(&self.facing, self.cone_cos, &d)
        })
    }

    fn bearing(&self, i: usize) -> Vector3<f64> {
        Vector3::new(
            (self.pix[i][0] - self.principal_px[0]) / self.focal_px,
            (self.pix[i][1] - self.principal_px[1]) / self.focal_px,
            1.0,
        )
        .normalize()
    }

    /// The local model of the cost at a pose (centred coordinates); `None`
    /// if a beacon is not in front of the camera.
    fn normal_equations(&self, q: &UnitQuaternion<f64>, t: &Vector3<f64>) -> Option<Model> {
        let r: Matrix3<f64> = q.to_rotation_matrix().into_inner();
        let f = self.focal_px;
        let mut m = Model {
            cost: 0.0,
            jtj: Matrix6::zeros(),
            hessian: Matrix6::zeros(),
            gradient: Vector6::zeros(),
        };
        for i in 0..self.n {
            let w = r * self.obj[i].coords; // R B
            let x = w + t;
            if x.z <= 1e-9 {
                return None;
            }
            let iz = 1.0 / x.z;
            let ru = self.principal_px[0] + f * x.x * iz - self.pix[i][0];
            let rv = self.principal_px[1] + f * x.y * iz - self.pix[i][1];
            m.cost += ru * ru + rv * rv;
            // d(u, v)/dX, then d/dω = (R B) × (d/dX).
            let au = Vector3::new(f * iz, 0.0, -f * x.x * iz * iz);
            let av = Vector3::new(0.0, f * iz, -f * x.y * iz * iz);
            let cu = w.cross(&au);
            let cv = w.cross(&av);
            let ju = Vector6::new(au.x, au.y, au.z, cu.x, cu.y, cu.z);
            let jv = Vector6::new(av.x, av.y, av.z, cv.x, cv.y, cv.z);
            m.jtj += ju * ju.transpose() + jv * jv.transpose();
            m.gradient += ju * ru + jv * rv;
            // Second-order term Σ r ∇²r: the projection's curvature seen
            // through dX/dp = [I | −[w]×], plus the rotation's own curvature
            // (exp(ω)w ≈ w + ω×w + ½ω×(ω×w)) in the ω–ω block.
            let f2 = f * iz * iz;
            let mut c = Matrix3::zeros();
            c[(0, 2)] = -ru * f2;
            c[(2, 0)] = -ru * f2;
            c[(1, 2)] = -rv * f2;
            c[(2, 1)] = -rv * f2;
            c[(2, 2)] = 2.0 * f2 * iz * (ru * x.x + rv * x.y);
            // With W = −[w]×: [I W]ᵀ C [I W] = [[C, CW], [(CW)ᵀ, WᵀCW]].
            let wx = w.cross_matrix();
            let cw = -(c * wx);
            let a = au * ru + av * rv;
            let rot =
                0.5 * (a * w.transpose() + w * a.transpose()) - Matrix3::identity() * a.dot(&w);
            let mut tt = m.hessian.fixed_view_mut::<3, 3>(0, 0);
            tt += c;
            let mut tw = m.hessian.fixed_view_mut::<3, 3>(0, 3);
            tw += cw;
            let mut wt = m.hessian.fixed_view_mut::<3, 3>(3, 0);
            wt += cw.transpose();
            let mut ww = m.hessian.fixed_view_mut::<3, 3>(3, 3);
            ww += wx * cw + rot;
        }
        m.hessian += m.jtj;
        Some(m)
    }

    fn cost(&self, q: &UnitQuaternion<f64>, t: &Vector3<f64>) -> f64 {
        let r: Matrix3<f64> = q.to_rotation_matrix().into_inner();
        let f = self.focal_px;
        let mut cost = 0.0;
        for i in 0..self.n {
            let x = r * self.obj[i].coords + t;
            if x.z <= 1e-9 {
                return f64::INFINITY;
            }
            let iz = 1.0 / x.z;
            let ru = self.principal_px[0] + f * x.x * iz - self.pix[i][0];
            let rv = self.principal_px[1] + f * x.y * iz - self.pix[i][1];
            cost += ru * ru + rv * rv;
        }
        cost
    }

    /// Damped Newton (Levenberg–Marquardt form) on the reprojection error
    /// from `(q, t)`, centred coordinates.
    ///
    /// The step solves `(H + μD) δ = −g` with `H` the exact Hessian of
    /// `½Σ|r|²` (Gauss–Newton's `JᵀJ` plus `Σ r ∇²r`) and `D = diag(JᵀJ)`;
    /// `μ` follows Nielsen's rule and grows until `H + μD` is positive
    /// definite. Far from a minimum this behaves like gradient descent, close
    /// to it like Newton. Plain Gauss–Newton converges only linearly on the
    /// flat, curved valleys of long-range, noisy fits (residuals not small
    /// against the weak curvature); the exact Hessian keeps it quadratic.
    fn refine(&self, mut q: UnitQuaternion<f64>, mut t: Vector3<f64>) -> Fit {
        let tol = self.cfg.convergence_tol;
        let Some(mut m) = self.normal_equations(&q, &t) else {
            return Fit {
                q,
                t,
                cost: f64::INFINITY,
                iterations: 0,
                converged: false,
            };
        };
        let mut mu = 1e-3;
        let mut nu = 2.0;
        let mut converged = false;
        let mut it = 0;
        while it < self.cfg.max_iterations {
            it += 1;
            if m.cost <= 1e-24 * self.focal_px * self.focal_px {
                converged = true;
                break;
            }
            let mut d = m.jtj.diagonal();
            let dmax = d.max();
            for di in d.iter_mut() {
                *di = di.max(1e-12 * dmax + 1e-300);
            }
            let mut a = m.hessian;
            for k in 0..6 {
                a[(k, k)] += mu * d[k];
            }
            let Some(chol) = a.cholesky() else {
                mu = (mu * nu).max(1e-6);
                nu *= 2.0;
                if !mu.is_finite() || mu > 1e16 {
                    break;
                }
                continue;
            };
            let step = chol.solve(&(-m.gradient));
            let dt = Vector3::new(step[0], step[1], step[2]);
            let dw = Vector3::new(step[3], step[4], step[5]);
            if dt.norm() <= tol * (t.norm() + tol) && dw.norm() <= tol {
                converged = true;
                break;
            }
            let q_new = UnitQuaternion::from_scaled_axis(dw) * q;
            let t_new = t + dt;
            let cost_new = self.cost(&q_new, &t_new);
            // Predicted decrease of ½‖r‖² by the quadratic model.
            let pred = -(m.gradient.dot(&step) + 0.5 * step.dot(&(m.hessian * step)));
            let actual = 0.5 * (m.cost - cost_new);
            if cost_new.is_finite() && actual > 0.0 {
                let rho = if pred > 0.0 { actual / pred } else { 1.0 };
                q = q_new;
                t = t_new;
                match self.normal_equations(&q, &t) {
                    Some(next) => m = next,
                    None => break,
                }
                mu *= (1.0 - (2.0 * rho - 1.0).powi(3)).max(1.0 / 3.0);
                nu = 2.0;
                // A decrease the pixels cannot resolve: done.
                if actual <= self.cfg.relative_cost_tol * 0.5 * (m.cost + actual) {
                    converged = true;
                    break;
                }
            } else {
                mu = (mu * nu).max(1e-9);
                nu *= 2.0;
                if !mu.is_finite() || mu > 1e16 {
                    // No descent direction left: a (numerical) minimum.
                    converged = true;
                    break;
                }
            }
        }
        Fit {
            q,
            t,
            cost: m.cost,
            iterations: it,
            converged,
        }
    }
}

/// Quadratic model of `½Σ|r|²` at a pose.
#[derive(Debug, Clone, Copy)]
struct Model {
    /// `Σ|r|²`, px².
    cost: f64,
    /// Gauss–Newton matrix `JᵀJ`.
    jtj: Matrix6<f64>,
    /// Exact Hessian `JᵀJ + Σ r ∇²r`.
    hessian: Matrix6<f64>,
    /// `Jᵀr`.
    gradient: Vector6<f64>,
}

/// Distance between a fit and a pose: rotation angle (rad) plus translation
/// difference relative to the range.
fn pose_distance(f: &Fit, q: &UnitQuaternion<f64>, t: &Vector3<f64>) -> f64 {
    f.q.angle_to(q) + (f.t - t).norm() / t.norm().max(1.0)
}

/// P3P by Grunert's elimination (see Haralick et al., IJCV 1994).
///
/// With world points `P1, P2, P3`, unit bearings `f1, f2, f3` and depths
/// `s_i` (so `X_i = s_i f_i`), let `a = |P2−P3|`, `b = |P1−P3|`,
/// `c = |P1−P2|`, `cα = f2·f3`, `cβ = f1·f3`, `cγ = f1·f2`, `u = s2/s1`,
/// `v = s3/s1`. The law of cosines gives
///
/// ```text
/// (A)  b²(u² + v² − 2uv cα) = a² Q(v)
/// (C)  b²(1 + u² − 2u cγ)   = c² Q(v),      Q(v) = 1 + v² − 2v cβ = b²/s1²
/// ```
///
/// (A) − (C) is linear in `u`: `u = N(v)/D(v)` with
/// `N = (K−1)v² − 2K cβ v + 1 + K`, `K = (a²−c²)/b²`, `D = 2(cγ − v cα)`.
/// Putting it into (C) and multiplying by `D²` gives the quartic
/// `D²(1 − (c²/b²) Q) + N² − 2 cγ N D = 0` in `v`. Each real root with
/// `D ≠ 0`, `u > 0`, `v > 0` gives `s1 = b/√Q(v)` and the three camera-frame
/// points; the rotation and translation follow from the two triangles'
/// orthonormal frames (triad), exact because P3P preserves the triangle.
fn p3p(
    p: &[Point3<f64>; 3],
    f: &[Vector3<f64>; 3],
    out: &mut [(UnitQuaternion<f64>, Vector3<f64>); MAX_ROOTS],
) -> usize {
    let a2 = (p[1] - p[2]).norm_squared();
    let b2 = (p[0] - p[2]).norm_squared();
    let c2 = (p[0] - p[1]).norm_squared();
    if b2 <= 1e-18 {
        return 0;
    }
    let ca = f[1].dot(&f[2]);
    let cb = f[0].dot(&f[2]);
    let cg = f[0].dot(&f[1]);
    let k = (a2 - c2) / b2;
    let r = c2 / b2;
    // Polynomials in ascending powers of v.
    let nq = [1.0 + k, -2.0 * k * cb, k - 1.0];
    let dq = [2.0 * cg, -2.0 * ca];
    let qq = [1.0, -2.0 * cb, 1.0];
    let d2 = mul(&dq, &dq); // degree 2
    let one_minus_rq = [1.0 - r * qq[0], -r * qq[1], -r * qq[2]];
    let t1 = mul(&d2, &one_minus_rq); // degree 4
    let t2 = mul(&nq, &nq); // degree 4
    let t3 = mul(&nq, &dq); // degree 3
    let mut quartic = [0.0; 5];
    for i in 0..5 {
        quartic[i] = t1[i] + t2[i] - if i < 4 { 2.0 * cg * t3[i] } else { 0.0 };
    }
    let mut roots = [0.0; MAX_ROOTS];
    let nr = real_roots(&quartic, &mut roots);

    let frame_p = match triad(&p[0].coords, &p[1].coords, &p[2].coords) {
        Some(m) => m,
        None => return 0,
    };
    let mut m = 0;
    for &v in &roots[..nr] {
        if v <= 0.0 {
            continue;
        }
        let d = 2.0 * (cg - v * ca);
        if d.abs() < 1e-12 {
            continue;
        }
        let u = (nq[0] + nq[1] * v + nq[2] * v * v) / d;
        let q = 1.0 + v * v - 2.0 * v * cb;

        if u <= 0.0 || q <= 0.0 {
            continue;
        }
        let s1 = (b2 / q).sqrt();
        let x = [f[0] * s1, f[1] * (u * s1), f[2] * (v * s1)];
        let Some(frame_x) = triad(&x[0], &x[1], &x[2]) else {
            continue;
        };
        let rot = frame_x * frame_p.transpose();
        let rot = Rotation3::from_matrix_unchecked(rot);
        let t = x[0] - rot * p[0].coords;
        let uq = UnitQuaternion::from_rotation_matrix(&rot);
        if m < MAX_ROOTS && t.iter().all(|c| c.is_finite()) {
            out[m] = (uq, t);
            m += 1;
        }
    }
    m
}

/// Orthonormal frame `[e1 e2 e3]` of a triangle: `e1` along `b − a`, `e3`
/// normal to the triangle.
fn triad(a: &Vector3<f64>, b: &Vector3<f64>, c: &Vector3<f64>) -> Option<Matrix3<f64>> {
    let e1 = (b - a).try_normalize(1e-12)?;
    let e3 = e1.cross(&(c - a)).try_normalize(1e-12)?;
    let e2 = e3.cross(&e1);
    Some(Matrix3::from_columns(&[e1, e2, e3]))
}

/// Product of two polynomials in ascending powers (result length 5, padded).
fn mul(a: &[f64], b: &[f64]) -> [f64; 5] {
    let mut out = [0.0; 5];
    for (i, ai) in a.iter().enumerate() {
        for (j, bj) in b.iter().enumerate() {
            if i + j < 5 {
                out[i + j] += ai * bj;
            }
        }
    }
    out
}

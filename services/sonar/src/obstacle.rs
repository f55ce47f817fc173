//! Scenario obstacles and the acceleration structure the sonar casts its rays into.

use std::collections::HashMap;

use nalgebra::{Point3, Unit, Vector3};
use parry3d_f64::bounding_volume::Aabb;
use parry3d_f64::math::{Pose, Rot3, Vector as PVec};
use parry3d_f64::partitioning::{Bvh, BvhBuildStrategy, BvhLeafCost};
use parry3d_f64::query::{PointQuery, Ray, RayCast};
use parry3d_f64::shape::{Ball, Cuboid, Cylinder, Shape, TriMesh, TriMeshFlags};
use serde::{Deserialize, Serialize};

use crate::SonarError;

/// One static obstacle of the scenario, in world NED coordinates (m, deg).
///
/// In TOML: `{ kind = "box", center_ned_m = [..], half_extents_m = [..], yaw_deg = 0.0 }`,
/// `{ kind = "cylinder", ... }`, `{ kind = "sphere", ... }`, `{ kind = "mesh", ... }`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum Obstacle {
    /// A box, rotated about the vertical (NED z, down) by `yaw_deg`
    /// (positive from north towards east, like a heading).
    Box {
        /// Centre, NED, m.
        center_ned_m: [f64; 3],
        /// Half extents along the box's own x, y, z before the yaw, m (all > 0).
        half_extents_m: [f64; 3],
        /// Rotation about NED z, deg.
        yaw_deg: f64,
    },
    /// A vertical cylinder (axis along NED z), e.g. a pillar or a rock column.
    Cylinder {
        /// Centre, NED, m.
        center_ned_m: [f64; 3],
        /// Radius, m (> 0).
        radius_m: f64,
        /// Half of the height along NED z, m (> 0).
        half_height_m: f64,
    },
    /// A sphere.
    Sphere {
        /// Centre, NED, m.
        center_ned_m: [f64; 3],
        /// Radius, m (> 0).
        radius_m: f64,
    },
    /// A triangle mesh, vertices in NED, m. If every edge is shared by exactly two
    /// triangles the mesh is treated as a closed solid (outward normals assumed, points
    /// inside it have clearance 0); otherwise it is a surface (e.g. a wall or the sea bed).
    Mesh {
        /// Vertices, NED, m.
        vertices_ned_m: Vec<[f64; 3]>,
        /// Triangles as indices into `vertices_ned_m`.
        triangles: Vec<[u32; 3]>,
    },
}

fn finite3(v: &[f64; 3]) -> bool {
    v.iter().all(|x| x.is_finite())
}

fn bad(reason: String) -> SonarError {
    SonarError::InvalidObstacle {
        index: None,
        reason,
    }
}

impl Obstacle {
    /// A short name of the kind (`box`, `cylinder`, `sphere`, `mesh`).
    pub fn kind(&self) -> &'static str {
        match self {
            Obstacle::Box { .. } => "box",
            Obstacle::Cylinder { .. } => "cylinder",
            Obstacle::Sphere { .. } => "sphere",
            Obstacle::Mesh { .. } => "mesh",
        }
    }

    /// Checks that every value is finite and every size positive; names the bad key.
    pub fn validate(&self) -> Result<(), SonarError> {
        match self {
            Obstacle::Box {
                center_ned_m,
                half_extents_m,
                yaw_deg,
            } => {
                if !finite3(center_ned_m) {
                    return Err(bad(format!(
                        "box.center_ned_m must be finite, got {center_ned_m:?}"
                    )));
                }
                if !half_extents_m.iter().all(|h| h.is_finite() && *h > 0.0) {
                    return Err(bad(format!(
                        "box.half_extents_m must be finite and > 0, got {half_extents_m:?}"
                    )));
                }
                if !yaw_deg.is_finite() {
                    return Err(bad(format!("box.yaw_deg must be finite, got {yaw_deg}")));
                }
            }
            Obstacle::Cylinder {
                center_ned_m,
                radius_m,
                half_height_m,
            } => {
                if !finite3(center_ned_m) {
                    return Err(bad(format!(
                        "cylinder.center_ned_m must be finite, got {center_ned_m:?}"
                    )));
                }
                if !(radius_m.is_finite() && *radius_m > 0.0) {
                    return Err(bad(format!(
                        "cylinder.radius_m must be finite and > 0, got {radius_m}"
                    )));
                }
                if !(half_height_m.is_finite() && *half_height_m > 0.0) {
                    return Err(bad(format!(
                        "cylinder.half_height_m must be finite and > 0, got {half_height_m}"
                    )));
                }
            }
            Obstacle::Sphere {
                center_ned_m,
                radius_m,
            } => {
                if !finite3(center_ned_m) {
                    return Err(bad(format!(
                        "sphere.center_ned_m must be finite, got {center_ned_m:?}"
                    )));
                }
                if !(radius_m.is_finite() && *radius_m > 0.0) {
                    return Err(bad(format!(
                        "sphere.radius_m must be finite and > 0, got {radius_m}"
                    )));
                }
            }
            Obstacle::Mesh {
                vertices_ned_m,
                triangles,
            } => {
                if vertices_ned_m.len() < 3 {
                    return Err(bad(format!(
                        "mesh.vertices_ned_m needs at least 3 vertices, got {}",
                        vertices_ned_m.len()
                    )));
                }
                if triangles.is_empty() {
                    return Err(bad("mesh.triangles must not be empty".to_string()));
                }
                if let Some((i, v)) = vertices_ned_m.iter().enumerate().find(|(_, v)| !finite3(v)) {
                    return Err(bad(format!(
                        "mesh.vertices_ned_m[{i}] must be finite, got {v:?}"
                    )));
                }
                let n = vertices_ned_m.len();
                for (i, t) in triangles.iter().enumerate() {
                    if t.iter().any(|&k| k as usize >= n) {
                        return Err(bad(format!(
                            "mesh.triangles[{i}] = {t:?} refers past the {n} vertices"
                        )));
                    }
                    if t[0] == t[1] || t[1] == t[2] || t[0] == t[2] {
                        return Err(bad(format!("mesh.triangles[{i}] = {t:?} repeats a vertex")));
                    }
                    let a = Vector3::from(vertices_ned_m[t[0] as usize]);
                    let b = Vector3::from(vertices_ned_m[t[1] as usize]);
                    let c = Vector3::from(vertices_ned_m[t[2] as usize]);
                    if (b - a).cross(&(c - a)).norm() <= 1e-12 {
                        return Err(bad(format!("mesh.triangles[{i}] = {t:?} has zero area")));
                    }
                }
            }
        }
        Ok(())
    }
}

/// The parry shape of one obstacle, kept concrete (no trait objects).
#[derive(Debug, Clone)]
enum PartShape {
    Cuboid(Cuboid),
    Cylinder(Cylinder),
    Ball(Ball),
    Mesh(Box<TriMesh>),
}

#[derive(Debug, Clone)]
struct Part {
    pose: Pose,
    shape: PartShape,
}

impl Part {
    fn cast_ray(&self, ray: &Ray, max_toi: f64) -> Option<f64> {
        match &self.shape {
            PartShape::Cuboid(s) => s.cast_ray(&self.pose, ray, max_toi, true),
            PartShape::Cylinder(s) => {
                vertical_cylinder_toi(self.pose.translation, s.radius, s.half_height, ray, max_toi)
            }
            PartShape::Ball(s) => s.cast_ray(&self.pose, ray, max_toi, true),
            PartShape::Mesh(s) => s.cast_ray(&self.pose, ray, max_toi, true),
        }
    }

    fn distance(&self, p: PVec) -> f64 {
        match self.closest(p) {
            (_, true) => 0.0,
            (q, false) => q.distance(p),
        }
    }

    /// The nearest point of the part to `p`, and whether `p` is inside it.
    fn closest(&self, p: PVec) -> (PVec, bool) {
        let proj = match &self.shape {
            PartShape::Cuboid(s) => s.project_point(&self.pose, p, true),
            PartShape::Cylinder(s) => s.project_point(&self.pose, p, true),
            PartShape::Ball(s) => s.project_point(&self.pose, p, true),
            PartShape::Mesh(s) => s.project_point(&self.pose, p, true),
        };
        (proj.point, proj.is_inside)
    }

    fn aabb(&self) -> Aabb {
        match &self.shape {
            PartShape::Cuboid(s) => s.compute_aabb(&self.pose),
            PartShape::Cylinder(s) => s.compute_aabb(&self.pose),
            PartShape::Ball(s) => s.compute_aabb(&self.pose),
            PartShape::Mesh(s) => s.compute_aabb(&self.pose),
        }
    }
}

/// Closed-form ray cast against a solid cylinder whose axis is NED z.
///
/// parry casts rays on cylinders by GJK, which costs ~0.4 µs a ray and more at grazing
/// angles; this is the exact quadratic (tens of ns). The cylinder is centred at `c` with
/// `|z − c_z| ≤ h`, `(x − c_x)² + (y − c_y)² ≤ r²`. A ray that starts inside hits at 0.
fn vertical_cylinder_toi(c: PVec, r: f64, h: f64, ray: &Ray, max_toi: f64) -> Option<f64> {
    let p = ray.origin - c;
    let d = ray.dir;
    let rho2 = p.x * p.x + p.y * p.y;
    if rho2 <= r * r && p.z.abs() <= h {
        return Some(0.0);
    }
    let mut best = f64::INFINITY;
    // side: |p_xy + t d_xy|² = r²
    let a = d.x * d.x + d.y * d.y;
    if a > 0.0 {
        let b = p.x * d.x + p.y * d.y;
        let cc = rho2 - r * r;
        let disc = b * b - a * cc;
        if disc >= 0.0 {
            let t = (-b - disc.sqrt()) / a;
            if t >= 0.0 && (p.z + t * d.z).abs() <= h {
                best = t;
            }
        }
    }
    // caps: the plane z = ±h the ray meets first from outside
    if d.z != 0.0 {
        let plane = if p.z < -h { -h } else { h };
        let t = (plane - p.z) / d.z;
        if t >= 0.0 && t < best {
            let (x, y) = (p.x + t * d.x, p.y + t * d.y);
            if x * x + y * y <= r * r {
                best = t;
            }
        }
    }
    (best < max_toi).then_some(best)
}

/// A surface point inside a cone: its distance from the apex and its angle off the axis.
#[derive(Debug, Clone, Copy)]
struct ConeHit {
    range: f64,
    off_axis: f64,
    /// Unit direction from the apex to the point.
    dir: PVec,
}

impl BvhLeafCost for ConeHit {
    fn cost(&self) -> f64 {
        self.range
    }
}

/// The angle between `v` and the unit `axis` when it is at most the cone's half angle
/// (`cos_half` its cosine), else `None`. The apex itself (`v = 0`) is on the axis.
pub(crate) fn off_axis(v: PVec, axis: PVec, cos_half: f64) -> Option<f64> {
    let n = v.length();
    if n <= 0.0 {
        return Some(0.0);
    }
    let c = v.dot(axis) / n;
    (c >= cos_half).then(|| c.clamp(-1.0, 1.0).acos())
}

/// False only when no point of `aabb` can lie inside the cone (apex `o`, unit `axis`, half
/// angle `half`): the box's bounding sphere is tested against the cone, conservatively.
fn aabb_may_meet_cone(aabb: &Aabb, o: PVec, axis: PVec, half: f64) -> bool {
    let c = aabb.center() - o;
    let r = aabb.half_extents().length();
    let d = c.length();
    if d <= r {
        return true;
    }
    let ang = (c.dot(axis) / d).clamp(-1.0, 1.0).acos();
    ang <= half + (r / d).asin()
}

pub(crate) fn pvec(v: &Vector3<f64>) -> PVec {
    PVec::new(v.x, v.y, v.z)
}

/// True if every undirected edge of the mesh is used by exactly two triangles.
fn is_closed(triangles: &[[u32; 3]]) -> bool {
    let mut edges: HashMap<(u32, u32), u32> = HashMap::with_capacity(triangles.len() * 3);
    for t in triangles {
        for (a, b) in [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])] {
            *edges.entry((a.min(b), a.max(b))).or_insert(0) += 1;
        }
    }
    edges.values().all(|&c| c == 2)
}

fn build_part(o: &Obstacle) -> Result<Part, SonarError> {
    o.validate()?;
    Ok(match o {
        Obstacle::Box {
            center_ned_m,
            half_extents_m,
            yaw_deg,
        } => Part {
            pose: Pose::from_parts(
                PVec::from_array(*center_ned_m),
                Rot3::from_rotation_z(yaw_deg.to_radians()),
            ),
            shape: PartShape::Cuboid(Cuboid::new(PVec::from_array(*half_extents_m))),
        },
        Obstacle::Cylinder {
            center_ned_m,
            radius_m,
            half_height_m,
        } => Part {
            // parry's cylinder axis is its local y; turn it onto NED z.
            pose: Pose::from_parts(
                PVec::from_array(*center_ned_m),
                Rot3::from_rotation_x(std::f64::consts::FRAC_PI_2),
            ),
            shape: PartShape::Cylinder(Cylinder::new(*half_height_m, *radius_m)),
        },
        Obstacle::Sphere {
            center_ned_m,
            radius_m,
        } => Part {
            pose: Pose::from_translation(PVec::from_array(*center_ned_m)),
            shape: PartShape::Ball(Ball::new(*radius_m)),
        },
        Obstacle::Mesh {
            vertices_ned_m,
            triangles,
        } => {
            let verts: Vec<PVec> = vertices_ned_m
                .iter()
                .map(|v| PVec::from_array(*v))
                .collect();
            let flags = if is_closed(triangles) {
                TriMeshFlags::ORIENTED
            } else {
                TriMeshFlags::empty()
            };
            let mesh = TriMesh::with_flags(verts, triangles.clone(), flags)
                .map_err(|e| bad(format!("mesh could not be built: {e}")))?;
            Part {
                pose: Pose::identity(),
                shape: PartShape::Mesh(Box::new(mesh)),
            }
        }
    })
}

/// The scenario's static obstacles behind one bounding-volume hierarchy (parry's `Bvh`),
/// so a ray visits only the obstacles whose boxes it crosses: 200 obstacles cost about
/// what 2 do.
///
/// Built once; queries take `&self` and allocate nothing.
#[derive(Debug, Clone)]
pub struct ObstacleField {
    parts: Vec<Part>,
    bvh: Bvh,
}

impl ObstacleField {
    /// Validates every obstacle and builds the hierarchy. An empty list is allowed
    /// (nothing ever echoes).
    pub fn new(obstacles: &[Obstacle]) -> Result<Self, SonarError> {
        let mut parts = Vec::with_capacity(obstacles.len());
        for (i, o) in obstacles.iter().enumerate() {
            let part = build_part(o).map_err(|e| match e {
                SonarError::InvalidObstacle { reason, .. } => SonarError::InvalidObstacle {
                    index: Some(i),
                    reason,
                },
                other => other,
            })?;
            parts.push(part);
        }
        let aabbs: Vec<Aabb> = parts.iter().map(Part::aabb).collect();
        let bvh = Bvh::from_leaves(BvhBuildStrategy::Binned, &aabbs);
        Ok(Self { parts, bvh })
    }

    /// Number of obstacles.
    pub fn len(&self) -> usize {
        self.parts.len()
    }

    /// True if there are no obstacles.
    pub fn is_empty(&self) -> bool {
        self.parts.is_empty()
    }

    /// Distance along `dir` from `origin` to the first obstacle surface hit before `max_m`,
    /// or `None`. A ray that starts inside a solid obstacle hits at 0.
    pub fn cast_ray(
        &self,
        origin: &Point3<f64>,
        dir: &Unit<Vector3<f64>>,
        max_m: f64,
    ) -> Option<f64> {
        if self.parts.is_empty() || max_m.is_nan() || max_m <= 0.0 {
            return None;
        }
        let ray = Ray::new(pvec(&origin.coords), pvec(dir));
        self.bvh
            .cast_ray(&ray, max_m, |i, best| {
                self.parts
                    .get(i as usize)
                    .and_then(|p| p.cast_ray(&ray, best))
            })
            .map(|(_, toi)| toi)
    }

    /// The nearest echo inside the cone of half angle `half_angle_rad` about `axis` from
    /// each obstacle's nearest point: `(range, off-axis angle, unit direction)` in m, rad
    /// and world axes, or `None`.
    ///
    /// For a convex obstacle whose nearest point to `origin` lies inside the cone, that
    /// point is its nearest point inside the cone (exact). When it lies outside, the nearest
    /// point inside the cone is on the cone's surface; the surface ray toward the obstacle's
    /// nearest point gives it exactly for a sphere and an upper bound for the others, which
    /// the caller's rays sampling the cone ([`crate::Sonar`]) tighten. A non-convex mesh
    /// may hide a nearer point behind the first test; the rays find it to within their
    /// spacing. Every point returned is a real surface point inside the cone.
    pub fn cone_nearest(
        &self,
        origin: &Point3<f64>,
        axis: &Unit<Vector3<f64>>,
        half_angle_rad: f64,
        max_m: f64,
    ) -> Option<(f64, f64, Vector3<f64>)> {
        if self.parts.is_empty() || max_m.is_nan() || max_m <= 0.0 {
            return None;
        }
        let o = pvec(&origin.coords);
        let a = pvec(axis);
        let cos_half = half_angle_rad.cos();
        self.bvh
            .find_best(
                max_m,
                |node, _| {
                    let aabb = node.aabb();
                    if aabb_may_meet_cone(&aabb, o, a, half_angle_rad) {
                        aabb.distance_to_local_point(o, true)
                    } else {
                        f64::MAX
                    }
                },
                |i, _| {
                    let part = self.parts.get(i as usize)?;
                    let (p, inside) = part.closest(o);
                    if inside {
                        return Some(ConeHit {
                            range: 0.0,
                            off_axis: 0.0,
                            dir: a,
                        });
                    }
                    if let Some(off_axis) = off_axis(p - o, a, cos_half) {
                        let range = p.distance(o);
                        return Some(ConeHit {
                            range,
                            off_axis,
                            dir: if range > 0.0 { (p - o) / range } else { a },
                        });
                    }
                    // Outside the cone: for a convex obstacle the nearest point inside it is
                    // on the cone's surface; the surface ray in the plane of the axis and
                    // that nearest point finds it exactly for a sphere, and a point of it
                    // (an upper bound) for the others.
                    let v = p - o;
                    let w = v - a * v.dot(a);
                    let wl = w.length();
                    if wl <= 0.0 {
                        return None;
                    }
                    let dir = a * cos_half + w * (half_angle_rad.sin() / wl);
                    part.cast_ray(&Ray::new(o, dir), max_m).map(|t| ConeHit {
                        range: t,
                        off_axis: half_angle_rad,
                        dir,
                    })
                },
            )
            .map(|(_, h)| (h.range, h.off_axis, Vector3::new(h.dir.x, h.dir.y, h.dir.z)))
    }

    /// Clearance from `p` to the nearest obstacle surface, m (0 inside a solid obstacle,
    /// `f64::INFINITY` when there are no obstacles).
    pub fn distance(&self, p: &Point3<f64>) -> f64 {
        self.nearest(p).map_or(f64::INFINITY, |(_, d)| d)
    }

    /// Index (into the list given to [`ObstacleField::new`]) of the obstacle nearest to `p`
    /// and the clearance to it, m; `None` when there are no obstacles.
    pub fn nearest(&self, p: &Point3<f64>) -> Option<(usize, f64)> {
        if self.parts.is_empty() {
            return None;
        }
        let q = pvec(&p.coords);
        self.bvh
            .find_best(
                f64::MAX,
                |node, _| node.aabb().distance_to_local_point(q, true),
                |i, _| self.parts.get(i as usize).map(|part| part.distance(q)),
            )
            .map(|(i, d)| (i as usize, d))
    }
}

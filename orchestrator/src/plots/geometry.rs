//! Obstacle outlines as the figures draw them: from above and from the side.

/// The obstacle's outline seen from above, as (north, east) points, m.
pub(crate) fn footprint(o: &sonar::Obstacle) -> Vec<(f64, f64)> {
    match o {
        sonar::Obstacle::Box {
            center_ned_m: c,
            half_extents_m: h,
            yaw_deg,
        } => {
            let (s, co) = yaw_deg.to_radians().sin_cos();
            [(1.0, 1.0), (1.0, -1.0), (-1.0, -1.0), (-1.0, 1.0)]
                .iter()
                .map(|&(a, b)| {
                    let (x, y) = (a * h[0], b * h[1]);
                    (c[0] + co * x - s * y, c[1] + s * x + co * y)
                })
                .collect()
        }
        sonar::Obstacle::Cylinder {
            center_ned_m: c,
            radius_m: r,
            ..
        }
        | sonar::Obstacle::Sphere {
            center_ned_m: c,
            radius_m: r,
        } => circle(c[0], c[1], *r),
        sonar::Obstacle::Mesh { vertices_ned_m, .. } => {
            hull(vertices_ned_m.iter().map(|v| (v[0], v[1])).collect())
        }
    }
}

/// The obstacle's outline seen from the side (east axis), as (north, depth) points, m.
pub(crate) fn side_profile(o: &sonar::Obstacle) -> Vec<(f64, f64)> {
    let rect = |n0: f64, n1: f64, d0: f64, d1: f64| vec![(n0, d0), (n1, d0), (n1, d1), (n0, d1)];
    match o {
        sonar::Obstacle::Box {
            center_ned_m: c,
            half_extents_m: h,
            yaw_deg,
        } => {
            let (s, co) = yaw_deg.to_radians().sin_cos();
            let hn = h[0] * co.abs() + h[1] * s.abs();
            rect(c[0] - hn, c[0] + hn, c[2] - h[2], c[2] + h[2])
        }
        sonar::Obstacle::Cylinder {
            center_ned_m: c,
            radius_m: r,
            half_height_m: hh,
        } => rect(c[0] - r, c[0] + r, c[2] - hh, c[2] + hh),
        sonar::Obstacle::Sphere {
            center_ned_m: c,
            radius_m: r,
        } => circle(c[0], c[2], *r),
        sonar::Obstacle::Mesh { vertices_ned_m, .. } => {
            hull(vertices_ned_m.iter().map(|v| (v[0], v[2])).collect())
        }
    }
}

pub(crate) fn circle(a: f64, b: f64, r: f64) -> Vec<(f64, f64)> {
    (0..64)
        .map(|k| {
            let t = f64::from(k) * std::f64::consts::TAU / 64.0;
            (a + r * t.cos(), b + r * t.sin())
        })
        .collect()
}

/// Convex hull (Andrew's monotone chain), counter-clockwise.
pub(crate) fn hull(mut pts: Vec<(f64, f64)>) -> Vec<(f64, f64)> {
    pts.retain(|p| p.0.is_finite() && p.1.is_finite());
    pts.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.total_cmp(&b.1)));
    pts.dedup();
    if pts.len() < 3 {
        return pts;
    }
    let cross = |o: (f64, f64), a: (f64, f64), b: (f64, f64)| {
        (a.0 - o.0) * (b.1 - o.1) - (a.1 - o.1) * (b.0 - o.0)
    };
    let mut h: Vec<(f64, f64)> = Vec::with_capacity(2 * pts.len());
    for pass in 0..2 {
        let start = h.len();
        let iter: Box<dyn Iterator<Item = &(f64, f64)>> = if pass == 0 {
            Box::new(pts.iter())
        } else {
            Box::new(pts.iter().rev())
        };
        for &p in iter {
            while h.len() >= start + 2 && cross(h[h.len() - 2], h[h.len() - 1], p) <= 0.0 {
                h.pop();
            }
            h.push(p);
        }
        h.pop();
    }
    h
}

//! Real roots of small polynomials (degree ≤ 4), allocation-free.
//!
//! Used by the P3P start of the PnP solver (a quartic). The method is
//! deliberately simple and robust rather than closed-form: the real roots of
//! the derivative split the real line into intervals on which the polynomial
//! is monotone, and each interval with a sign change holds exactly one root,
//! found by safeguarded Newton–bisection. A critical point where the
//! polynomial (nearly) touches zero is reported as a double root. This never
//! loses a simple root to cancellation, which Ferrari's formulas can.

/// Most roots returned (degree 4).
pub(crate) const MAX_ROOTS: usize = 4;

/// Evaluates `c[0] + c[1] x + ... + c[deg] x^deg` and its derivative.
fn eval(c: &[f64], x: f64) -> (f64, f64) {
    let mut p = 0.0;
    let mut dp = 0.0;
    for &ci in c.iter().rev() {
        dp = dp * x + p;
        p = p * x + ci;
    }
    (p, dp)
}

/// Real roots of the polynomial with coefficients `c` (ascending powers,
/// `c.len() ≤ 5`), written to `out` in ascending order; returns how many.
///
/// Leading coefficients that are negligible against the others are dropped
/// (the degree is reduced), so a quartic that is really a cubic is solved as
/// one.
pub(crate) fn real_roots(c: &[f64], out: &mut [f64; MAX_ROOTS]) -> usize {
    let scale = c.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
    if !(scale.is_finite() && scale > 0.0) {
        return 0;
    }
    let mut deg = c.len().saturating_sub(1).min(MAX_ROOTS);
    while deg > 0 && c[deg].abs() <= 1e-14 * scale {
        deg -= 1;
    }
    let c = &c[..=deg];
    match deg {
        0 => 0,
        1 => {
            out[0] = -c[0] / c[1];
            1
        }
        _ => {
            // Roots of the derivative, recursively.
            let mut dc = [0.0; MAX_ROOTS];
            for i in 1..=deg {
                dc[i - 1] = c[i] * i as f64;
            }
            let mut crit = [0.0; MAX_ROOTS];
            let ncrit = real_roots(&dc[..deg], &mut crit);
            // Cauchy bound on the magnitude of every root.
            let lead = c[deg];
            let bound = 1.0
                + c[..deg]
                    .iter()
                    .fold(0.0_f64, |m, v| m.max((v / lead).abs()));
            let mut edges = [0.0; MAX_ROOTS + 2];
            edges[0] = -bound;
            let mut ne = 1;
            for &x in &crit[..ncrit] {
                if x > -bound && x < bound {
                    edges[ne] = x;
                    ne += 1;
                }
            }
            edges[ne] = bound;
            ne += 1;
            let mut n = 0;
            let tiny = 1e-13 * scale;
            for k in 0..ne - 1 {
                let (a, b) = (edges[k], edges[k + 1]);
                let (fa, _) = eval(c, a);
                let (fb, _) = eval(c, b);
                if n < MAX_ROOTS && k > 0 && fa.abs() <= tiny {
                    // A critical point on the axis: a multiple root.
                    if n == 0 || (out[n - 1] - a).abs() > 1e-12 * (1.0 + a.abs()) {
                        out[n] = a;
                        n += 1;
                    }
                    continue;
                }
                if fa.signum() == fb.signum() || fb.abs() <= tiny {
                    continue;
                }
                if n < MAX_ROOTS {
                    out[n] = bracketed_root(c, a, b, fa);
                    n += 1;
                }
            }
            n
        }
    }
}

/// One root in `[a, b]` where `p(a)` and `p(b)` differ in sign.
fn bracketed_root(c: &[f64], mut a: f64, mut b: f64, fa: f64) -> f64 {
    let neg_at_a = fa < 0.0;
    let mut x = 0.5 * (a + b);
    for _ in 0..100 {
        let (f, df) = eval(c, x);
        if f == 0.0 {
            return x;
        }
        if (f < 0.0) == neg_at_a {
            a = x;
        } else {
            b = x;
        }
        let newton = x - f / df;
        let next = if df != 0.0 && newton > a && newton < b {
            newton
        } else {
            0.5 * (a + b)
        };
        if (next - x).abs() <= 4.0 * f64::EPSILON * (1.0 + x.abs()) {
            return next;
        }
        x = next;
    }
    x
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    fn from_roots(r: &[f64]) -> Vec<f64> {
        // Ascending coefficients of prod (x - r_i).
        let mut c = vec![1.0];
        for &ri in r {
            let mut n = vec![0.0; c.len() + 1];
            for (i, &ci) in c.iter().enumerate() {
                n[i] -= ri * ci;
                n[i + 1] += ci;
            }
            c = n;
        }
        c
    }

    #[test]
    fn quartic_with_four_real_roots_is_solved() {
        let c = from_roots(&[-3.0, -0.5, 0.25, 7.0]);
        let mut out = [0.0; 4];
        let n = real_roots(&c, &mut out);
        assert_eq!(n, 4);
        for (x, e) in out.iter().zip([-3.0, -0.5, 0.25, 7.0]) {
            assert_relative_eq!(*x, e, epsilon = 1e-12);
        }
    }

    #[test]
    fn quartic_with_two_real_roots_is_solved() {
        // (x^2 + 1)(x - 2)(x + 4)
        let mut c = from_roots(&[2.0, -4.0]);
        let q = c.clone();
        c.push(0.0);
        c.push(0.0);
        for i in 0..q.len() {
            c[i + 2] += q[i];
        }
        let mut out = [0.0; 4];
        let n = real_roots(&c, &mut out);
        assert_eq!(n, 2);
        assert_relative_eq!(out[0], -4.0, epsilon = 1e-12);
        assert_relative_eq!(out[1], 2.0, epsilon = 1e-12);
    }

    #[test]
    fn double_root_is_reported_once() {
        let c = from_roots(&[1.0, 1.0, -2.0]);
        let mut out = [0.0; 4];
        let n = real_roots(&c, &mut out);
        assert_eq!(n, 2);
        assert_relative_eq!(out[0], -2.0, epsilon = 1e-9);
        assert_relative_eq!(out[1], 1.0, epsilon = 1e-6);
    }

    #[test]
    fn degenerate_leading_coefficient_reduces_degree() {
        let mut c = from_roots(&[0.5, 3.0]);
        c.push(0.0);
        c.push(1e-20);
        let mut out = [0.0; 4];
        let n = real_roots(&c, &mut out);
        assert_eq!(n, 2);
        assert_relative_eq!(out[0], 0.5, epsilon = 1e-12);
        assert_relative_eq!(out[1], 3.0, epsilon = 1e-12);
    }
}

//! The water and the sensor: how a beacon's light reaches a pixel.

use serde::{Deserialize, Serialize};

/// Errors of this crate: configuration that cannot be used.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum OpticsError {
    /// A configuration value is out of range; `key` names it.
    #[error("{key} {reason}")]
    InvalidConfig {
        /// The offending key, with its table prefix (`optics.read_noise_dn`).
        key: &'static str,
        /// What is wrong, with the value that was given.
        reason: String,
    },
}

fn invalid(key: &'static str, reason: String) -> OpticsError {
    OpticsError::InvalidConfig { key, reason }
}

/// The optics of turbid water and of the camera's sensor (`[optics]`).
///
/// A beacon at range `r` (m) seen from inside its emission cone puts
/// `E = beacon_power · cone · exp(−c·r) / r²` (DN·px²) into the image:
/// inverse-square fall-off and the water's attenuation `c`. Of that, the
/// fraction `exp(−forward_scatter_per_m · r)` stays in the lamp's sharp core
/// (a Gaussian of `core_sigma_px`) and the rest is forward-scattered into a
/// glow whose width grows with the optical depth `c·r`
/// (`σ_glow² = core_sigma_px² + (glow_sigma_px_per_depth · c·r)²`). The
/// water itself glows with a veiling backscatter background of
/// `backscatter_dn`, brighter towards the top of the image by
/// `backscatter_gradient`; a hull in front of the camera hides the water
/// behind it, so it shows dark (`backscatter · (1 − exp(−c·d))` at distance
/// `d`). The sensor adds shot noise (variance `gain_dn_per_electron · I`)
/// and read noise (`read_noise_dn`), quantises to 8 bits and saturates
/// bright cores at 255.
///
/// **Visibility.** `c` is not set by hand unless `attenuation_per_m` is
/// given: it is the attenuation at which a beacon's peak, at the camera's
/// `visibility_range_m`, stands exactly `contrast_at_visibility_dn` above
/// the background (about the detector's threshold). So visibility is what
/// the optics produce: a beacon slightly nearer is seen, one farther fades
/// into the noise, and a more turbid scenario (shorter visibility) gets a
/// larger `c`, a wider glow and fainter beacons everywhere, not a cut-off.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct OpticsConfig {
    /// A lamp's whole image at 1 m in clear water, DN·px². Default 1.5e5
    /// (a saturated core up to ~8 m in the paper's water).
    pub beacon_power: f64,
    /// The water's attenuation coefficient `c`, 1/m; 0 (the default) derives
    /// it from `[camera] visibility_range_m` (see the type's docs).
    pub attenuation_per_m: f64,
    /// Forward-scattering coefficient, 1/m: the share of a lamp's light that
    /// stays in its core falls as `exp(−forward_scatter_per_m · r)`. Default 0.08.
    pub forward_scatter_per_m: f64,
    /// Width of a lamp's core (optics blur), px. Default 0.8.
    pub core_sigma_px: f64,
    /// Growth of the forward-scatter glow with optical depth, px per unit of
    /// `c·r`. Default 2.0.
    pub glow_sigma_px_per_depth: f64,
    /// Veiling backscatter of the water, DN (mid-image). Default 18.
    pub backscatter_dn: f64,
    /// The backscatter is `1 + gradient` times brighter at the top edge and
    /// `1 − gradient` at the bottom, in [0, 1). Default 0.25.
    pub backscatter_gradient: f64,
    /// Sensor read noise, DN (1σ). Default 1.5.
    pub read_noise_dn: f64,
    /// Conversion gain, DN per photo-electron (shot-noise variance = gain · DN). Default 0.2.
    pub gain_dn_per_electron: f64,
    /// A beacon's peak above the background at the visibility range, DN
    /// (used to derive `c`). Default 16.
    pub contrast_at_visibility_dn: f64,
    /// A lamp's emission fades linearly to zero over the last this-many
    /// degrees of its cone (`[beacons] emission_half_angle_deg`). Default 10.
    pub cone_soft_deg: f64,
}

impl Default for OpticsConfig {
    fn default() -> Self {
        Self {
            beacon_power: 1.5e5,
            attenuation_per_m: 0.0,
            forward_scatter_per_m: 0.08,
            core_sigma_px: 0.8,
            glow_sigma_px_per_depth: 2.0,
            backscatter_dn: 18.0,
            backscatter_gradient: 0.25,
            read_noise_dn: 1.5,
            gain_dn_per_electron: 0.2,
            contrast_at_visibility_dn: 16.0,
            cone_soft_deg: 10.0,
        }
    }
}

fn check(key: &'static str, v: f64, ok: bool, what: &str) -> Result<(), OpticsError> {
    if v.is_finite() && ok {
        Ok(())
    } else {
        Err(invalid(key, format!("must be {what}, got {v}")))
    }
}

impl OpticsConfig {
    /// Checks every field; the error names the key.
    pub fn validate(&self) -> Result<(), OpticsError> {
        check(
            "optics.beacon_power",
            self.beacon_power,
            self.beacon_power > 0.0,
            "> 0",
        )?;
        check(
            "optics.attenuation_per_m",
            self.attenuation_per_m,
            self.attenuation_per_m >= 0.0,
            ">= 0",
        )?;
        check(
            "optics.forward_scatter_per_m",
            self.forward_scatter_per_m,
            self.forward_scatter_per_m >= 0.0,
            ">= 0",
        )?;
        check(
            "optics.core_sigma_px",
            self.core_sigma_px,
            (0.3..=10.0).contains(&self.core_sigma_px),
            "in [0.3, 10]",
        )?;
        check(
            "optics.glow_sigma_px_per_depth",
            self.glow_sigma_px_per_depth,
            self.glow_sigma_px_per_depth >= 0.0,
            ">= 0",
        )?;
        check(
            "optics.backscatter_dn",
            self.backscatter_dn,
            (0.0..=200.0).contains(&self.backscatter_dn),
            "in [0, 200]",
        )?;
        check(
            "optics.backscatter_gradient",
            self.backscatter_gradient,
            (0.0..1.0).contains(&self.backscatter_gradient),
            "in [0, 1)",
        )?;
        check(
            "optics.read_noise_dn",
            self.read_noise_dn,
            self.read_noise_dn >= 0.0,
            ">= 0",
        )?;
        check(
            "optics.gain_dn_per_electron",
            self.gain_dn_per_electron,
            self.gain_dn_per_electron >= 0.0,
            ">= 0",
        )?;
        check(
            "optics.contrast_at_visibility_dn",
            self.contrast_at_visibility_dn,
            self.contrast_at_visibility_dn > 0.0,
            "> 0",
        )?;
        check(
            "optics.cone_soft_deg",
            self.cone_soft_deg,
            (0.0..=90.0).contains(&self.cone_soft_deg),
            "in [0, 90]",
        )
    }

    /// The fraction of a lamp's light left in its core at range `r_m`.
    pub fn core_fraction(&self, r_m: f64) -> f64 {
        (-self.forward_scatter_per_m * r_m).exp()
    }

    /// Width of the forward-scatter glow at range `r_m` in water of
    /// attenuation `c`, px.
    pub fn glow_sigma_px(&self, c: f64, r_m: f64) -> f64 {
        let s = self.glow_sigma_px_per_depth * c * r_m;
        (self.core_sigma_px * self.core_sigma_px + s * s).sqrt()
    }

    /// A beacon's peak above the background (noise-free, unsaturated), DN,
    /// seen head-on at range `r_m` in water of attenuation `c`.
    pub fn peak_dn(&self, c: f64, r_m: f64) -> f64 {
        let e = self.beacon_power * (-c * r_m).exp() / (r_m * r_m);
        let f = self.core_fraction(r_m);
        let sc = self.core_sigma_px;
        let sg = self.glow_sigma_px(c, r_m);
        let tau = std::f64::consts::TAU;
        e * (f / (tau * sc * sc) + (1.0 - f) / (tau * sg * sg))
    }

    /// The attenuation coefficient `c`, 1/m: `attenuation_per_m` if set,
    /// else the one at which a beacon at `visibility_range_m` peaks exactly
    /// `contrast_at_visibility_dn` above the background. An error if even
    /// clear water (`c = 0`) cannot carry the lamps that far.
    pub fn attenuation(&self, visibility_range_m: f64) -> Result<f64, OpticsError> {
        if self.attenuation_per_m > 0.0 {
            return Ok(self.attenuation_per_m);
        }
        let v = visibility_range_m;
        let want = self.contrast_at_visibility_dn;
        if !(v.is_finite() && v > 0.0) || self.peak_dn(0.0, v) < want {
            return Err(invalid(
                "camera.visibility_range_m",
                format!(
                    "is farther than the lamps reach even in clear water ({v} m: raise \
                     optics.beacon_power or set optics.attenuation_per_m)"
                ),
            ));
        }
        // peak_dn falls monotonically with c: bisect.
        let (mut lo, mut hi) = (0.0f64, 1.0f64);
        while self.peak_dn(hi, v) > want && hi < 1e3 {
            hi *= 2.0;
        }
        for _ in 0..80 {
            let mid = 0.5 * (lo + hi);
            if self.peak_dn(mid, v) > want {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        Ok(0.5 * (lo + hi))
    }

    /// Standard deviation of the sensor noise at a noise-free level `dn`.
    pub fn noise_sigma_dn(&self, dn: f64) -> f64 {
        (self.read_noise_dn * self.read_noise_dn + self.gain_dn_per_electron * dn.max(0.0)).sqrt()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn visibility_maps_onto_an_attenuation_that_puts_the_peak_at_the_contrast() {
        let o = OpticsConfig::default();
        let c12 = o.attenuation(12.0).unwrap();
        assert!((o.peak_dn(c12, 12.0) - o.contrast_at_visibility_dn).abs() < 1e-6);
        // Murkier water: a shorter visibility means a larger c.
        let c6 = o.attenuation(6.0).unwrap();
        assert!(c6 > c12, "c(6 m) = {c6}, c(12 m) = {c12}");
        // Nearer beacons stand out, farther ones fade below the contrast.
        assert!(o.peak_dn(c12, 8.0) > 4.0 * o.contrast_at_visibility_dn);
        assert!(o.peak_dn(c12, 17.9) < 0.5 * o.contrast_at_visibility_dn);
        // A given c is taken as it is.
        let fixed = OpticsConfig {
            attenuation_per_m: 0.3,
            ..o.clone()
        };
        assert_eq!(fixed.attenuation(12.0).unwrap(), 0.3);
        // Lamps cannot reach 500 m even in clear water.
        assert!(o.attenuation(500.0).is_err());
    }

    #[test]
    fn the_glow_widens_with_range_and_turbidity() {
        let o = OpticsConfig::default();
        assert!(o.glow_sigma_px(0.2, 10.0) > o.glow_sigma_px(0.2, 5.0));
        assert!(o.glow_sigma_px(0.4, 10.0) > o.glow_sigma_px(0.2, 10.0));
        assert!((o.glow_sigma_px(0.0, 10.0) - o.core_sigma_px).abs() < 1e-12);
        assert!(o.core_fraction(10.0) < o.core_fraction(5.0));
    }

    #[test]
    fn bad_values_name_their_key() {
        let o = OpticsConfig {
            read_noise_dn: -1.0,
            ..OpticsConfig::default()
        };
        assert!(o
            .validate()
            .unwrap_err()
            .to_string()
            .starts_with("optics.read_noise_dn"));
        assert!(OpticsConfig::default().validate().is_ok());
    }
}

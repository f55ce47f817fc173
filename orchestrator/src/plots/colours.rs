//! Vehicle colours for the figures and the report's animation.
//!
//! Up to [`MAX_NAMED_VEHICLES`] vehicles each get a colour of their own and
//! their name in the legend (the leader black, then the tab10 palette). A
//! larger group is coloured by **file**: its vehicles' lateral offset from
//! the leader in the nominal formation (the slots summed along each chain of
//! parents), on one hue ramp from the outermost file to port to the
//! outermost to starboard, the leader black; the legend names at most
//! [`MAX_FILES_NAMED`] files, spread evenly over the ramp. A 100-entry
//! legend would otherwise run off the figure.

use plotters::style::{HSLColor, RGBColor};
use shoal_scenario::Scenario;

/// Groups up to this size are coloured and named vehicle by vehicle.
pub const MAX_NAMED_VEHICLES: usize = 12;
/// Files a legend names at most.
pub const MAX_FILES_NAMED: usize = 5;
/// Offsets closer than this are one file, m.
const FILE_TOLERANCE_M: f64 = 0.25;

/// Vehicle colours: the leader black, then the tab10 palette.
pub(crate) const VEHICLE_COLOURS: [RGBColor; 10] = [
    RGBColor(0, 0, 0),
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(255, 127, 14),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(23, 190, 207),
    RGBColor(188, 189, 34),
];

/// How a run's vehicles are coloured, in the scenario's vehicle order.
#[derive(Debug, Clone)]
pub struct Colouring {
    colours: Vec<RGBColor>,
    /// Named files (label, colour) when coloured by file; empty otherwise.
    files: Vec<(String, RGBColor)>,
}

impl Colouring {
    /// The colouring of `scenario`'s vehicles.
    pub fn of(scenario: &Scenario) -> Self {
        let n = scenario.vehicles.len();
        if n <= MAX_NAMED_VEHICLES {
            return Self {
                colours: (0..n)
                    .map(|k| VEHICLE_COLOURS[k % VEHICLE_COLOURS.len()])
                    .collect(),
                files: Vec::new(),
            };
        }
        let across = across_m(scenario);
        let mut files: Vec<f64> = across.clone();
        files.sort_by(f64::total_cmp);
        files.dedup_by(|a, b| (*a - *b).abs() < FILE_TOLERANCE_M);
        let file_of = |y: f64| {
            files
                .iter()
                .enumerate()
                .min_by(|a, b| (a.1 - y).abs().total_cmp(&(b.1 - y).abs()))
                .map_or(0, |(i, _)| i)
        };
        let colours = scenario
            .vehicles
            .iter()
            .zip(&across)
            .map(|(v, y)| {
                if v.parent.is_none() {
                    VEHICLE_COLOURS[0]
                } else {
                    file_colour(file_of(*y), files.len())
                }
            })
            .collect();
        let m = files.len().min(MAX_FILES_NAMED);
        let mut named: Vec<usize> = (0..m)
            .map(|j| {
                if m > 1 {
                    (j * (files.len() - 1) + (m - 1) / 2) / (m - 1)
                } else {
                    0
                }
            })
            .collect();
        named.dedup();
        let mut legend = vec![("leader".to_string(), VEHICLE_COLOURS[0])];
        legend.extend(named.into_iter().map(|i| {
            let y = files[i];
            let side = if y < -FILE_TOLERANCE_M {
                format!("file {} m to port", crate::plots::num(round1(-y)))
            } else if y > FILE_TOLERANCE_M {
                format!("file {} m to starboard", crate::plots::num(round1(y)))
            } else {
                "file on the leader's track".to_string()
            };
            (side, file_colour(i, files.len()))
        }));
        Self {
            colours,
            files: legend,
        }
    }

    /// Whether the group is coloured by file (and its vehicles go unnamed).
    pub fn by_file(&self) -> bool {
        !self.files.is_empty()
    }

    /// Colour of vehicle `k` (scenario order).
    pub fn colour(&self, k: usize) -> RGBColor {
        self.colours
            .get(k)
            .copied()
            .unwrap_or(VEHICLE_COLOURS[k % VEHICLE_COLOURS.len()])
    }

    /// The legend's files (label, colour), the leader first; empty when
    /// vehicles are named one by one.
    pub fn files(&self) -> &[(String, RGBColor)] {
        &self.files
    }
}

/// `#rrggbb` of a colour (the report's animation).
pub fn hex(c: RGBColor) -> String {
    format!("#{:02x}{:02x}{:02x}", c.0, c.1, c.2)
}

fn round1(x: f64) -> f64 {
    (x * 10.0).round() / 10.0
}

/// Colour of file `i` of `n`, port to starboard: a hue ramp from orange
/// through green and blue to violet (clear of the safe-distance line's red
/// and of the leader's black).
fn file_colour(i: usize, n: usize) -> RGBColor {
    let f = if n > 1 {
        i as f64 / (n - 1) as f64
    } else {
        0.5
    };
    let c = plotters::style::Color::to_rgba(&HSLColor(0.08 + 0.72 * f, 0.75, 0.45));
    RGBColor(c.0, c.1, c.2)
}

/// Each vehicle's nominal lateral offset from the leader (the slots' `y`
/// summed along its chain of parents), m, in scenario order.
fn across_m(scenario: &Scenario) -> Vec<f64> {
    scenario
        .vehicles
        .iter()
        .map(|v| {
            let (mut y, mut at, mut hops) = (0.0, v, 0);
            while let (Some(slot), Some(parent)) = (
                at.slot_m,
                at.parent.as_deref().and_then(|p| scenario.vehicle(p)),
            ) {
                y += slot[1];
                at = parent;
                hops += 1;
                if hops > scenario.vehicles.len() {
                    break;
                }
            }
            y
        })
        .collect()
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    fn group(n: usize, files: usize) -> Scenario {
        // a column: `files` heads across the leader, the rest behind them
        let mut text = String::from(
            "name = \"g\"\nduration_s = 1.0\n[[vehicles]]\nname = \"L\"\nstart_ned_m = [0.0, 0.0, 10.0]\n",
        );
        for k in 1..n {
            let (parent, slot) = if k < files {
                let y = if k % 2 == 1 { -4.0 } else { 4.0 };
                let p = if k <= 2 {
                    "L".to_string()
                } else {
                    format!("F{}", k - 2)
                };
                (p, [-3.0, y, 0.0])
            } else {
                let p = if k == files {
                    "L".to_string()
                } else {
                    format!("F{}", k - files)
                };
                (p, [-6.0, 0.0, 0.0])
            };
            text.push_str(&format!(
                "[[vehicles]]\nname = \"F{k}\"\nparent = \"{parent}\"\nslot_m = {slot:?}\nstart_ned_m = [0.0, 0.0, 10.0]\n"
            ));
        }
        Scenario::from_toml(&text).unwrap()
    }

    #[test]
    fn a_small_group_is_named_vehicle_by_vehicle() {
        let c = Colouring::of(&group(5, 3));
        assert!(!c.by_file());
        assert_eq!(c.colour(0), VEHICLE_COLOURS[0]);
        assert_eq!(c.colour(3), VEHICLE_COLOURS[3]);
    }

    #[test]
    fn a_large_group_is_coloured_by_file_with_a_short_legend() {
        let s = group(100, 9);
        let c = Colouring::of(&s);
        assert!(c.by_file());
        // the leader, then at most five files from port to starboard
        assert_eq!(c.files()[0].0, "leader");
        assert!(c.files().len() <= 1 + MAX_FILES_NAMED);
        assert!(c.files()[1].0.contains("to port"), "{:?}", c.files());
        assert!(
            c.files().last().unwrap().0.contains("to starboard"),
            "{:?}",
            c.files()
        );
        // one colour per file: a vehicle shares its file head's colour
        let head = s.vehicles.iter().position(|v| v.name == "F1").unwrap();
        let behind = s
            .vehicles
            .iter()
            .position(|v| v.parent.as_deref() == Some("F1") && v.slot_m.unwrap()[1] == 0.0)
            .unwrap();
        assert_eq!(c.colour(head), c.colour(behind));
        assert_ne!(c.colour(head), c.colour(0));
        assert_eq!(hex(c.colour(0)), "#000000");
    }
}

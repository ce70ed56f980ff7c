//! Allowed ranges of the commands' numeric options, checked before any work starts.
//!
//! One [`Range`] per kind of quantity (speed, coil current, run length, ...); [`f64_in`] and
//! [`f32_in`] turn a range into a clap value parser, so a bad value is rejected while the
//! command line is parsed (exit status 2) with a message naming the option, the value and the
//! allowed range. Checks that involve more than one option (`--v-min-kmh` below `--v-max-kmh`,
//! grid sizes) use [`Range::check`] or [`ensure_count`] at the start of the command, still
//! before anything is computed or written; so does a coil current against the loaded vehicle's
//! own coil rating ([`check_current`]).

use anyhow::{bail, Result};
use shimmy_core::vehicle::{find_field, Vehicle};

/// A range of finite numbers with its unit: `lo <= x <= hi`, or `lo < x <= hi` when `lo_open`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Range {
    /// Lower bound.
    pub lo: f64,
    /// The lower bound itself is excluded.
    pub lo_open: bool,
    /// Upper bound (included).
    pub hi: f64,
    /// Unit for messages (may be empty).
    pub unit: &'static str,
}

impl Range {
    /// `lo <= x <= hi`.
    pub const fn closed(lo: f64, hi: f64, unit: &'static str) -> Self {
        Range {
            lo,
            lo_open: false,
            hi,
            unit,
        }
    }

    /// `lo < x <= hi`.
    pub const fn above(lo: f64, hi: f64, unit: &'static str) -> Self {
        Range {
            lo,
            lo_open: true,
            hi,
            unit,
        }
    }

    /// `x` is finite and inside.
    pub fn contains(&self, x: f64) -> bool {
        x.is_finite()
            && (if self.lo_open {
                x > self.lo
            } else {
                x >= self.lo
            })
            && x <= self.hi
    }

    /// The range as text, e.g. `0 < value <= 600 s`.
    pub fn describe(&self) -> String {
        let op = if self.lo_open { "<" } else { "<=" };
        let unit = if self.unit.is_empty() {
            String::new()
        } else {
            format!(" {}", self.unit)
        };
        format!("{} {op} value <= {}{unit}", self.lo, self.hi)
    }

    /// Parses a number and checks it (the clap value parser's body).
    pub fn parse(&self, s: &str) -> std::result::Result<f64, String> {
        let x: f64 = s
            .trim()
            .parse()
            .map_err(|_| format!("not a number; allowed: {}", self.describe()))?;
        if self.contains(x) {
            Ok(x)
        } else {
            Err(format!("out of range; allowed: {}", self.describe()))
        }
    }

    /// The same check for a value computed from several options: an error naming `option`,
    /// the value and the range.
    pub fn check(&self, option: &str, x: f64) -> Result<f64> {
        if !self.contains(x) {
            bail!("{option} {x}: out of range; allowed: {}", self.describe());
        }
        Ok(x)
    }
}

/// Coil current as the command line parses it: 0 A to the largest coil rating a vehicle may
/// have (the range of `damper.rated_current_a`). The vehicle's own rating is checked by
/// [`check_current`] once the vehicle is loaded.
pub fn any_coil_current() -> Range {
    let hi = find_field("damper", "rated_current_a").map_or(0.0, |f| f.hi);
    Range::closed(0.0, hi, "A")
}

/// Checks the coil current `i` given by `option` (a command-line option or a scenario file's
/// field) against `vehicle`'s coil rating (`damper.rated_current_a`): 0 A to the rating. The
/// one check of every current a command or a scenario asks of a damper.
pub fn check_current(option: &str, i: f64, vehicle: &Vehicle) -> Result<f64> {
    let rated = f64::from(vehicle.rated_current_a());
    let range = Range::closed(0.0, rated, "A");
    if !range.contains(i) {
        bail!(
            "{option} {i}: out of range; allowed: {} (the coil rating, damper.rated_current_a, of the vehicle)",
            range.describe()
        );
    }
    Ok(i)
}

/// Speed-ramp rate (`margin`, `vehicles`): 0.01 to 50 km/h per s.
pub const RATE_KMH_PER_S: Range = Range::closed(0.01, 50.0, "km/h/s");

/// Forward speed: 1 to 250 km/h.
pub const SPEED_KMH: Range = Range::closed(1.0, 250.0, "km/h");

/// A clap value parser for an `f64` option in `range`.
pub fn f64_in(
    range: Range,
) -> impl Fn(&str) -> std::result::Result<f64, String> + Clone + Send + Sync + 'static {
    move |s: &str| range.parse(s)
}

/// A clap value parser for an `f32` option in `range` (checked in `f64`, then rounded).
pub fn f32_in(
    range: Range,
) -> impl Fn(&str) -> std::result::Result<f32, String> + Clone + Send + Sync + 'static {
    move |s: &str| range.parse(s).map(|x| x as f32)
}

/// A clap value parser for a forward speed in km/h ([`SPEED_KMH`]).
pub fn speed_kmh(
) -> impl Fn(&str) -> std::result::Result<f64, String> + Clone + Send + Sync + 'static {
    f64_in(SPEED_KMH)
}

/// A clap value parser for a coil current in A ([`any_coil_current`]; the vehicle's own rating
/// is checked later by [`check_current`]).
pub fn current_a(
) -> impl Fn(&str) -> std::result::Result<f64, String> + Clone + Send + Sync + 'static {
    f64_in(any_coil_current())
}

/// Number of items of a list (or grid) option: 1 to `max`.
pub fn ensure_count(option: &str, n: usize, max: usize) -> Result<()> {
    if n == 0 || n > max {
        bail!("{option}: {n} values; allowed: 1 to {max}");
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bounds_nan_and_infinity() {
        let r = Range::above(0.0, 600.0, "s");
        assert_eq!(r.parse("600"), Ok(600.0));
        assert!(r.parse("0").unwrap_err().contains("0 < value <= 600 s"));
        for bad in ["-1", "600.5", "NaN", "inf", "1e9", "x"] {
            assert!(r.parse(bad).is_err(), "{bad}");
        }
        assert_eq!(Range::closed(0.0, 2.0, "A").parse("0"), Ok(0.0));
        assert!(any_coil_current().contains(10.0) && !any_coil_current().contains(10.01));
        let e = SPEED_KMH.check("--v-max-kmh", 300.0).unwrap_err();
        assert!(e.to_string().contains("--v-max-kmh 300"));
        assert!(ensure_count("--speeds-kmh", 0, 4).is_err());
        assert!(ensure_count("--speeds-kmh", 4, 4).is_ok());
    }
}

//! Measured logs (CSV) for `shimmy-sim analyze`: which column holds which signal in which unit
//! ([`LogMapping`], from command-line options or a small TOML mapping file), and the parser
//! that turns a file into [`LogSample`]s in SI units. A bad file is rejected with a message
//! that names the line and the column; an empty cell (or `NaN`) in a signal column is a missing
//! value, a gap the analysis treats as the board treats a missed sample.
//!
//! Mapping file (every key optional; the defaults read a `shimmy-sim run` trace):
//!
//! ```toml
//! delimiter = ","            # "," | ";" | "\t"; without it, the header line decides
//! [time]                     # either a time column ...
//! column = "t_s"
//! unit = "s"                 # s | ms | us
//! # rate_hz = 500.0          # ... or no time column: rows are equally spaced at this rate
//! [yaw]                      # wheel yaw: two wheels, or one signal (e.g. a steering angle)
//! left = "psi_l_meas_rad"
//! right = "psi_r_meas_rad"
//! # column = "steer_deg"     # one signal, used for both wheels (instead of left/right)
//! unit = "rad"               # rad | mrad | deg
//! gain = 1.0                 # wheel yaw per unit of the signal (a steering angle: 1 / ratio)
//! [speed]
//! column = "speed_meas_mps"
//! unit = "m/s"               # m/s | km/h | mph
//! ```

use anyhow::{bail, Context, Result};
use serde::Deserialize;
use std::path::Path;

/// Unit of a time column.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TimeUnit {
    /// Seconds.
    S,
    /// Milliseconds.
    Ms,
    /// Microseconds.
    Us,
}

/// Unit of an angle column.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AngleUnit {
    /// Radians.
    Rad,
    /// Milliradians.
    Mrad,
    /// Degrees.
    Deg,
}

/// Unit of a speed column.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SpeedUnit {
    /// Metres per second.
    Mps,
    /// Kilometres per hour.
    Kmh,
    /// Miles per hour.
    Mph,
}

impl TimeUnit {
    /// The allowed names.
    pub const NAMES: &'static str = "s, ms, us";

    /// Parses `s`, `ms` or `us`.
    pub fn parse(s: &str) -> Option<Self> {
        match s {
            "s" => Some(Self::S),
            "ms" => Some(Self::Ms),
            "us" => Some(Self::Us),
            _ => None,
        }
    }

    fn to_s(self, x: f64) -> f64 {
        match self {
            Self::S => x,
            Self::Ms => x * 1e-3,
            Self::Us => x * 1e-6,
        }
    }
}

impl AngleUnit {
    /// The allowed names.
    pub const NAMES: &'static str = "rad, mrad, deg";

    /// Parses `rad`, `mrad` or `deg`.
    pub fn parse(s: &str) -> Option<Self> {
        match s {
            "rad" => Some(Self::Rad),
            "mrad" => Some(Self::Mrad),
            "deg" => Some(Self::Deg),
            _ => None,
        }
    }

    fn to_rad(self, x: f64) -> f64 {
        match self {
            Self::Rad => x,
            Self::Mrad => x * 1e-3,
            Self::Deg => x.to_radians(),
        }
    }
}

impl SpeedUnit {
    /// The allowed names.
    pub const NAMES: &'static str = "m/s, km/h, mph";

    /// Parses `m/s`, `km/h` or `mph`.
    pub fn parse(s: &str) -> Option<Self> {
        match s {
            "m/s" | "mps" => Some(Self::Mps),
            "km/h" | "kmh" => Some(Self::Kmh),
            "mph" => Some(Self::Mph),
            _ => None,
        }
    }

    fn to_mps(self, x: f64) -> f64 {
        match self {
            Self::Mps => x,
            Self::Kmh => x / 3.6,
            Self::Mph => x * 0.44704,
        }
    }
}

/// Where the time comes from.
#[derive(Clone, Debug, PartialEq)]
pub enum TimeSource {
    /// A column in the given unit.
    Column {
        /// Column name.
        name: String,
        /// Its unit.
        unit: TimeUnit,
    },
    /// No time column: row i is at i / rate_hz.
    Rate {
        /// Sample rate, Hz.
        rate_hz: f64,
    },
}

/// Which columns hold the wheel yaw.
#[derive(Clone, Debug, PartialEq)]
pub enum YawColumns {
    /// Left and right wheel yaw.
    Wheels {
        /// Left wheel column.
        left: String,
        /// Right wheel column.
        right: String,
    },
    /// One signal (a single wheel or a steering angle), used for both wheels.
    Single(String),
}

/// Which column holds which signal, in which unit.
#[derive(Clone, Debug, PartialEq)]
pub struct LogMapping {
    /// Field separator; `None`: the one of `,` `;` tab that splits the header into the most
    /// fields (a log exported with a locale's `;` reads without options).
    pub delimiter: Option<char>,
    /// Time column or fixed rate.
    pub time: TimeSource,
    /// Yaw column(s).
    pub yaw: YawColumns,
    /// Unit of the yaw column(s).
    pub yaw_unit: AngleUnit,
    /// Wheel yaw per unit of the signal (1 for a wheel yaw; 1 / steering ratio for a
    /// steering-wheel angle).
    pub yaw_gain: f64,
    /// Speed column.
    pub speed: String,
    /// Its unit.
    pub speed_unit: SpeedUnit,
}

impl Default for LogMapping {
    /// The columns of a `shimmy-sim run` trace: the samples the in-loop meter received.
    fn default() -> Self {
        Self {
            delimiter: None,
            time: TimeSource::Column {
                name: "t_s".into(),
                unit: TimeUnit::S,
            },
            yaw: YawColumns::Wheels {
                left: "psi_l_meas_rad".into(),
                right: "psi_r_meas_rad".into(),
            },
            yaw_unit: AngleUnit::Rad,
            yaw_gain: 1.0,
            speed: "speed_meas_mps".into(),
            speed_unit: SpeedUnit::Mps,
        }
    }
}

/// Allowed range of a mapping's sample rate, Hz.
pub const RATE_RANGE_HZ: (f64, f64) = (1.0, 100_000.0);
/// Allowed range of the yaw gain (magnitude; the sign may flip the signal).
pub const GAIN_RANGE: (f64, f64) = (1e-4, 1e4);
/// Largest plausible |wheel yaw| after unit and gain, rad (90 deg: beyond it the column or
/// its unit is wrong).
pub const MAX_YAW_RAD: f64 = std::f64::consts::FRAC_PI_2;
/// Plausible speed range after the unit, m/s (-10 .. 150 m/s, i.e. -36 .. 540 km/h).
pub const SPEED_RANGE_MPS: (f64, f64) = (-10.0, 150.0);

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct MappingFile {
    delimiter: Option<String>,
    time: Option<TimeSection>,
    yaw: Option<YawSection>,
    speed: Option<SpeedSection>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct TimeSection {
    column: Option<String>,
    unit: Option<String>,
    rate_hz: Option<f64>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct YawSection {
    left: Option<String>,
    right: Option<String>,
    column: Option<String>,
    unit: Option<String>,
    gain: Option<f64>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SpeedSection {
    column: Option<String>,
    unit: Option<String>,
}

/// Changes to a mapping, field by field (the command-line options, or a mapping file); `None`
/// keeps the field.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MappingChanges {
    /// Field separator: `,`, `;` or a tab (`\t`).
    pub delimiter: Option<String>,
    /// Time column.
    pub time_column: Option<String>,
    /// Unit of the time column.
    pub time_unit: Option<String>,
    /// Fixed rate instead of a time column, Hz.
    pub rate_hz: Option<f64>,
    /// One yaw signal for both wheels.
    pub yaw_column: Option<String>,
    /// Left wheel yaw column.
    pub yaw_left: Option<String>,
    /// Right wheel yaw column.
    pub yaw_right: Option<String>,
    /// Unit of the yaw column(s).
    pub yaw_unit: Option<String>,
    /// Wheel yaw per unit of the signal.
    pub yaw_gain: Option<f64>,
    /// Speed column.
    pub speed_column: Option<String>,
    /// Its unit.
    pub speed_unit: Option<String>,
}

impl MappingChanges {
    /// The changes a mapping file (TOML, module docs) asks for; unknown keys are errors.
    pub fn parse_toml(text: &str) -> Result<Self> {
        let f: MappingFile = toml::from_str(text)?;
        let (time, yaw, speed) = (f.time, f.yaw, f.speed);
        Ok(Self {
            delimiter: f.delimiter,
            time_column: time.as_ref().and_then(|t| t.column.clone()),
            time_unit: time.as_ref().and_then(|t| t.unit.clone()),
            rate_hz: time.as_ref().and_then(|t| t.rate_hz),
            yaw_column: yaw.as_ref().and_then(|y| y.column.clone()),
            yaw_left: yaw.as_ref().and_then(|y| y.left.clone()),
            yaw_right: yaw.as_ref().and_then(|y| y.right.clone()),
            yaw_unit: yaw.as_ref().and_then(|y| y.unit.clone()),
            yaw_gain: yaw.as_ref().and_then(|y| y.gain),
            speed_column: speed.as_ref().and_then(|s| s.column.clone()),
            speed_unit: speed.as_ref().and_then(|s| s.unit.clone()),
        })
    }

    /// Loads a mapping file.
    pub fn load(path: &Path) -> Result<Self> {
        let text = crate::sim::input::files::read_text(path, crate::sim::input::files::TEXT_LIMIT)
            .context("reading mapping file")?;
        Self::parse_toml(&text).with_context(|| format!("mapping file {}", path.display()))
    }

    /// `self` with every field `other` sets replaced by `other`'s.
    #[must_use]
    pub fn then(self, other: &Self) -> Self {
        fn pick<T: Clone>(a: Option<T>, b: &Option<T>) -> Option<T> {
            b.clone().or(a)
        }
        Self {
            delimiter: pick(self.delimiter, &other.delimiter),
            time_column: pick(self.time_column, &other.time_column),
            time_unit: pick(self.time_unit, &other.time_unit),
            rate_hz: pick(self.rate_hz, &other.rate_hz),
            yaw_column: pick(self.yaw_column, &other.yaw_column),
            yaw_left: pick(self.yaw_left, &other.yaw_left),
            yaw_right: pick(self.yaw_right, &other.yaw_right),
            yaw_unit: pick(self.yaw_unit, &other.yaw_unit),
            yaw_gain: pick(self.yaw_gain, &other.yaw_gain),
            speed_column: pick(self.speed_column, &other.speed_column),
            speed_unit: pick(self.speed_unit, &other.speed_unit),
        }
    }

    /// The default mapping ([`LogMapping::default`]) with these changes, validated: each bad
    /// value is named with the allowed ones.
    pub fn mapping(&self) -> Result<LogMapping> {
        let mut m = LogMapping::default();
        if let Some(d) = &self.delimiter {
            m.delimiter = Some(match d.as_str() {
                "," => ',',
                ";" => ';',
                "\t" | "\\t" | "tab" => '\t',
                _ => bail!("delimiter `{d}`: allowed: \",\", \";\", \"\\t\""),
            });
        }
        if self.rate_hz.is_some() && (self.time_column.is_some() || self.time_unit.is_some()) {
            bail!("time: give either a time column (time.column, time.unit) or time.rate_hz, not both");
        }
        if let Some(r) = self.rate_hz {
            let (lo, hi) = RATE_RANGE_HZ;
            if !(lo..=hi).contains(&r) {
                bail!("time.rate_hz = {r}: allowed {lo} ..= {hi} Hz");
            }
            m.time = TimeSource::Rate { rate_hz: r };
        } else {
            let name = self.time_column.clone().unwrap_or_else(|| "t_s".into());
            let unit = match &self.time_unit {
                Some(u) => TimeUnit::parse(u)
                    .with_context(|| format!("time.unit `{u}`: allowed: {}", TimeUnit::NAMES))?,
                None => TimeUnit::S,
            };
            m.time = TimeSource::Column { name, unit };
        }
        m.yaw = match (&self.yaw_column, &self.yaw_left, &self.yaw_right) {
            (Some(c), None, None) => YawColumns::Single(c.clone()),
            (Some(_), _, _) => {
                bail!(
                    "yaw: give either one column (yaw.column) or yaw.left and yaw.right, not both"
                )
            }
            (None, None, None) => m.yaw,
            (None, Some(l), Some(r)) => YawColumns::Wheels {
                left: l.clone(),
                right: r.clone(),
            },
            (None, _, _) => bail!("yaw: yaw.left and yaw.right go together (or one yaw.column)"),
        };
        if let Some(u) = &self.yaw_unit {
            m.yaw_unit = AngleUnit::parse(u)
                .with_context(|| format!("yaw.unit `{u}`: allowed: {}", AngleUnit::NAMES))?;
        }
        if let Some(g) = self.yaw_gain {
            let (lo, hi) = GAIN_RANGE;
            if !(g.is_finite() && (lo..=hi).contains(&g.abs())) {
                bail!("yaw.gain = {g}: allowed |gain| in {lo} ..= {hi}");
            }
            m.yaw_gain = g;
        }
        // A steering-wheel angle read as a wheel yaw is ~15x too large: a false shimmy.
        if let (YawColumns::Single(c), None) = (&m.yaw, self.yaw_gain) {
            bail!(
                "yaw.column `{c}` is one signal for both wheels: give yaw.gain (--yaw-gain): 1 \
                 for a wheel yaw, 1 / steering ratio for a steering-wheel angle (0.0625 at 16:1)"
            );
        }
        if let Some(c) = &self.speed_column {
            m.speed = c.clone();
        }
        if let Some(u) = &self.speed_unit {
            m.speed_unit = SpeedUnit::parse(u)
                .with_context(|| format!("speed.unit `{u}`: allowed: {}", SpeedUnit::NAMES))?;
        }
        Ok(m)
    }
}

/// One row of a log in SI units; `None`: the cell was empty or `NaN` (a gap in that signal).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LogSample {
    /// Time, s.
    pub t_s: f64,
    /// Left wheel yaw, rad (gain applied).
    pub psi_l_rad: Option<f64>,
    /// Right wheel yaw, rad (gain applied).
    pub psi_r_rad: Option<f64>,
    /// Vehicle speed, m/s.
    pub speed_mps: Option<f64>,
}

/// A parsed log.
#[derive(Clone, Debug, PartialEq)]
pub struct Log {
    /// The rows, time strictly increasing.
    pub samples: Vec<LogSample>,
    /// The header's column names.
    pub columns: Vec<String>,
}

fn column_index(header: &[String], name: &str, role: &str) -> Result<usize> {
    header.iter().position(|h| h == name).with_context(|| {
        format!(
            "{role} column `{name}` is not in the header (columns: {})",
            header.join(", ")
        )
    })
}

fn unquote(s: &str) -> &str {
    let s = s.trim();
    s.strip_prefix('"')
        .and_then(|x| x.strip_suffix('"'))
        .unwrap_or(s)
}

/// The separator of `,` `;` tab that splits `header` into the most fields (`,` on a tie).
fn detect_delimiter(header: &str) -> char {
    [',', ';', '\t']
        .into_iter()
        .max_by_key(|&d| (header.split(d).count(), d == ','))
        .unwrap_or(',')
}

/// Parses a log's text with `map`. Lines starting with `#` and blank lines are skipped; the
/// first other line is the header. Errors name the line (1-based, as an editor counts) and
/// the column.
pub fn parse(text: &str, map: &LogMapping) -> Result<Log> {
    let mut lines = text
        .lines()
        .enumerate()
        .map(|(i, l)| (i + 1, l.trim_end_matches('\r')))
        .filter(|(_, l)| !l.trim().is_empty() && !l.trim_start().starts_with('#'));
    let Some((_, head)) = lines.next() else {
        bail!("the log is empty (no header line)");
    };
    let delimiter = map.delimiter.unwrap_or_else(|| detect_delimiter(head));
    let header: Vec<String> = head
        .split(delimiter)
        .map(|h| unquote(h).to_string())
        .collect();
    // (time column and its unit) or the fixed rate.
    let time = match &map.time {
        TimeSource::Column { name, unit } => Ok((column_index(&header, name, "time")?, *unit)),
        TimeSource::Rate { rate_hz } => Err(*rate_hz),
    };
    let (left, right) = match &map.yaw {
        YawColumns::Wheels { left, right } => (
            column_index(&header, left, "left yaw")?,
            column_index(&header, right, "right yaw")?,
        ),
        YawColumns::Single(c) => {
            let i = column_index(&header, c, "yaw")?;
            (i, i)
        }
    };
    let speed = column_index(&header, &map.speed, "speed")?;
    let mut samples: Vec<LogSample> = Vec::new();
    for (line, l) in lines {
        let cells: Vec<&str> = l.split(delimiter).map(unquote).collect();
        if cells.len() != header.len() {
            bail!(
                "line {line}: {} fields, the header has {}",
                cells.len(),
                header.len()
            );
        }
        // A number, or None for an empty cell / NaN; anything else names line and column.
        let value = |i: usize| -> Result<Option<f64>> {
            let c = cells.get(i).copied().unwrap_or("");
            if c.is_empty() || c.eq_ignore_ascii_case("nan") {
                return Ok(None);
            }
            match c.parse::<f64>() {
                Ok(x) if x.is_finite() => Ok(Some(x)),
                _ => bail!(
                    "line {line}, column {} `{}`: `{c}` is not a number",
                    i + 1,
                    header.get(i).map_or("", String::as_str)
                ),
            }
        };
        let t_s = match time {
            Ok((i, unit)) => match value(i)? {
                Some(t) => unit.to_s(t),
                None => bail!(
                    "line {line}, column {} `{}`: the time is missing",
                    i + 1,
                    header[i]
                ),
            },
            Err(rate_hz) => samples.len() as f64 / rate_hz,
        };
        if let (Some(prev), Ok((i, _))) = (samples.last(), time) {
            if t_s <= prev.t_s {
                bail!(
                    "line {line}, column {} `{}`: time {t_s} s does not advance (previous row: {} s)",
                    i + 1,
                    header[i],
                    prev.t_s
                );
            }
        }
        let yaw = |i: usize| -> Result<Option<f64>> {
            let Some(x) = value(i)? else { return Ok(None) };
            let rad = map.yaw_unit.to_rad(x) * map.yaw_gain;
            if rad.abs() > MAX_YAW_RAD {
                bail!(
                    "line {line}, column {} `{}`: wheel yaw {:.1} deg (after unit and gain) outside the allowed -90 ..= 90 deg",
                    i + 1,
                    header[i],
                    rad.to_degrees()
                );
            }
            Ok(Some(rad))
        };
        let psi_l_rad = yaw(left)?;
        let psi_r_rad = yaw(right)?;
        let speed_mps = match value(speed)? {
            Some(v) => {
                let v = map.speed_unit.to_mps(v);
                let (lo, hi) = SPEED_RANGE_MPS;
                if !(lo..=hi).contains(&v) {
                    bail!(
                        "line {line}, column {} `{}`: speed {v:.2} m/s outside the allowed {lo} ..= {hi} m/s",
                        speed + 1,
                        header[speed]
                    );
                }
                Some(v)
            }
            None => None,
        };
        samples.push(LogSample {
            t_s,
            psi_l_rad,
            psi_r_rad,
            speed_mps,
        });
    }
    if samples.len() < 2 {
        bail!(
            "the log has {} data row(s); at least 2 are needed",
            samples.len()
        );
    }
    Ok(Log {
        samples,
        columns: header,
    })
}

/// Reads and parses a log file; errors start with the file name.
pub fn load(path: &Path, map: &LogMapping) -> Result<Log> {
    let text = crate::sim::input::files::read_text(path, crate::sim::input::files::DATA_LIMIT)
        .context("reading log")?;
    parse(&text, map).with_context(|| format!("log {}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn err(text: &str, map: &LogMapping) -> String {
        format!("{:#}", parse(text, map).unwrap_err())
    }

    #[test]
    fn one_yaw_signal_needs_its_gain() {
        let single = |gain| MappingChanges {
            yaw_column: Some("steer_deg".into()),
            yaw_gain: gain,
            ..MappingChanges::default()
        };
        let e = format!("{:#}", single(None).mapping().unwrap_err());
        assert!(e.contains("steer_deg") && e.contains("yaw.gain"), "{e}");
        assert_eq!(single(Some(0.0625)).mapping().unwrap().yaw_gain, 0.0625);
    }

    #[test]
    fn the_header_decides_the_delimiter_when_none_is_given() {
        let comma =
            "t_s,psi_l_meas_rad,psi_r_meas_rad,speed_meas_mps\n0,0.01,0.02,10\n0.01,0.03,0.04,11\n";
        let want = parse(comma, &LogMapping::default()).unwrap();
        for d in [";", "\t"] {
            let text = comma.replace(',', d);
            let got = parse(&text, &LogMapping::default()).unwrap();
            assert_eq!(got.samples, want.samples, "delimiter {d:?}");
        }
        // A delimiter given is used as given: a `;` log read with `,` has no time column.
        let forced = MappingChanges {
            delimiter: Some(",".into()),
            ..MappingChanges::default()
        }
        .mapping()
        .unwrap();
        let e = err(&comma.replace(',', ";"), &forced);
        assert!(e.contains("time column `t_s`"), "{e}");
    }

    #[test]
    fn units_gain_and_missing_cells() {
        let map = MappingChanges {
            delimiter: Some(";".into()),
            time_column: Some("time".into()),
            time_unit: Some("ms".into()),
            yaw_column: Some("steer".into()),
            yaw_unit: Some("deg".into()),
            yaw_gain: Some(0.05),
            speed_column: Some("v".into()),
            speed_unit: Some("km/h".into()),
            ..MappingChanges::default()
        }
        .mapping()
        .unwrap();
        let log = parse(
            "# logger 1\ntime;steer;v\n0;20;36\n2;;NaN\n4;-40;72\n",
            &map,
        )
        .unwrap();
        assert_eq!(log.samples.len(), 3);
        let s = log.samples[0];
        assert_eq!(s.t_s, 0.0);
        assert!((s.psi_l_rad.unwrap() - 1f64.to_radians()).abs() < 1e-15);
        assert_eq!(s.psi_l_rad, s.psi_r_rad);
        assert!((s.speed_mps.unwrap() - 10.0).abs() < 1e-12);
        assert_eq!(log.samples[1].t_s, 2e-3);
        assert_eq!(log.samples[1].psi_l_rad, None);
        assert_eq!(log.samples[1].speed_mps, None);
        assert!((log.samples[2].psi_r_rad.unwrap() + 2f64.to_radians()).abs() < 1e-15);
    }

    #[test]
    fn a_fixed_rate_replaces_the_time_column() {
        let map = MappingChanges {
            rate_hz: Some(250.0),
            ..MappingChanges::default()
        }
        .mapping()
        .unwrap();
        let log = parse(
            "psi_l_meas_rad,psi_r_meas_rad,speed_meas_mps\n0,0,5\n0.001,0.001,5\n0,0,5\n",
            &map,
        )
        .unwrap();
        let t: Vec<f64> = log.samples.iter().map(|s| s.t_s).collect();
        assert_eq!(t, [0.0, 0.004, 0.008]);
    }

    #[test]
    fn bad_files_name_line_and_column() {
        let map = LogMapping::default();
        let head = "t_s,psi_l_meas_rad,psi_r_meas_rad,speed_meas_mps\n";
        let cases = [
            ("", "empty"),
            ("t,a,b\n0,1,2\n", "time column `t_s` is not in the header (columns: t, a, b)"),
            (
                "t_s,psi_l_meas_rad,psi_r_meas_rad\n0,0,0\n",
                "speed column `speed_meas_mps` is not in the header",
            ),
            ("0,0,0,5\n0.001,0,0\n", "line 3: 3 fields, the header has 4"),
            (
                "0,0,0,5\n0.001,0,x1,5\n",
                "line 3, column 3 `psi_r_meas_rad`: `x1` is not a number",
            ),
            ("0,0,0,5\n,0,0,5\n", "line 3, column 1 `t_s`: the time is missing"),
            (
                "0,0,0,5\n0.002,0,0,5\n0.001,0,0,5\n",
                "line 4, column 1 `t_s`: time 0.001 s does not advance (previous row: 0.002 s)",
            ),
            (
                "0,0,0,5\n0.001,2,0,5\n",
                "line 3, column 2 `psi_l_meas_rad`: wheel yaw 114.6 deg",
            ),
            (
                "0,0,0,5\n0.001,0,0,500\n",
                "line 3, column 4 `speed_meas_mps`: speed 500.00 m/s outside the allowed -10 ..= 150 m/s",
            ),
            ("0,0,0,5\n", "1 data row(s); at least 2"),
        ];
        for (body, want) in cases {
            let text = if body.starts_with("t,") || body.starts_with("t_s,") || body.is_empty() {
                body.to_string()
            } else {
                format!("{head}{body}")
            };
            let e = err(&text, &map);
            assert!(e.contains(want), "`{body}`: got `{e}`, want `{want}`");
        }
    }

    #[test]
    fn bad_mappings_name_the_field_and_the_allowed_values() {
        let cases = [
            (
                "[time]\nunit = \"min\"\n",
                "time.unit `min`: allowed: s, ms, us",
            ),
            (
                "[time]\nrate_hz = 0.0\n",
                "time.rate_hz = 0: allowed 1 ..= 100000 Hz",
            ),
            (
                "[time]\nrate_hz = 100.0\ncolumn = \"t\"\n",
                "either a time column",
            ),
            (
                "[yaw]\nunit = \"grad\"\n",
                "yaw.unit `grad`: allowed: rad, mrad, deg",
            ),
            ("[yaw]\ngain = 0.0\n", "yaw.gain = 0: allowed |gain|"),
            (
                "[yaw]\nleft = \"a\"\n",
                "yaw.left and yaw.right go together",
            ),
            (
                "[speed]\nunit = \"knots\"\n",
                "speed.unit `knots`: allowed: m/s, km/h, mph",
            ),
            ("delimiter = \"|\"\n", "delimiter `|`"),
            ("[speed]\ncolum = \"v\"\n", "unknown field `colum`"),
        ];
        for (toml, want) in cases {
            let e = match MappingChanges::parse_toml(toml).and_then(|c| c.mapping()) {
                Ok(m) => panic!("`{toml}` accepted: {m:?}"),
                Err(e) => format!("{e:#}"),
            };
            assert!(e.contains(want), "`{toml}`: got `{e}`, want `{want}`");
        }
        // A mapping file, then command-line options on top.
        let file =
            MappingChanges::parse_toml("[speed]\ncolumn = \"v\"\nunit = \"km/h\"\n").unwrap();
        let cli = MappingChanges {
            speed_unit: Some("mph".into()),
            ..MappingChanges::default()
        };
        let m = file.then(&cli).mapping().unwrap();
        assert_eq!((m.speed.as_str(), m.speed_unit), ("v", SpeedUnit::Mph));
    }
}

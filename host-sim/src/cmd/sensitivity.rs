//! `shimmy-sim sensitivity`: how the Hopf onset/offset speeds and the onset frequency move with
//! a relative change of each parameter the linear model depends on (table and CSV).

use std::io::Write;
use std::path::PathBuf;

use anyhow::{Context, Result};
use shimmy_core::eigen::ModeShape;
use shimmy_core::model::LinearModel;
use shimmy_core::stability::{self, DEFAULT_TOL_MPS};
use shimmy_core::units::{kmh_to_mps, mps_to_kmh};
use shimmy_core::vehicles::car::{Param, PlantParams};

use crate::model::registry::{self, ModelVisitor, Registered};
use crate::out::table::opt;
use crate::sim::input::vehicle_file;

/// Options of `shimmy-sim sensitivity`.
#[derive(clap::Args, Debug, Clone)]
pub struct SensitivityArgs {
    /// The vehicle (`--vehicle`, a named set or a vehicle file).
    #[command(flatten)]
    pub vehicle: crate::cmd::VehicleArg,
    /// Relative change applied down and up in %: above 0, at most 90.
    #[arg(long, default_value_t = 20.0, allow_negative_numbers = true, value_parser = crate::sim::input::arg_range::f64_in(PERCENT))]
    pub percent: f64,
    /// Output folder (`--out`; default out/sensitivity, [`Self::out_dir`]).
    #[command(flatten)]
    pub out: crate::cmd::OutArg,
}

impl SensitivityArgs {
    /// The output folder: `--out`, else out/sensitivity.
    pub fn out_dir(&self) -> PathBuf {
        self.out.dir_or("out/sensitivity")
    }
}

/// The relative change: above 0, at most 90 % (at 100 % a parameter would vanish).
pub const PERCENT: crate::sim::input::arg_range::Range =
    crate::sim::input::arg_range::Range::above(0.0, 90.0, "%");

/// Parameters varied by the sensitivity study (those the linear model depends on; F_z, mu, C_s
/// only shape the nonlinear tyre and l_t only the damper lever, so they have no effect without
/// a damper).
pub const SENSITIVITY_PARAMS: [Param; 15] = [
    Param::CA,
    Param::Sigma,
    Param::E,
    Param::TP,
    Param::KD,
    Param::CSw,
    Param::CK,
    Param::IP,
    Param::IK,
    Param::KTr,
    Param::JSw,
    Param::IS,
    Param::HR,
    Param::KPhi,
    Param::IPhi,
];

/// A crossing as the sensitivity table shows it: speed km/h, kind, frequency Hz, mode shape.
pub type CrossingRow = (f64, stability::CrossingKind, f64, ModeShape);

/// The Hopf crossings of a parameter set in 1..250 km/h. The first shimmy window (the first
/// onset of the shimmy-shaped mode, [`ModeShape::is_shimmy`], and its first offset above it)
/// gets the table's columns; [`Window::all`] keeps every crossing, so a second instability
/// inside the range (another mode's) is never hidden, and never taken for the window.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Window {
    /// First onset of the shimmy mode, km/h.
    pub onset_kmh: Option<f64>,
    /// The shimmy mode's first offset above its first onset (its first offset when there is no
    /// onset), km/h.
    pub offset_kmh: Option<f64>,
    /// Frequency at the first onset, Hz.
    pub onset_freq_hz: Option<f64>,
    /// Every crossing, in increasing speed.
    pub all: Vec<CrossingRow>,
}

impl Window {
    /// The crossings beyond the first onset/offset pair.
    pub fn others(&self) -> impl Iterator<Item = &CrossingRow> {
        self.all
            .iter()
            .filter(move |c| Some(c.0) != self.onset_kmh && Some(c.0) != self.offset_kmh)
    }

    /// [`Window::others`] as text (`onset 197.12 km/h 44.1 Hz anti-phase-wheel-yaw; ...`),
    /// `-` when there are none.
    pub fn others_text(&self) -> String {
        let v: Vec<String> = self
            .others()
            .map(|(v, k, f, m)| format!("{} {v:.2} km/h {f:.1} Hz {}", k.name(), m.name()))
            .collect();
        if v.is_empty() {
            "-".into()
        } else {
            v.join("; ")
        }
    }
}

/// Every Hopf crossing of `p` (no damper) in 1..250 km/h.
pub fn window_of<M: LinearModel<N>, const N: usize>(p: &M) -> Result<Window> {
    let xs = stability::hopf_crossings(
        p,
        0.0,
        kmh_to_mps(1.0),
        kmh_to_mps(250.0),
        kmh_to_mps(1.0),
        DEFAULT_TOL_MPS,
    )
    .context("Hopf search")?;
    // the window is the shimmy mode's (by shape): another mode's crossing (the 42-47 Hz
    // anti-phase wheel yaw) is one of the others, never the window
    let on = xs
        .iter()
        .find(|x| x.kind == stability::CrossingKind::Onset && x.shape.is_shimmy());
    let off = xs.iter().find(|x| {
        x.kind == stability::CrossingKind::Offset
            && x.shape.is_shimmy()
            && on.is_none_or(|o| x.speed_mps > o.speed_mps)
    });
    Ok(Window {
        onset_kmh: on.map(|x| mps_to_kmh(x.speed_mps)),
        offset_kmh: off.map(|x| mps_to_kmh(x.speed_mps)),
        onset_freq_hz: on.map(|x| x.freq_hz),
        all: xs
            .iter()
            .map(|x| (mps_to_kmh(x.speed_mps), x.kind, x.freq_hz, x.shape))
            .collect(),
    })
}

/// One varied parameter: its window at a factor, or `None` when the varied vehicle is not
/// valid (e.g. a truck whose struts cannot carry the load).
type Variant = Box<dyn Fn(f64) -> Result<Option<Window>>>;

/// The base window and one variant per parameter (name, unit, base value, variant) of the
/// vehicle's model: the car's [`SENSITIVITY_PARAMS`], another model's fields but those without
/// a linear effect ([`registry::ModelEntry::NO_LINEAR_EFFECT`]).
struct Variants;

impl ModelVisitor for Variants {
    type Output = Result<(Window, Vec<(&'static str, &'static str, f64, Variant)>)>;
    fn visit<M: Registered<N>, const N: usize>(self, f: M::File) -> Self::Output {
        let t = M::model_of(&f);
        let any: &dyn std::any::Any = &t;
        if let Some(&p) = any.downcast_ref::<PlantParams>() {
            let vs = SENSITIVITY_PARAMS
                .iter()
                .map(|&q| {
                    let f: Variant = Box::new(move |k| window_of(&p.scaled(q, k)).map(Some));
                    (q.name(), q.unit(), p.get(q), f)
                })
                .collect();
            return Ok((window_of(&p)?, vs));
        }
        let vs = M::fields()
            .iter()
            .filter(|f| !M::NO_LINEAR_EFFECT.contains(&f.name))
            .map(|f| {
                let base = t.field(f.name).unwrap_or(f64::NAN);
                let name = f.name;
                let w: Variant = Box::new(move |k| {
                    let mut v = t;
                    if v.set_field(name, base * k).is_err() || v.check().is_err() {
                        return Ok(None);
                    }
                    window_of(&v.linear()).map(Some)
                });
                (f.name, f.unit, base, w)
            })
            .collect();
        Ok((window_of(&t.linear())?, vs))
    }
}

/// Runs `shimmy-sim sensitivity`.
pub fn command(args: &SensitivityArgs) -> Result<()> {
    PERCENT.check("--percent", args.percent)?;
    let vehicle = vehicle_file::load_model(&args.vehicle.spec)?;
    let _out_dir = crate::sim::input::files::OutDir::claim(&args.out_dir())?;
    // one variant per parameter: (name, unit, base value, the window at a factor, or None
    // when the varied vehicle is not valid, e.g. a truck whose struts cannot carry the load)
    let (w0, variants) = registry::with_model(vehicle, Variants)?;
    let (on0, off0, f0) = (w0.onset_kmh, w0.offset_kmh, w0.onset_freq_hz);
    println!(
        "Hopf window sensitivity of `{}` (+-{}% per parameter, no damper, 1..250 km/h)",
        args.vehicle.spec, args.percent
    );
    println!(
        "base: onset {} km/h, offset {} km/h, onset frequency {} Hz",
        opt(on0, 2),
        opt(off0, 2),
        opt(f0, 2)
    );
    if w0.others().next().is_some() {
        println!("base, further crossings: {}", w0.others_text());
    }
    println!(
        "{:<7} | {:>9} {:>9} {:>7} | {:>9} {:>9} {:>7} | {:>8} {:>8}",
        "param", "on -", "off -", "f -", "on +", "off +", "f +", "d on/d%", "d off/d%"
    );
    let path = args.out_dir().join("sensitivity.csv");
    let mut f = Vec::new();
    writeln!(
        f,
        "param,unit,base_value,factor,onset_kmh,offset_kmh,onset_freq_hz,base_onset_kmh,base_offset_kmh,base_onset_freq_hz,crossings,further_crossings"
    )?;
    let mut further = Vec::new();
    let k = args.percent / 100.0;
    for (name, unit, base, window) in &variants {
        let mut res = Vec::new();
        for factor in [1.0 - k, 1.0 + k] {
            let Some(w) = window(factor)? else {
                println!("{name} x{factor}: not a valid vehicle (outside its range, or struts that cannot carry the load)");
                res.push((None, None, None));
                continue;
            };
            if w.others().next().is_some() {
                further.push(format!("{name} x{factor}: {}", w.others_text()));
            }
            writeln!(
                f,
                "{},{},{},{},{},{},{},{},{},{},{},\"{}\"",
                name,
                unit,
                base,
                factor,
                w.onset_kmh.map_or(String::new(), |x| format!("{x:.6}")),
                w.offset_kmh.map_or(String::new(), |x| format!("{x:.6}")),
                w.onset_freq_hz.map_or(String::new(), |x| format!("{x:.6}")),
                on0.map_or(String::new(), |x| format!("{x:.6}")),
                off0.map_or(String::new(), |x| format!("{x:.6}")),
                f0.map_or(String::new(), |x| format!("{x:.6}")),
                w.all.len(),
                w.others_text(),
            )?;
            res.push((w.onset_kmh, w.offset_kmh, w.onset_freq_hz));
        }
        // Central-difference slope in km/h per % change.
        let slope = |a: Option<f64>, b: Option<f64>| match (a, b) {
            (Some(a), Some(b)) => format!("{:.3}", (b - a) / (2.0 * args.percent)),
            _ => "-".into(),
        };
        println!(
            "{:<7} | {:>9} {:>9} {:>7} | {:>9} {:>9} {:>7} | {:>8} {:>8}",
            name,
            opt(res[0].0, 2),
            opt(res[0].1, 2),
            opt(res[0].2, 2),
            opt(res[1].0, 2),
            opt(res[1].1, 2),
            opt(res[1].2, 2),
            slope(res[0].0, res[1].0),
            slope(res[0].1, res[1].1)
        );
    }
    if further.is_empty() {
        println!("no crossing beyond the first onset/offset pair in any variant");
    } else {
        println!(
            "crossings beyond the first onset/offset pair ({} of {} variants):",
            further.len(),
            2 * variants.len()
        );
        for l in &further {
            println!("  {l}");
        }
    }
    crate::sim::input::files::write_file(&path, &f)?;
    println!("wrote {}", path.display());
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use shimmy_core::stability::{mode_at, ModeSelect};
    use shimmy_core::vehicles::car::{Param, ParamSet};

    /// `gentle` with I_k +20 %: the shimmy window closes and the 42.8 Hz anti-phase wheel-yaw
    /// mode crosses at 212.4 km/h. The window is the shimmy mode's, so there is none (the
    /// first onset of any mode, the anti-phase one, used to be reported as the window's); the
    /// anti-phase crossing stays among the others. Independently, the shimmy-shaped mode's
    /// real part is negative on a 1 km/h grid over 1..250 km/h. `nominal` keeps its window.
    #[test]
    fn another_modes_onset_is_never_the_shimmy_window() {
        let g = ParamSet::Gentle.params();
        let p = g.with(Param::IK, g.get(Param::IK) * 1.2);
        let w = window_of(&p).unwrap();
        assert_eq!(
            (w.onset_kmh, w.offset_kmh, w.onset_freq_hz),
            (None, None, None),
            "{w:?}"
        );
        let others: Vec<&CrossingRow> = w.others().collect();
        assert_eq!(others.len(), 1, "{w:?}");
        let (v, kind, f, shape) = *others[0];
        assert_eq!(
            (kind, shape),
            (stability::CrossingKind::Onset, ModeShape::AntiPhaseWheelYaw)
        );
        assert!((v - 212.4).abs() < 0.1 && (f - 42.8).abs() < 0.1, "{v} {f}");
        assert!(
            w.others_text().contains("anti-phase"),
            "{}",
            w.others_text()
        );
        for k in 1..=250 {
            let m = mode_at(&p, kmh_to_mps(f64::from(k)), 0.0, ModeSelect::Shimmy).unwrap();
            assert!(m.re < 0.0, "{k} km/h: {m:?}");
        }
        let n = window_of(&ParamSet::Nominal.params()).unwrap();
        assert!((n.onset_kmh.unwrap() - 29.3486).abs() < 1e-3, "{n:?}");
        assert!((n.offset_kmh.unwrap() - 84.1478).abs() < 1e-3, "{n:?}");
    }
}

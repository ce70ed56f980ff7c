//! `shimmy-sim sensitivity`: how the Hopf onset/offset speeds and the onset frequency move with
//! a relative change of each parameter the linear model depends on (table and CSV).

use std::fs;
use std::io::Write;
use std::path::PathBuf;

use anyhow::{Context, Result};
use shimmy_core::params::{kmh_to_mps, mps_to_kmh, Param, PlantParams};
use shimmy_core::stability::{self, DEFAULT_TOL_MPS};

use crate::out::table::opt;
use crate::sim::vehicle_file;

/// Options of `shimmy-sim sensitivity`.
#[derive(clap::Args, Debug, Clone)]
pub struct SensitivityArgs {
    /// Vehicle: a named set (nominal, gentle, hard) or a vehicle file (TOML, see
    /// docs/vehicle-file.md; parameter files are vehicle files). `--params` is the older name.
    #[arg(long, visible_alias = "params", default_value = "nominal")]
    pub vehicle: String,
    /// Relative change applied down and up in %: above 0, at most 90.
    #[arg(long, default_value_t = 20.0, allow_negative_numbers = true, value_parser = crate::sim::arg_range::f64_in(PERCENT))]
    pub percent: f64,
    /// Output directory (CSV).
    #[arg(long, default_value = "out/sensitivity")]
    pub out: PathBuf,
}

/// The relative change: above 0, at most 90 % (at 100 % a parameter would vanish).
pub const PERCENT: crate::sim::arg_range::Range =
    crate::sim::arg_range::Range::above(0.0, 90.0, "%");

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

/// Onset/offset speeds (km/h) and onset frequency (Hz) of a parameter set (None where absent),
/// searching 1..250 km/h.
pub fn window_of(p: &PlantParams) -> Result<(Option<f64>, Option<f64>, Option<f64>)> {
    let xs = stability::hopf_crossings(
        p,
        0.0,
        kmh_to_mps(1.0),
        kmh_to_mps(250.0),
        kmh_to_mps(1.0),
        DEFAULT_TOL_MPS,
    )
    .context("Hopf search")?;
    let on = xs.iter().find(|x| x.kind == stability::CrossingKind::Onset);
    let off = xs
        .iter()
        .find(|x| x.kind == stability::CrossingKind::Offset);
    Ok((
        on.map(|x| mps_to_kmh(x.speed_mps)),
        off.map(|x| mps_to_kmh(x.speed_mps)),
        on.map(|x| x.freq_hz),
    ))
}

/// Runs `shimmy-sim sensitivity`.
pub fn command(args: &SensitivityArgs) -> Result<()> {
    PERCENT.check("--percent", args.percent)?;
    let p = vehicle_file::load(&args.vehicle)?.plant;
    let (on0, off0, f0) = window_of(&p)?;
    println!(
        "Hopf window sensitivity of `{}` (+-{}% per parameter, no damper, 1..250 km/h)",
        args.vehicle, args.percent
    );
    println!(
        "base: onset {} km/h, offset {} km/h, onset frequency {} Hz",
        opt(on0, 2),
        opt(off0, 2),
        opt(f0, 2)
    );
    println!(
        "{:<7} | {:>9} {:>9} {:>7} | {:>9} {:>9} {:>7} | {:>8} {:>8}",
        "param", "on -", "off -", "f -", "on +", "off +", "f +", "d on/d%", "d off/d%"
    );
    fs::create_dir_all(&args.out)?;
    let path = args.out.join("sensitivity.csv");
    let mut f = fs::File::create(&path)?;
    writeln!(
        f,
        "param,unit,base_value,factor,onset_kmh,offset_kmh,onset_freq_hz,base_onset_kmh,base_offset_kmh,base_onset_freq_hz"
    )?;
    let k = args.percent / 100.0;
    for q in SENSITIVITY_PARAMS {
        let mut res = Vec::new();
        for factor in [1.0 - k, 1.0 + k] {
            let w = window_of(&p.scaled(q, factor))?;
            writeln!(
                f,
                "{},{},{},{},{},{},{},{},{},{}",
                q.name(),
                q.unit(),
                p.get(q),
                factor,
                w.0.map_or(String::new(), |x| format!("{x:.6}")),
                w.1.map_or(String::new(), |x| format!("{x:.6}")),
                w.2.map_or(String::new(), |x| format!("{x:.6}")),
                on0.map_or(String::new(), |x| format!("{x:.6}")),
                off0.map_or(String::new(), |x| format!("{x:.6}")),
                f0.map_or(String::new(), |x| format!("{x:.6}")),
            )?;
            res.push(w);
        }
        // Central-difference slope in km/h per % change.
        let slope = |a: Option<f64>, b: Option<f64>| match (a, b) {
            (Some(a), Some(b)) => format!("{:.3}", (b - a) / (2.0 * args.percent)),
            _ => "-".into(),
        };
        println!(
            "{:<7} | {:>9} {:>9} {:>7} | {:>9} {:>9} {:>7} | {:>8} {:>8}",
            q.name(),
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
    println!("wrote {}", path.display());
    Ok(())
}

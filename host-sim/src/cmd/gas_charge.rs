//! `shimmy-sim gas-charge`: the mining truck's struts (`docs/mining-truck.md`): which initial
//! gas volumes keep the truck free of shimmy at a load and speed (Gao et al.'s question), and
//! the Hopf-window maps over speed x gas volume and speed x payload (PNG + CSV).
use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use plotters::prelude::*;
use shimmy_core::model::LinearModel;
use shimmy_core::stability;
use shimmy_core::units::kmh_to_mps;
use shimmy_core::vehicles::truck::TruckParams;

use crate::model::registry::Registered;
use crate::out::plot_util::{self, diverging};
use crate::sim::input::arg_range::{self, Range};
use crate::sim::input::vehicle_file;
use crate::sim::study::truck_study::{self, WindowPoint};

/// Options of `shimmy-sim gas-charge`.
#[derive(clap::Args, Debug, Clone)]
pub struct GasChargeArgs {
    /// Truck: truck-empty, truck-full or a vehicle file with `model = "mining-truck-5dof"`.
    #[arg(long, default_value = "truck-full")]
    pub vehicle: String,
    /// The speed to be free of shimmy at, km/h: 1 to 250.
    #[arg(long, default_value_t = 30.0, allow_negative_numbers = true, value_parser = arg_range::speed_kmh())]
    pub speed_kmh: f64,
    /// Smallest initial gas volume searched, l: 0.1 to 200.
    #[arg(long, default_value_t = 1.0, allow_negative_numbers = true, value_parser = arg_range::f64_in(GAS_L))]
    pub v0_min_l: f64,
    /// Largest initial gas volume searched, l: 0.1 to 200, above `--v0-min-l`.
    #[arg(long, default_value_t = 60.0, allow_negative_numbers = true, value_parser = arg_range::f64_in(GAS_L))]
    pub v0_max_l: f64,
    /// Grid step of the search (and of the maps' gas axis), l: 0.01 to 50.
    #[arg(long, default_value_t = 1.0, allow_negative_numbers = true, value_parser = arg_range::f64_in(STEP_L))]
    pub step_l: f64,
    /// Highest speed of the maps, km/h: 1 to 250.
    #[arg(long, default_value_t = 70.0, allow_negative_numbers = true, value_parser = arg_range::speed_kmh())]
    pub map_v_max_kmh: f64,
    /// Output folder (`--out`; default out/gas-charge, [`Self::out_dir`]).
    #[command(flatten)]
    pub out: crate::cmd::OutArg,
}

impl GasChargeArgs {
    /// The output folder: `--out`, else out/gas-charge.
    pub fn out_dir(&self) -> PathBuf {
        self.out.dir_or("out/gas-charge")
    }
}

/// Initial gas volume: 0.1 to 200 l (the truck field's range).
pub const GAS_L: Range = Range::closed(0.1, 200.0, "l");
/// Gas grid step: 0.01 to 50 l.
pub const STEP_L: Range = Range::closed(0.01, 50.0, "l");

/// Rows of the payload map.
const PAYLOAD_ROWS: usize = 21;

/// Runs `shimmy-sim gas-charge`; fails when no charge in the range keeps the truck stable.
pub fn command(args: &GasChargeArgs) -> Result<()> {
    anyhow::ensure!(
        args.v0_max_l > args.v0_min_l,
        "--v0-min-l {} must be below --v0-max-l {}",
        args.v0_min_l,
        args.v0_max_l
    );
    let t = match TruckParams::from_any(vehicle_file::load_model(&args.vehicle)?) {
        Ok(t) => t.model,
        Err(_) => bail!(
            "--vehicle `{}`: gas-charge needs a {} vehicle (truck-empty, truck-full or a file with that model)",
            args.vehicle,
            TruckParams::NAME
        ),
    };
    let _out_dir = crate::sim::input::files::OutDir::claim(&args.out_dir())?;
    let ans = truck_study::gas_charge(
        &t,
        args.speed_kmh,
        args.v0_min_l,
        args.v0_max_l,
        args.step_l,
    )?;
    println!(
        "gas charge of `{}` (payload {:.0} t, pre-charge {:.2} MPa) at {} km/h:",
        args.vehicle,
        t.payload_kg * 1e-3,
        t.hps.p0_pa * 1e-6,
        args.speed_kmh
    );
    println!(
        "{:>8} | {:>11} {:>7} | {:>10} {:>11}",
        "V0 l", "growth 1/s", "f Hz", "stroke mm", "k_strut MN/m"
    );
    for r in &ans.rows {
        if r.feasible {
            println!(
                "{:>8.2} | {:>11.4} {:>7.3} | {:>10.1} {:>11.3}",
                r.v0_l,
                r.growth_1ps,
                r.freq_hz,
                r.stroke_mm,
                r.stiffness_npm * 1e-6
            );
        } else {
            println!(
                "{:>8.2} | the struts cannot carry the load at this charge",
                r.v0_l
            );
        }
    }
    let csv = args.out_dir().join("gas-charge.csv");
    write_charge_csv(&csv, &ans)?;

    let gas: Vec<f64> = ans.rows.iter().map(|r| r.v0_l).collect();
    let payloads: Vec<f64> = (0..PAYLOAD_ROWS)
        .map(|i| TruckParams::RATED_PAYLOAD_KG * i as f64 / (PAYLOAD_ROWS - 1) as f64)
        .collect();
    let speeds: Vec<f64> = (0..)
        .map(|i| 1.0 + f64::from(i))
        .take_while(|v| *v <= args.map_v_max_kmh)
        .collect();
    let by_gas = Map::compute(&speeds, &gas, |v0_l| t.with_gas_volume(v0_l * 1e-3))?;
    let by_load = Map::compute(&speeds, &payloads, |kg| t.with_payload(kg))?;
    let gas_csv = args.out_dir().join("hopf-vs-gas.csv");
    by_gas.write_csv(&gas_csv, "v0_l", 1.0)?;
    let load_csv = args.out_dir().join("hopf-vs-load.csv");
    by_load.write_csv(&load_csv, "payload_t", 1e-3)?;
    let png = args.out_dir().join("hopf-map.png");
    plot(&png, &by_gas, &by_load, &args.vehicle, t.hps.v0_m3 * 1e3)?;
    println!();
    println!("onset (first Hopf crossing, km/h) vs initial gas volume at this payload:");
    for w in by_gas
        .windows
        .iter()
        .step_by((by_gas.windows.len() / 12).max(1))
    {
        println!("  {:>7.2} l: {}", w.x, describe(w));
    }
    println!("onset vs payload at V0 = {:.2} l:", t.hps.v0_m3 * 1e3);
    for w in by_load.windows.iter().step_by(4) {
        println!("  {:>7.1} t: {}", w.x * 1e-3, describe(w));
    }
    println!(
        "wrote {}, {}, {}, {}",
        csv.display(),
        gas_csv.display(),
        load_csv.display(),
        png.display()
    );
    println!();
    if ans.stable_l.is_empty() {
        bail!(
            "no initial gas volume in {} .. {} l keeps `{}` free of shimmy at {} km/h",
            args.v0_min_l,
            args.v0_max_l,
            args.vehicle,
            args.speed_kmh
        );
    }
    for (lo, hi) in &ans.stable_l {
        println!(
            "free of shimmy at {} km/h for V0 in {lo:.3} .. {hi:.3} l{}",
            args.speed_kmh,
            if (*hi - args.v0_max_l).abs() < 1e-9 {
                " (to the end of the searched range)"
            } else {
                ""
            }
        );
    }
    if let Some(lo) = ans.least_l() {
        println!("least gas charge: {lo:.3} l");
    }
    Ok(())
}

fn describe(w: &WindowPoint) -> String {
    if !w.feasible {
        return "struts cannot carry the load".into();
    }
    match (w.onset_kmh, w.offset_kmh) {
        (None, _) => format!("no onset up to {} km/h", truck_study::WINDOW_V_MAX_KMH),
        (Some(a), Some(b)) => format!(
            "{a:.2} .. {b:.2} km/h, {:.3} Hz",
            w.freq_hz.unwrap_or(f64::NAN)
        ),
        (Some(a), None) => format!(
            "from {a:.2} km/h to the end, {:.3} Hz",
            w.freq_hz.unwrap_or(f64::NAN)
        ),
    }
}

fn write_charge_csv(path: &Path, ans: &truck_study::ChargeAnswer) -> Result<()> {
    let mut f = Vec::new();
    writeln!(
        f,
        "v0_l,feasible,growth_1ps,freq_hz,stroke_mm,k_strut_npm,speed_kmh"
    )?;
    for r in &ans.rows {
        writeln!(
            f,
            "{},{},{},{},{},{},{}",
            r.v0_l,
            r.feasible,
            r.growth_1ps,
            r.freq_hz,
            r.stroke_mm,
            r.stiffness_npm,
            ans.speed_kmh
        )?;
    }
    crate::sim::input::files::write_file(path, &f)
}

/// Growth rate over speed x one truck parameter, and the first window per row.
struct Map {
    speeds_kmh: Vec<f64>,
    ys: Vec<f64>,
    /// growth[row][speed], NaN where the struts cannot carry the load.
    growth: Vec<Vec<f64>>,
    windows: Vec<WindowPoint>,
}

impl Map {
    fn compute(speeds_kmh: &[f64], ys: &[f64], truck: impl Fn(f64) -> TruckParams) -> Result<Self> {
        let mut growth = Vec::with_capacity(ys.len());
        let mut windows = Vec::with_capacity(ys.len());
        for &y in ys {
            let t = truck(y);
            let feasible = t.operating_point().is_ok();
            growth.push(
                speeds_kmh
                    .iter()
                    .map(|&v| {
                        if feasible {
                            stability::critical_mode_at(&t, kmh_to_mps(v), 0.0).map(|m| m.re)
                        } else {
                            Ok(f64::NAN)
                        }
                    })
                    .collect::<std::result::Result<Vec<_>, _>>()
                    .context("eigen-solve of the map")?,
            );
            windows.push(truck_study::window(&t, y)?);
        }
        Ok(Self {
            speeds_kmh: speeds_kmh.to_vec(),
            ys: ys.to_vec(),
            growth,
            windows,
        })
    }

    fn write_csv(&self, path: &Path, y_name: &str, y_scale: f64) -> Result<()> {
        let mut f = Vec::new();
        writeln!(f, "{y_name},speed_kmh,growth_1ps,onset_kmh,offset_kmh")?;
        for ((y, row), w) in self.ys.iter().zip(&self.growth).zip(&self.windows) {
            let opt = |x: Option<f64>| x.map_or(String::new(), |x| x.to_string());
            for (v, g) in self.speeds_kmh.iter().zip(row) {
                writeln!(
                    f,
                    "{},{v},{g},{},{}",
                    y * y_scale,
                    opt(w.onset_kmh),
                    opt(w.offset_kmh)
                )?;
            }
        }
        crate::sim::input::files::write_file(path, &f)
    }
}

fn plot(path: &Path, by_gas: &Map, by_load: &Map, name: &str, v0_l: f64) -> Result<()> {
    let png = crate::sim::input::files::PendingFile::new(path);
    let root = BitMapBackend::new(png.tmp(), (1000, 900)).into_drawing_area();
    root.fill(&WHITE)?;
    let (top, bottom) = root.split_vertically(450);
    panel(
        &top,
        by_gas,
        &format!("{name}: growth rate [1/s] over speed x initial gas volume"),
        "initial gas volume V0 [l]",
        1.0,
    )?;
    panel(
        &bottom,
        by_load,
        &format!("{name}, V0 = {v0_l:.1} l: growth rate [1/s] over speed x payload"),
        "payload [t]",
        1e-3,
    )?;
    png.commit(root.present())?;
    Ok(())
}

fn panel(
    area: &DrawingArea<BitMapBackend<'_>, plotters::coord::Shift>,
    m: &Map,
    caption: &str,
    y_desc: &str,
    y_scale: f64,
) -> Result<()> {
    let (map_area, bar) = area.split_horizontally(area.dim_in_pixel().0 - plot_util::COLOUR_BAR_PX);
    let ys: Vec<f64> = m.ys.iter().map(|y| y * y_scale).collect();
    let cells = plot_util::cells(&m.speeds_kmh, ys[0], ys[ys.len() - 1], ys.len());
    let g_max = m
        .growth
        .iter()
        .flatten()
        .filter(|g| g.is_finite())
        .fold(0.0_f64, |a, g| a.max(g.abs()))
        .max(1e-9);
    let colour = |g: f64| {
        if g.is_finite() {
            diverging(g / g_max)
        } else {
            RGBColor(200, 200, 200)
        }
    };
    let mut chart = ChartBuilder::on(&map_area)
        .caption(caption, ("sans-serif", 16))
        .margin(10)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(cells.x.clone(), cells.y.clone())?;
    plot_util::mesh(&mut chart, "speed [km/h]", y_desc)?;
    for (row, y) in m.growth.iter().zip(&ys) {
        chart.draw_series(row.iter().zip(&m.speeds_kmh).map(|(g, v)| {
            Rectangle::new(
                [
                    (v - cells.dx / 2.0, y - cells.dy / 2.0),
                    (v + cells.dx / 2.0, y + cells.dy / 2.0),
                ],
                colour(*g).filled(),
            )
        }))?;
    }
    // the Hopf boundary: onset (and offset) per row
    let onset: Vec<(f64, f64)> = m
        .windows
        .iter()
        .zip(&ys)
        .filter_map(|(w, y)| w.onset_kmh.map(|v| (v, *y)))
        .collect();
    chart
        .draw_series(LineSeries::new(onset, BLACK.stroke_width(2)))?
        .label("onset (Hopf)")
        .legend(plot_util::line_marker(BLACK, 2));
    let v_top = m.speeds_kmh.last().copied().unwrap_or(0.0);
    let offset: Vec<(f64, f64)> = m
        .windows
        .iter()
        .zip(&ys)
        .filter_map(|(w, y)| w.offset_kmh.filter(|v| *v <= v_top).map(|v| (v, *y)))
        .collect();
    if !offset.is_empty() {
        chart
            .draw_series(LineSeries::new(offset, BLUE.stroke_width(2)))?
            .label("offset (Hopf)")
            .legend(plot_util::line_marker(BLUE, 2));
    }
    plot_util::legend(&mut chart, SeriesLabelPosition::UpperRight)?;
    plot_util::colour_bar(&bar, -g_max, g_max, "growth rate [1/s]", 30, |g| {
        diverging(g / g_max)
    })?;
    Ok(())
}

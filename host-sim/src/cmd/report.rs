//! `shimmy-sim report [SCENARIO.toml...] [--out DIR] [--controllers a,b]`: runs scenario files
//! (default: the shipped standard set in `host-sim/scenarios/`) and writes one self-contained
//! report (see [`report`]). Every file is parsed and validated before anything runs.

use crate::model::registry::{
    for_each_image_model, image_model_names, image_models, name_of, Registered, StudyTypeVisitor,
};
use crate::model::study::StudyModel;
use crate::out::progress;
use crate::out::provenance::Provenance;
use crate::out::report::{self, Report, ReportRun, Section};
use crate::sim::input::vehicle_file;
use crate::sim::run::scenario::{self, controller_name, ScenarioSpec, CONTROLLERS};
use crate::sim::run::scenario_file::{self, ScenarioModel};
use anyhow::{bail, Context, Result};
use clap::Args;
use rayon::prelude::*;
use shimmy_core::model::LinearModel;
use std::path::{Path, PathBuf};

/// Options of `shimmy-sim report`.
#[derive(Args, Debug, Clone)]
pub struct ReportArgs {
    /// Scenario files (TOML), all on one vehicle model; none = every `*.toml` in
    /// host-sim/scenarios/ (with a truck `--vehicle`: in host-sim/scenarios/truck/).
    pub scenarios: Vec<PathBuf>,
    /// Output folder (`--out`; default out/report, [`Self::out_dir`]).
    #[command(flatten)]
    pub out: crate::cmd::OutArg,
    /// Controllers to run on every scenario (comma separated: no-damper, passive-off,
    /// passive-on, smc, asmc, skyhook); default: each file's own `controller.kind`.
    #[arg(long, value_delimiter = ',')]
    pub controllers: Vec<String>,
    /// Fixed current of `passive-on` when given in `--controllers`, in A: 0 to the coil rating
    /// of the vehicle the firmware believes.
    #[arg(long, default_value_t = 1.0, alias = "on-current", allow_negative_numbers = true, value_parser = crate::sim::input::arg_range::current_a())]
    pub on_current_a: f64,
    /// The simulated vehicle for every scenario (overrides each file's `[plant]`, sensors
    /// included): a named set or a vehicle file (TOML, see docs/vehicle-file.md).
    #[arg(long, visible_alias = "params")]
    pub vehicle: Option<String>,
    /// The vehicle the firmware believes (`--model-vehicle`).
    #[command(flatten)]
    pub model_vehicle: crate::cmd::ModelVehicleArg,
}

impl ReportArgs {
    /// The output folder: `--out`, else out/report.
    pub fn out_dir(&self) -> PathBuf {
        self.out.dir_or("out/report")
    }
}

/// The shipped standard scenario folder: `host-sim/scenarios` below the working directory if it
/// exists, else the one this binary was built from.
pub fn standard_dir() -> PathBuf {
    let local = Path::new("host-sim/scenarios");
    if local.is_dir() {
        local.to_path_buf()
    } else {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("scenarios")
    }
}

/// The `*.toml` files of `dir`, sorted by name.
pub fn scenario_files(dir: &Path) -> Result<Vec<PathBuf>> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .with_context(|| format!("reading {}", dir.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .collect();
    v.sort();
    if v.is_empty() {
        bail!("no scenario files (*.toml) in {}", dir.display());
    }
    Ok(v)
}

/// The `--controllers` list by their one name each (short forms accepted).
fn controllers(a: &ReportArgs) -> Result<Vec<&'static str>> {
    a.controllers
        .iter()
        .map(|c| match controller_name(c) {
            Some(n) => Ok(n),
            None => bail!("--controllers {c}: allowed: {}", CONTROLLERS.join(", ")),
        })
        .collect()
}

/// Loads and validates every file (nothing runs if one is bad), expands the controller list;
/// every file is on the model `M` (none given: `M`'s shipped scenarios).
pub fn plan<M: ScenarioModel<N>, const N: usize>(
    a: &ReportArgs,
) -> Result<Vec<(PathBuf, Vec<ScenarioSpec<M, N>>)>> {
    let files = if a.scenarios.is_empty() {
        scenario_files(&standard_dir().join(M::SCENARIO_DIR))?
    } else {
        a.scenarios.clone()
    };
    let controllers = controllers(a)?;
    files
        .into_iter()
        .map(|f| {
            let spec = M::scenario(scenario_file::load_any(&f)?)
                .with_context(|| format!("scenario file {}", f.display()))?;
            // One run per `--controllers` entry, else the file's own controller.
            let runs: Vec<Option<(&str, f64)>> = if controllers.is_empty() {
                vec![None]
            } else {
                controllers
                    .iter()
                    .map(|&c| Some((c, a.on_current_a)))
                    .collect()
            };
            let specs = runs
                .into_iter()
                .map(|controller| {
                    let mut s = spec.clone();
                    s.apply_overrides(a.vehicle.as_deref(), a.model_vehicle.given(), controller)
                        .with_context(|| format!("scenario file {}", f.display()))?;
                    Ok(s)
                })
                .collect::<Result<Vec<_>>>()?;
            Ok((f, specs))
        })
        .collect()
}

/// Runs `plan` (all runs in parallel) and builds the report.
pub fn build<M: ScenarioModel<N>, const N: usize>(
    a: &ReportArgs,
    plan: Vec<(PathBuf, Vec<ScenarioSpec<M, N>>)>,
) -> Result<Report<M, N>> {
    let jobs: Vec<(usize, &ScenarioSpec<M, N>)> = plan
        .iter()
        .enumerate()
        .flat_map(|(i, (_, specs))| specs.iter().map(move |s| (i, s)))
        .collect();
    let bar = progress::bar(jobs.len(), "closed-loop runs");
    let runs: Vec<(usize, ReportRun<M, N>)> = jobs
        .par_iter()
        .map(|&(i, spec)| {
            let (cfg, r) = scenario::run(spec)
                .with_context(|| format!("{} / {}", spec.name, spec.controller))?;
            bar.inc(1);
            Ok((i, ReportRun::new(&spec.controller, cfg, r, spec.t_dist_s)))
        })
        .collect::<Result<_>>()?;
    bar.finish_and_clear();
    let mut sections: Vec<Section<M, N>> = plan
        .iter()
        .map(|(file, specs)| {
            let s = &specs[0];
            Section {
                name: s.name.clone(),
                description: format!(
                    "File `{}`: {} s, seed {}, initial in-phase wheel yaw {:.2} deg, encoder {} bit.",
                    file.display(),
                    s.duration_s,
                    s.sensors.seed,
                    s.initial_yaw_rad.to_degrees(),
                    s.sensors.encoder_bits
                ),
                runs: Vec::new(),
                extra_plots: Vec::new(),
            }
        })
        .collect();
    for (i, r) in runs {
        sections[i].runs.push(r);
    }
    let mut provenance = Provenance::of_this_process();
    for (file, specs) in &plan {
        provenance = provenance.file("scenario file", file)?;
        if let Some(s) = specs.first() {
            provenance = provenance.seed(
                &format!("{} (road and sensor noise)", s.name),
                s.sensors.seed,
            );
        }
    }
    for (role, spec) in [
        ("vehicle", &a.vehicle),
        ("model vehicle", &a.model_vehicle.spec),
    ] {
        if let Some(v) = spec {
            provenance = provenance.model_vehicle(role, v, &vehicle_file::load_model(v)?)?;
        }
    }
    Ok(Report {
        title: "shimmy-sim scenario report".into(),
        intro: format!(
            "{} scenario file(s), closed loop at 1 kHz: nonlinear {} plant with the Spencer MR damper, simulated sensors, the firmware's `shimmy-core` controller and mode meter. Controllers: {}.",
            sections.len(),
            <M::Linear as LinearModel<N>>::NAME,
            if a.controllers.is_empty() {
                "each file's own".to_string()
            } else {
                controllers(a)?.join(", ")
            }
        ),
        sections,
        provenance: Some(provenance),
    })
}

/// The vehicle model of the report: `--vehicle`'s, else the first file's, else the first
/// model with a firmware image (the car).
fn model_name(a: &ReportArgs) -> Result<&'static str> {
    if let Some(v) = &a.vehicle {
        return Ok(vehicle_file::load_model(v)
            .context("--vehicle")?
            .model_name());
    }
    Ok(match a.scenarios.first() {
        Some(f) => scenario_file::load_any(f)?.model_name(),
        None => image_model_names()[0],
    })
}

/// The command.
pub fn command(a: &ReportArgs) -> Result<()> {
    struct On<'a>(&'a ReportArgs, &'static str, Option<Result<()>>);
    impl StudyTypeVisitor for On<'_> {
        fn visit<M: Registered<N> + StudyModel<N>, const N: usize>(&mut self) {
            if self.2.is_none() && name_of::<M, N>() == self.1 {
                self.2 = Some(command_on::<M, N>(self.0));
            }
        }
    }
    let mut on = On(a, model_name(a)?, None);
    for_each_image_model(&mut on);
    match on.2 {
        Some(r) => r,
        None => bail!(
            "`report` runs scenario files on the {} models, not the {}",
            image_models(),
            on.1
        ),
    }
}

/// The command on scenarios of the model `M`.
fn command_on<M: ScenarioModel<N>, const N: usize>(a: &ReportArgs) -> Result<()> {
    let plan = plan::<M, N>(a)?;
    let out_dir = crate::sim::input::files::OutDir::claim(&a.out_dir())?;
    let report = build(a, plan)?;
    let w = report::write(&out_dir, &report)?;
    let rows: Vec<(&str, &ReportRun<M, N>)> = report
        .sections
        .iter()
        .flat_map(|s| s.runs.iter().map(move |r| (s.name.as_str(), r)))
        .collect();
    println!("{}", report::metrics_table(&rows));
    println!(
        "wrote {} plots and {} CSV files; report: {}",
        w.plots.len(),
        w.csv.len(),
        w.report.display()
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::out::plot_util::assert_real_plot;

    fn tmp(name: &str) -> PathBuf {
        std::env::temp_dir().join(format!("shimmy-report-{name}-{}", std::process::id()))
    }

    #[test]
    fn report_of_two_files_and_two_controllers() {
        let dir = tmp("ok");
        std::fs::create_dir_all(&dir).unwrap();
        let f1 = dir.join("kick.toml");
        std::fs::write(
            &f1,
            "name = \"kick\"\nduration_s = 8.0\n[speed]\nconstant_kmh = 55.0\n[initial]\nyaw_deg = 1.0\n[road_noise]\nstd_nm = 10.0\ncorner_hz = 20.0\ncommon = 0.5\n",
        )
        .unwrap();
        let f2 = dir.join("bump.toml");
        std::fs::write(
            &f2,
            "name = \"bump\"\nduration_s = 2.0\n[speed]\nconstant_kmh = 60.0\n[[impulse]]\nt_s = 0.5\nduration_s = 0.02\npeak_nm = 400.0\n",
        )
        .unwrap();
        let out = dir.join("out");
        let a = ReportArgs {
            scenarios: vec![f1, f2],
            out: crate::cmd::OutArg::new(&out),
            controllers: vec!["passive-off".into(), "asmc".into()],
            on_current_a: 1.0,
            vehicle: None,
            model_vehicle: Default::default(),
        };
        command(&a).unwrap();
        let md = std::fs::read_to_string(out.join("report.md")).unwrap();
        crate::out::html::check_tables(&md).unwrap();
        // The same page self-contained, and the metrics for scripts, with provenance.
        let html = std::fs::read_to_string(out.join("report.html")).unwrap();
        assert_eq!(html.matches("src=\"data:image/png;base64,").count(), 3);
        let json: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap())
                .unwrap();
        assert_eq!(json["metrics"]["runs"].as_array().unwrap().len(), 4);
        assert_eq!(json["provenance"]["inputs"][0]["role"], "scenario file");
        assert!(
            md.contains("| seed: kick (road and sensor noise) | 1 |"),
            "{md}"
        );
        for needle in [
            "## kick",
            "## bump",
            "| kick | asmc |",
            "| bump | passive-off |",
        ] {
            assert!(md.contains(needle), "report lacks `{needle}`");
        }
        // Every referenced plot exists and is a real picture.
        for png in ["kick-time.png", "kick-margin.png", "bump-time.png"] {
            assert!(md.contains(png), "{png} not referenced");
            assert_real_plot(&out.join(png), 8).unwrap();
        }
        // metrics.csv: header + 4 runs; the ASMC kick settles, and the same runs as `run`
        // (one place computes both).
        let csv = std::fs::read_to_string(out.join("metrics.csv")).unwrap();
        assert_eq!(csv.lines().count(), 5, "{csv}");
        let mut spec = scenario_file::load(&dir.join("kick.toml")).unwrap();
        spec.controller = "asmc".into();
        let (cfg, r) = scenario::run(&spec).unwrap();
        let m = r.metrics(&cfg, Some(0.0));
        let row = csv.lines().find(|l| l.starts_with("kick,asmc,")).unwrap();
        let peak: f64 = row.split(',').nth(2).unwrap().parse().unwrap();
        assert_eq!(peak, m.peak_yaw_rad.to_degrees());
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_bad_file_stops_the_report_before_anything_runs() {
        let dir = tmp("bad");
        std::fs::create_dir_all(&dir).unwrap();
        let good = dir.join("good.toml");
        std::fs::write(&good, "duration_s = 1.0\n[speed]\nconstant_kmh = 40.0\n").unwrap();
        let bad = dir.join("bad.toml");
        std::fs::write(&bad, "duration_s = -1.0\n[speed]\nconstant_kmh = 40.0\n").unwrap();
        let out = dir.join("out");
        let a = ReportArgs {
            scenarios: vec![good, bad],
            out: crate::cmd::OutArg::new(&out),
            controllers: vec![],
            on_current_a: 1.0,
            vehicle: None,
            model_vehicle: Default::default(),
        };
        let e = format!("{:#}", command(&a).unwrap_err());
        assert!(e.contains("duration_s"), "{e}");
        assert!(!out.exists(), "nothing may be written");
        let a = ReportArgs {
            controllers: vec!["pid".into()],
            scenarios: vec![dir.join("good.toml")],
            ..a
        };
        assert!(format!("{:#}", command(&a).unwrap_err()).contains("--controllers pid"));
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn the_standard_set_is_found_and_valid() {
        let a = ReportArgs {
            scenarios: vec![],
            out: crate::cmd::OutArg::new(tmp("std")),
            controllers: vec![],
            on_current_a: 1.0,
            vehicle: None,
            model_vehicle: Default::default(),
        };
        let plan = plan::<
            shimmy_core::vehicles::car::PlantParams,
            { shimmy_core::vehicles::car::N_STATES },
        >(&a)
        .unwrap();
        assert!(plan.len() >= 7, "{} files", plan.len());
    }
}

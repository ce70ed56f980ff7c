//! `shimmy-fmu-bundle LIB FMU`: packs the built shared library `LIB` (libshimmy_fmu.so) into the
//! FMI 3.0 archive `FMU` with the modelDescription.xml generated from the model's own variable
//! table (`fmi-export`'s metadata of `ShimmyController`, the same one the library serves).
use std::io::Write;
use std::path::Path;
use std::process::ExitCode;

use fmi::schema::fmi3::{DefaultExperiment, Fmi3CoSimulation, Fmi3ModelDescription};
use fmi_export::fmi3::Model;
use shimmy_fmu::{ShimmyController, CONTROL_PERIOD_S};

/// The model identifier: the library's name inside `binaries/<platform>/`.
const MODEL_IDENTIFIER: &str = "shimmy_fmu";

fn model_description() -> Fmi3ModelDescription {
    let meta = ShimmyController::build_toplevel_metadata();
    Fmi3ModelDescription {
        fmi_version: "3.0".into(),
        model_name: "shimmy".into(),
        instantiation_token: ShimmyController::INSTANTIATION_TOKEN.into(),
        description: Some(
            "Supervised adaptive sliding-mode MR steering-damper controller and \
             eigenvalue-margin monitor (shimmy-core), 1 kHz"
                .into(),
        ),
        version: Some(env!("CARGO_PKG_VERSION").into()),
        license: Some(env!("CARGO_PKG_LICENSE").into()),
        generation_tool: Some("shimmy-fmu-bundle (fmi-export)".into()),
        model_variables: meta.model_variables,
        model_structure: meta.model_structure,
        default_experiment: Some(DefaultExperiment {
            start_time: Some(0.0),
            stop_time: Some(10.0),
            step_size: Some(CONTROL_PERIOD_S),
            ..Default::default()
        }),
        co_simulation: Some(Fmi3CoSimulation {
            model_identifier: MODEL_IDENTIFIER.into(),
            can_handle_variable_communication_step_size: Some(true),
            fixed_internal_step_size: Some(CONTROL_PERIOD_S),
            has_event_mode: Some(false),
            can_get_and_set_fmu_state: Some(false),
            can_serialize_fmu_state: Some(false),
            ..Default::default()
        }),
        ..Default::default()
    }
}

fn bundle(lib: &Path, fmu: &Path) -> Result<(), String> {
    let xml = fmi::schema::serialize(&model_description(), false)
        .map_err(|e| format!("modelDescription.xml: {e}"))?;
    let platform = fmi::fmi3::platform_folder(std::env::consts::OS, std::env::consts::ARCH)
        .map_err(|e| format!("platform: {e}"))?;
    let ext = lib
        .extension()
        .and_then(|e| e.to_str())
        .ok_or_else(|| format!("{}: no file extension", lib.display()))?;
    let so = std::fs::read(lib).map_err(|e| format!("{}: {e}", lib.display()))?;
    if let Some(dir) = fmu.parent() {
        std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    }
    let file = std::fs::File::create(fmu).map_err(|e| format!("{}: {e}", fmu.display()))?;
    let mut zip = zip::ZipWriter::new(file);
    let opts = zip::write::SimpleFileOptions::default();
    let zip_err = |e: zip::result::ZipError| format!("{}: {e}", fmu.display());
    let io_err = |e: std::io::Error| format!("{}: {e}", fmu.display());
    zip.start_file("modelDescription.xml", opts)
        .map_err(zip_err)?;
    zip.write_all(xml.as_bytes()).map_err(io_err)?;
    zip.start_file(
        format!("binaries/{platform}/{MODEL_IDENTIFIER}.{ext}"),
        opts,
    )
    .map_err(zip_err)?;
    zip.write_all(&so).map_err(io_err)?;
    zip.finish().map_err(zip_err)?;
    Ok(())
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [lib, fmu] = args.as_slice() else {
        eprintln!("usage: shimmy-fmu-bundle LIB FMU (e.g. target/debug/libshimmy_fmu.so target/fmu/shimmy_fmu.fmu)");
        return ExitCode::from(2);
    };
    match bundle(Path::new(lib), Path::new(fmu)) {
        Ok(()) => {
            println!("wrote {fmu}");
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("shimmy-fmu-bundle: {e}");
            ExitCode::FAILURE
        }
    }
}

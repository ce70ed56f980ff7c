//! The FMU: `fmu/` (crate `shimmy-fmu`, fmi-export) from the host build (dev profile), packed
//! into `target/fmu/shimmy_fmu.fmu` by its `shimmy-fmu-bundle` binary, then validated and
//! co-simulated with fmpy against the SciPy reference plant (`fmu/tests/`, pytest; the
//! simulator's side of the comparison through the `shimmy_sim` module of the host build).

use std::path::PathBuf;
use std::process::Command;

use crate::{apt_install, python, root, run, Step};

/// fmi-sys generates its FMI bindings with bindgen, which loads libclang: every workspace
/// build (clippy, doc, test) needs it.
pub fn ensure_libclang() -> Result<(), String> {
    let found = Command::new("sh")
        .args(["-c", "ldconfig -p | grep -q 'libclang[-.0-9]*\\.so'"])
        .status()
        .is_ok_and(|s| s.success());
    if found {
        return Ok(());
    }
    apt_install(
        "libclang-dev",
        "libclang is missing (bindgen in fmi-sys needs it)",
        "install it with: apt-get install libclang-dev (Debian/Ubuntu), or set LIBCLANG_PATH",
    )
}

/// Builds the FMU and returns its path.
pub fn build() -> Result<PathBuf, String> {
    ensure_libclang()?;
    let debug = crate::host_build()?;
    let lib = debug.join(format!(
        "{}shimmy_fmu{}",
        std::env::consts::DLL_PREFIX,
        std::env::consts::DLL_SUFFIX
    ));
    let fmu = root().join("target").join("fmu").join("shimmy_fmu.fmu");
    run(Command::new(debug.join("shimmy-fmu-bundle"))
        .arg(&lib)
        .arg(&fmu))?;
    Ok(fmu)
}

/// Builds the FMU, then runs `fmu/tests` (fmpy validation and the co-simulation).
pub fn tests() -> Step {
    let fmu = build()?;
    let py = python::venv_python()?;
    python::ensure_packages(
        &py,
        &[("fmpy", "fmpy"), ("pytest", "pytest"), ("scipy", "scipy")],
    )?;
    let module = python::module_dir()?;
    python::check_module_origin(&py, &module)?;
    python::pytest_with(
        &py,
        "fmu/tests",
        &[
            ("SHIMMY_FMU", fmu.as_os_str()),
            ("PYTHONPATH", module.as_os_str()),
        ],
    )
}

//! `cargo xtask python` (a step of `cargo xtask test`): a virtual environment in
//! `target/py-venv` (it sees the system's numpy/scipy; what is missing is installed into it with
//! pip, never into the system) and the pytest suite, run on the `shimmy_sim` module that the host
//! build made (`target/debug/libshimmy_py.so`, staged as `target/py-module/shimmy_sim.so` and put
//! first on `PYTHONPATH`). `--wheel` runs it on the wheel that `pip install ./python` builds
//! instead (maturin), which compiles the simulator's dependencies a second time: maturin builds
//! `python/` alone, with that package's feature resolution.

use std::ffi::OsStr;
use std::path::{Path, PathBuf};
use std::process::Command;

use crate::{root, run, Step};

/// The virtual environment's interpreter, created on first use.
pub fn venv_python() -> Result<PathBuf, String> {
    let venv = root().join("target").join("py-venv");
    let python = venv.join("bin").join("python");
    if !python.exists() {
        run(Command::new("python3")
            .args(["-m", "venv", "--system-site-packages"])
            .arg(&venv))
        .map_err(|e| format!("{e}\nNeeds python3 with the venv module"))?;
    }
    Ok(python)
}

/// Installs into the venv each of `packages` (pip name, import name) that does not import.
pub fn ensure_packages(python: &Path, packages: &[(&str, &str)]) -> Result<(), String> {
    let missing: Vec<&str> = packages
        .iter()
        .filter(|(_, module)| {
            !Command::new(python)
                .args(["-c", &format!("import {module}")])
                .output()
                .is_ok_and(|o| o.status.success())
        })
        .map(|(pip, _)| *pip)
        .collect();
    if missing.is_empty() {
        return Ok(());
    }
    crate::say(&format!(
        "xtask: installing {} with pip",
        missing.join(", ")
    ));
    run(Command::new(python)
        .args(["-m", "pip", "install", "--quiet"])
        .args(&missing))
}

/// What the Python tests import besides `shimmy_sim` (pip name, import name).
const TEST_PACKAGES: &[(&str, &str)] = &[
    ("pytest", "pytest"),
    ("numpy", "numpy"),
    ("scipy", "scipy"),
    ("dask", "dask"),
    ("distributed", "distributed"),
];

/// The `shimmy_sim` extension module of [`crate::host_build`], copied under the name Python imports
/// (`shimmy_sim.so`) into a directory of its own; returns that directory, for `PYTHONPATH`.
pub fn module_dir() -> Result<PathBuf, String> {
    let built = crate::host_build()?.join(format!(
        "{}shimmy_py{}",
        std::env::consts::DLL_PREFIX,
        std::env::consts::DLL_SUFFIX
    ));
    let dir = root().join("target").join("py-module");
    std::fs::create_dir_all(&dir).map_err(|e| format!("create {}: {e}", dir.display()))?;
    let module = dir.join(if cfg!(windows) {
        "shimmy_sim.pyd"
    } else {
        "shimmy_sim.so"
    });
    std::fs::copy(&built, &module).map_err(|e| format!("copy {}: {e}", built.display()))?;
    Ok(dir)
}

/// `python` imports `shimmy_sim` from `dir` (not from a wheel installed in the venv by `--wheel`).
pub fn check_module_origin(python: &Path, dir: &Path) -> Result<(), String> {
    let out = Command::new(python)
        .args(["-c", "import shimmy_sim; print(shimmy_sim.__file__)"])
        .env("PYTHONPATH", dir)
        .output()
        .map_err(|e| format!("cannot run {}: {e}", python.display()))?;
    let file = String::from_utf8_lossy(&out.stdout).trim().to_string();
    if !out.status.success() {
        return Err(format!(
            "import shimmy_sim failed: {}",
            String::from_utf8_lossy(&out.stderr).trim()
        ));
    }
    if Path::new(&file).parent() != Some(dir) {
        return Err(format!(
            "import shimmy_sim found {file}, not the module in {}",
            dir.display()
        ));
    }
    Ok(())
}

/// Runs `python/tests` with pytest on the module of the host build.
pub fn module_tests() -> Step {
    let python = venv_python()?;
    ensure_packages(&python, TEST_PACKAGES)?;
    let dir = module_dir()?;
    check_module_origin(&python, &dir)?;
    pytest_with(&python, "python/tests", &[("PYTHONPATH", dir.as_os_str())])
}

/// Builds the `shimmy-sim` wheel as `pip install ./python` does (maturin), installs it into the
/// venv and runs `python/tests` with pytest on it.
pub fn wheel_tests() -> Step {
    let python = venv_python()?;
    ensure_packages(&python, TEST_PACKAGES)?;
    // maturin runs as the venv's script (`python -m maturin` looks for it beside the venv's
    // interpreter): installed into the venv even when the system has one.
    let maturin = python.with_file_name("maturin");
    if !maturin.exists() {
        crate::say("xtask: installing maturin into the venv with pip");
        run(Command::new(&python).args([
            "-m",
            "pip",
            "install",
            "--quiet",
            "--ignore-installed",
            "maturin>=1.7,<2",
        ]))?;
    }
    let wheels = root().join("target").join("wheels-dev");
    if wheels.exists() {
        std::fs::remove_dir_all(&wheels).map_err(|e| format!("{}: {e}", wheels.display()))?;
    }
    run(Command::new(&maturin)
        .args(["build", "--quiet", "--profile", "dev"])
        .args(["-m", "python/Cargo.toml", "--interpreter"])
        .arg(&python)
        .arg("--out")
        .arg(&wheels)
        .current_dir(root()))?;
    let wheel = std::fs::read_dir(&wheels)
        .map_err(|e| format!("{}: {e}", wheels.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .find(|p| p.extension().is_some_and(|x| x == "whl"))
        .ok_or("maturin wrote no wheel")?;
    run(Command::new(&python)
        .args([
            "-m",
            "pip",
            "install",
            "--quiet",
            "--force-reinstall",
            "--no-deps",
        ])
        .arg(&wheel))?;
    pytest(&python, "python/tests")
}

/// Runs pytest on `dir` and returns its summary line.
pub fn pytest(python: &Path, dir: &str) -> Step {
    pytest_with(python, dir, &[])
}

/// [`pytest`] with extra environment variables.
pub fn pytest_with(python: &Path, dir: &str, env: &[(&str, &OsStr)]) -> Step {
    let out = Command::new(python)
        .args(["-m", "pytest", "-q", "-p", "no:cacheprovider", dir])
        .envs(env.iter().copied())
        .current_dir(root())
        .output()
        .map_err(|e| format!("cannot run pytest: {e}"))?;
    let stdout = String::from_utf8_lossy(&out.stdout);
    print!("{stdout}");
    eprint!("{}", String::from_utf8_lossy(&out.stderr));
    let summary = stdout
        .lines()
        .rev()
        .find(|l| l.contains(" passed") || l.contains(" failed") || l.contains("error"))
        .unwrap_or("")
        .trim()
        .to_string();
    if out.status.success() {
        Ok(summary)
    } else {
        Err(format!("pytest {dir} failed: {summary}"))
    }
}

//! `cargo xtask python` (run by hand, not a step of `cargo xtask test`): a virtual environment in `target/py-venv` (it sees
//! the system's numpy/scipy; what is missing is installed into it with pip, never into the
//! system), the `shimmy` wheel built with maturin (dev profile: the workspace's compiled
//! dependencies are reused) and its pytest suite.

use std::path::PathBuf;
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
pub fn ensure_packages(python: &PathBuf, packages: &[(&str, &str)]) -> Result<(), String> {
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
    println!("xtask: installing {} with pip", missing.join(", "));
    run(Command::new(python)
        .args(["-m", "pip", "install", "--quiet"])
        .args(&missing))
}

/// Builds the `shimmy` wheel, installs it into the venv and runs `python/tests` with pytest.
pub fn package_tests() -> Step {
    let python = venv_python()?;
    ensure_packages(
        &python,
        &[("pytest", "pytest"), ("numpy", "numpy"), ("scipy", "scipy")],
    )?;
    // maturin runs as the venv's script (`python -m maturin` looks for it beside the venv's
    // interpreter): installed into the venv even when the system has one.
    let maturin = python.with_file_name("maturin");
    if !maturin.exists() {
        println!("xtask: installing maturin into the venv with pip");
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
pub fn pytest(python: &PathBuf, dir: &str) -> Step {
    pytest_with(python, dir, &[])
}

/// [`pytest`] with extra environment variables.
pub fn pytest_with(python: &PathBuf, dir: &str, env: &[(&str, &std::ffi::OsStr)]) -> Step {
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

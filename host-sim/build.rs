//! Build-time provenance for the reports: `SHIMMY_GIT` is `git describe --always --dirty
//! --tags` of the source tree, or a sentence saying why there is none (no git, not a
//! checkout), so a build from a tarball still works and says so.

use std::process::Command;

fn git(args: &[&str]) -> Option<String> {
    let out = Command::new("git").args(args).output().ok()?;
    if !out.status.success() {
        return None;
    }
    let s = String::from_utf8(out.stdout).ok()?.trim().to_string();
    (!s.is_empty()).then_some(s)
}

fn main() {
    let describe = match git(&["describe", "--always", "--dirty", "--tags"]) {
        Some(d) => d,
        None if git(&["--version"]).is_none() => "unknown (built without git)".to_string(),
        None => "unknown (not built from a git checkout)".to_string(),
    };
    println!("cargo:rustc-env=SHIMMY_GIT={describe}");
    // Rebuild on a new commit or checkout (HEAD and the branch it points to) and on source
    // edits (for the `-dirty` mark). Only files that exist are named: cargo reruns a build
    // script on every build while a file it names is missing (a branch whose ref is only in
    // packed-refs, or a clone without packed-refs), and that rebuilt the simulator and
    // everything above it in every cargo call of `cargo xtask test`.
    let watch = |path: String| {
        if std::path::Path::new(&path).exists() {
            println!("cargo:rerun-if-changed={path}");
        }
    };
    if let Some(dir) = git(&["rev-parse", "--git-dir"]) {
        watch(format!("{dir}/HEAD"));
    }
    if let (Some(common), Some(head)) = (
        git(&["rev-parse", "--git-common-dir"]),
        git(&["symbolic-ref", "-q", "HEAD"]),
    ) {
        watch(format!("{common}/{head}"));
        watch(format!("{common}/packed-refs"));
    }
    for d in ["src", "../core/src", "build.rs"] {
        println!("cargo:rerun-if-changed={d}");
    }
}

//! `docs/measurements.md`: the figures that the firmware's size and benchmark steps measure,
//! written by `cargo xtask docs` and checked by `cargo xtask test`.
//!
//! The file is made of generated sections, each between a begin and an end marker. A step of
//! `cargo xtask test` renders its section from what it just measured and fails when the file's
//! section differs, so a figure in the docs is never older than the code. Only deterministic
//! figures go in: flash and static RAM of the release images (same toolchain, same bytes) and
//! instruction counts under QEMU `-icount` (same image, same count); no wall times.

use std::path::PathBuf;

/// The file, relative to the workspace root.
pub const PATH: &str = "docs/measurements.md";

/// The sections in the order the file lists them: (name, heading, the command that measures).
pub const SECTIONS: [(&str, &str, &str); 2] = [
    ("size", "Flash and static RAM", "cargo xtask size"),
    (
        "bench",
        "Instructions on the target (car image, QEMU -icount)",
        "cargo xtask bench --target-only",
    ),
];

const PREAMBLE: &str = "# Measurements

Written by `cargo xtask docs`; `cargo xtask test` fails when a section here differs from what its
step measures, so these figures belong to the commit they are in. Each section names the command
that prints the same figures with more detail. Instructions are counted under QEMU with
`-icount shift=0` (one virtual nanosecond per instruction; the bench calibrates the counter first,
`docs/firmware.md`); on the real Cortex-M4 at 168 MHz, flash wait states and FPU timing make it
about 1-1.5 cycles per instruction.
";

fn path() -> PathBuf {
    crate::root().join(PATH)
}

fn begin(name: &str) -> String {
    format!("<!-- measured: {name} -->")
}

fn end(name: &str) -> String {
    format!("<!-- end: {name} -->")
}

/// The section `name` of `text` (between its markers, without them), if present.
fn section_of<'a>(text: &'a str, name: &str) -> Option<&'a str> {
    let (b, e) = (begin(name), end(name));
    let start = text.find(&b)? + b.len();
    let stop = start + text[start..].find(&e)?;
    Some(text[start..stop].trim_matches('\n'))
}

/// Checks that the file's section `name` is `body`; the error names the first differing line
/// and the command that writes the file.
pub fn check(name: &str, body: &str) -> Result<(), String> {
    let text = std::fs::read_to_string(path()).map_err(|e| format!("read {PATH}: {e}"))?;
    let stale = |detail: String| {
        Err(format!(
            "{PATH} is stale in its `{name}` section ({detail}): run `cargo xtask docs` and commit it"
        ))
    };
    let Some(found) = section_of(&text, name) else {
        return stale("section missing".into());
    };
    let body = body.trim_matches('\n');
    if found == body {
        return Ok(());
    }
    let mut want = body.lines();
    let mut have = found.lines();
    for line in 1.. {
        match (want.next(), have.next()) {
            (Some(w), Some(h)) if w == h => continue,
            (w, h) => {
                return stale(format!(
                    "line {line}: measured `{}`, file has `{}`",
                    w.unwrap_or("(end)"),
                    h.unwrap_or("(end)")
                ))
            }
        }
    }
    unreachable!("the loop returns at the first difference")
}

/// The whole file from its sections' bodies, in [`SECTIONS`] order.
pub fn render(bodies: &[(&str, String)]) -> Result<String, String> {
    let mut out = String::from(PREAMBLE);
    for (name, heading, command) in SECTIONS {
        let body = bodies
            .iter()
            .find(|(n, _)| *n == name)
            .map(|(_, b)| b)
            .ok_or_else(|| format!("no measurement for the `{name}` section"))?;
        out.push_str(&format!(
            "\n## {heading}\n\n`{command}`\n\n{}\n{}\n{}\n",
            begin(name),
            body.trim_matches('\n'),
            end(name)
        ));
    }
    Ok(out)
}

/// Writes the file from its sections' bodies.
pub fn write(bodies: &[(&str, String)]) -> Result<(), String> {
    let text = render(bodies)?;
    std::fs::write(path(), text).map_err(|e| format!("write {PATH}: {e}"))
}

/// A Markdown table from a header and rows (cells as given, `|` escaped).
pub fn table(header: &[&str], align_right: &[bool], rows: &[Vec<String>]) -> String {
    let cell = |s: &str| s.replace('|', "\\|");
    let mut out = format!("| {} |\n|", header.join(" | "));
    for right in align_right {
        out.push_str(if *right { "---:|" } else { "---|" });
    }
    out.push('\n');
    for r in rows {
        let cells: Vec<String> = r.iter().map(|c| cell(c)).collect();
        out.push_str(&format!("| {} |\n", cells.join(" | ")));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn bodies() -> Vec<(&'static str, String)> {
        vec![("size", "a\nb".into()), ("bench", "c".into())]
    }

    #[test]
    fn a_rendered_file_holds_each_section_and_a_changed_figure_is_named() {
        let text = render(&bodies()).unwrap();
        assert_eq!(section_of(&text, "size"), Some("a\nb"));
        assert_eq!(section_of(&text, "bench"), Some("c"));
        assert_eq!(section_of(&text, "other"), None);
    }

    #[test]
    fn a_missing_section_is_an_error() {
        assert!(render(&[("size", "a".into())]).is_err());
    }

    #[test]
    fn tables_escape_bars() {
        let t = table(
            &["a", "b"],
            &[false, true],
            &[vec!["x|y".into(), "1".into()]],
        );
        assert_eq!(t, "| a | b |\n|---|---:|\n| x\\|y | 1 |\n");
    }
}

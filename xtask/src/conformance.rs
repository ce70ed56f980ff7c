//! Host/target conformance: the host test writes the replay digests of the committed sensor
//! trace (`target/conformance/host.txt`), the target program prints the same under QEMU; every
//! channel must agree bit for bit.

use crate::{build_firmware, host_cargo, qemu, root};

/// One digest line: `conformance | channel | count | hash | last value bits`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Row {
    pub channel: String,
    pub fields: Vec<String>,
}

/// Parses the digest rows out of log lines (anything else is ignored).
pub fn parse(lines: &[String]) -> Vec<Row> {
    lines
        .iter()
        .filter_map(|l| l.split_once("conformance | ").map(|x| x.1))
        .map(|rest| {
            let mut it = rest.split(" | ").map(|s| s.trim().to_string());
            let channel = it.next().unwrap_or_default();
            Row {
                channel,
                fields: it.collect(),
            }
        })
        .collect()
}

/// Compares host and target rows; `Err` names every channel that differs or is missing.
pub fn compare(host: &[Row], target: &[Row]) -> Result<usize, String> {
    if host.is_empty() {
        return Err("the host wrote no digest rows".into());
    }
    let mut bad = Vec::new();
    for h in host {
        match target.iter().find(|t| t.channel == h.channel) {
            Some(t) if t.fields == h.fields => {}
            Some(t) => bad.push(format!(
                "{}: host {:?} target {:?}",
                h.channel, h.fields, t.fields
            )),
            None => bad.push(format!("{}: missing on the target", h.channel)),
        }
    }
    if target.len() != host.len() {
        bad.push(format!(
            "{} target rows vs {} host rows",
            target.len(),
            host.len()
        ));
    }
    if bad.is_empty() {
        Ok(host.len())
    } else {
        Err(format!("host/target mismatch: {}", bad.join("; ")))
    }
}

/// The `cargo xtask test` step.
pub fn step() -> Result<String, String> {
    // `--workspace` (not `-p shimmy-tests`) resolves the same features as the host-test step,
    // so this reuses its build instead of compiling ~50 dependencies again.
    host_cargo(&[
        "test",
        "--workspace",
        "--test",
        "cross_crate",
        "conformance::",
        "--",
        "--test-threads",
        "1",
    ])?;
    let path = root().join("target/conformance/host.txt");
    let text = std::fs::read_to_string(&path).map_err(|e| format!("{}: {e}", path.display()))?;
    let host = parse(&text.lines().map(str::to_string).collect::<Vec<_>>());
    let elf = build_firmware("conformance", &["qemu"])?;
    let run = qemu::run(&elf)?;
    run.print();
    run.expect_success()?;
    let target = parse(&run.log);
    println!(
        "  {:<28} {:>6} {:>18} {:>18}  result",
        "channel", "count", "hash", "last bits"
    );
    for h in &host {
        let t = target.iter().find(|t| t.channel == h.channel);
        let f = |i: usize| h.fields.get(i).map(String::as_str).unwrap_or("?");
        println!(
            "  {:<28} {:>6} {:>18} {:>18}  {}",
            h.channel,
            f(0),
            f(1),
            f(2),
            if t.is_some_and(|t| t.fields == h.fields) {
                "identical"
            } else {
                "MISMATCH"
            }
        );
    }
    let n = compare(&host, &target)?;
    Ok(format!("{n} channels bit-identical host vs target"))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rows(s: &str) -> Vec<Row> {
        parse(&s.lines().map(str::to_string).collect::<Vec<_>>())
    }

    #[test]
    fn identical_rows_pass_and_any_difference_fails() {
        let host = rows("conformance | a | 10 | 00ff | 01\nconformance | b | 1 | 0001 | 02");
        let same =
            rows("INFO conformance | a | 10 | 00ff | 01\nINFO conformance | b | 1 | 0001 | 02");
        assert_eq!(compare(&host, &same), Ok(2));
        let one_bit =
            rows("INFO conformance | a | 10 | 00fe | 01\nINFO conformance | b | 1 | 0001 | 02");
        assert!(compare(&host, &one_bit).unwrap_err().contains("a: host"));
        let missing = rows("INFO conformance | a | 10 | 00ff | 01");
        assert!(compare(&host, &missing).is_err());
        assert!(compare(&[], &same).is_err());
    }
}

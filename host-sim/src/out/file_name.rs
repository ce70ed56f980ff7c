//! The one file-name sanitiser: every output file or folder named after a scenario, a run or a
//! controller label goes through [`sanitize`], so the same name always gives the same file.

/// File-name-safe form of a name: ASCII letters, digits, `-`, `_` and `.` stay, `+` becomes
/// `p` and `%` becomes `c` (so `c_a+20%` gives `c_ap20c`), anything else `_`.
pub fn sanitize(s: &str) -> String {
    s.chars()
        .map(|c| match c {
            'a'..='z' | 'A'..='Z' | '0'..='9' | '-' | '_' | '.' => c,
            '+' => 'p',
            '%' => 'c',
            _ => '_',
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_of_existing_outputs_are_kept() {
        assert_eq!(sanitize("kick-0.5deg"), "kick-0.5deg");
        assert_eq!(sanitize("kick-3deg-c_a+20%"), "kick-3deg-c_ap20c");
        assert_eq!(sanitize("kick-3deg-sigma-20%"), "kick-3deg-sigma-20c");
        assert_eq!(sanitize("ramp 20-120 km/h"), "ramp_20-120_km_h");
        assert_eq!(sanitize("damper off (0 A)"), "damper_off__0_A_");
        assert_eq!(sanitize("sensor-faults"), "sensor-faults");
    }
}

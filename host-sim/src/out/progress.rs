//! The one progress bar of the long commands (on stderr; indicatif draws nothing when stderr
//! is not a terminal, so logs, pipes and tests stay clean).

use indicatif::{ProgressBar, ProgressStyle};

/// A bar over `len` units of work named `what` (e.g. "closed-loop runs").
pub fn bar(len: usize, what: &str) -> ProgressBar {
    let b = ProgressBar::new(len as u64);
    b.set_style(
        ProgressStyle::with_template(&format!(
            "{{bar:40}} {{pos}}/{{len}} {what} {{elapsed_precise}} eta {{eta}}"
        ))
        .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    b
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_bar_counts_and_is_hidden_off_a_terminal() {
        let b = super::bar(3, "runs");
        b.inc(2);
        assert_eq!((b.position(), b.length()), (2, Some(3)));
        // The test harness captures stderr: nothing is drawn there.
        assert!(b.is_hidden());
    }
}

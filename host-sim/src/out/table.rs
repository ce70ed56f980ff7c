//! Small helpers shared by the Markdown and text tables of several commands.

/// A table cell for an optional number: `-` when absent, else the number with `prec` decimals.
pub fn opt(v: Option<f64>, prec: usize) -> String {
    v.map_or("-".into(), |x| format!("{x:.prec$}"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn absent_is_a_dash() {
        assert_eq!(opt(None, 2), "-");
        assert_eq!(opt(Some(1.005), 0), "1");
        assert_eq!(opt(Some(2.5), 2), "2.50");
    }
}

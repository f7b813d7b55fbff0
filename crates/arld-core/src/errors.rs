//! How an error reads on one line, for every client of the library: the command line prints it after
//! `error: `, and Python raises it.

/// An error with its causes on one line, `outer: cause: root`, leaving out a cause whose text an outer message
/// already includes (many errors name their cause in their own message).
pub fn error_line(err: &anyhow::Error) -> String {
    let mut line = String::new();
    for cause in err.chain() {
        let part = cause.to_string();
        if !line.contains(part.trim()) {
            if !line.is_empty() {
                line.push_str(": ");
            }
            line.push_str(part.trim());
        }
    }
    line
}

#[cfg(test)]
mod tests {
    use super::error_line;
    use anyhow::{Context, anyhow};

    /// Each cause once, outermost first; a cause an outer message already quotes is not repeated.
    #[test]
    fn causes_join_on_one_line_without_repeats() {
        let root: anyhow::Result<()> = Err(anyhow!("no such file"));
        let err = root
            .context("cannot read a.toml: no such file")
            .context("the run's configuration")
            .unwrap_err();
        assert_eq!(
            error_line(&err),
            "the run's configuration: cannot read a.toml: no such file"
        );
        let plain = anyhow!(" padded ").context("outer");
        assert_eq!(error_line(&plain), "outer: padded");
    }
}

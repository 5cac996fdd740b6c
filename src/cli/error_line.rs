//! One line for an error: its cause chain joined by ": ", each cause said once. Many error
//! types print their source inside their own message as well as returning it as the source
//! (an I/O error wrapped with the path it concerns), which would print "(os error 2)" twice.

/// The chain of `err` as one line, skipping a cause whose text the line already holds.
pub fn error_line(err: &anyhow::Error) -> String {
    let mut line = String::new();
    for cause in err.chain() {
        let text = cause.to_string();
        if text.is_empty() || line.contains(&text) {
            continue;
        }
        if !line.is_empty() {
            line.push_str(": ");
        }
        line.push_str(&text);
    }
    line
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, thiserror::Error)]
    #[error("reading {path}: {source}")]
    struct Read {
        path: String,
        source: std::io::Error,
    }

    #[test]
    fn a_cause_already_in_the_message_is_not_repeated() {
        let io = std::io::Error::from(std::io::ErrorKind::NotFound);
        let text = io.to_string();
        let err = anyhow::Error::new(Read {
            path: "a.tif".into(),
            source: io,
        })
        .context("analyze");
        let line = error_line(&err);
        assert_eq!(line, format!("analyze: reading a.tif: {text}"));
        assert_eq!(line.matches(&text).count(), 1);
        // Distinct causes are all kept.
        let err = anyhow::anyhow!("inner").context("middle").context("outer");
        assert_eq!(error_line(&err), "outer: middle: inner");
    }
}

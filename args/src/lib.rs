//! What spiv's two binaries (`spiv`, `spiv-firmware-sim`) share on the
//! command line.

/// Parses the arguments, or exits: help and version as clap prints them,
/// any other error as one line `NAME: … (see --help)` with status 2 (clap's
/// own message adds usage lines; `--help` has them).
pub fn parse_or_exit<T: clap::Parser>(name: &str) -> T {
    match T::try_parse() {
        Ok(a) => a,
        Err(e) => {
            use clap::error::ErrorKind;
            if matches!(
                e.kind(),
                ErrorKind::DisplayHelp
                    | ErrorKind::DisplayVersion
                    | ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand
            ) {
                e.exit();
            }
            eprintln!("{name}: {} (see --help)", one_line(&e.to_string()));
            std::process::exit(2);
        }
    }
}

/// clap's message up to its first blank line, as one line: the error and
/// what it lists on the lines below it (the missing arguments, say).
fn one_line(text: &str) -> String {
    let words: Vec<&str> = text
        .lines()
        .take_while(|l| !l.trim().is_empty())
        .map(str::trim)
        .collect();
    let line = words.join(" ");
    let line = line.trim_start_matches("error: ").trim();
    if line.is_empty() {
        "bad arguments".to_string()
    } else {
        line.to_string()
    }
}

#[cfg(test)]
mod tests {
    use super::one_line;
    use clap::Parser;

    #[derive(Parser, Debug)]
    struct Two {
        a: String,
        #[arg(short)]
        o: String,
    }

    /// A missing argument is named on the one line, with the rest.
    #[test]
    fn names_every_missing_argument() {
        let e = Two::try_parse_from(["x"]).unwrap_err();
        let line = one_line(&e.to_string());
        assert!(
            line.starts_with("the following required arguments were not provided:"),
            "{line}"
        );
        assert!(line.contains("<A>") && line.contains("-o <O>"), "{line}");
        assert!(!line.contains('\n') && !line.contains("Usage"), "{line}");
        let e = Two::try_parse_from(["x", "a", "-o", "b", "--nope"]).unwrap_err();
        assert!(one_line(&e.to_string()).starts_with("unexpected argument '--nope'"));
    }
}

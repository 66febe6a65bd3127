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
            let text = e.to_string();
            let first = text.lines().next().unwrap_or("bad arguments");
            eprintln!(
                "{name}: {} (see --help)",
                first.trim_start_matches("error: ").trim()
            );
            std::process::exit(2);
        }
    }
}

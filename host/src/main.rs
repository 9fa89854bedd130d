//! `host`: the command-line front end. Machine-readable outputs go to stdout, progress and
//! errors to stderr; every failure exits non-zero with a message naming what and where.

mod cmd;

use clap::{Parser, Subcommand};
use std::process::ExitCode;

#[derive(Parser)]
#[command(
    name = "host",
    version,
    about = "Haptic soft-tissue simulator: host tools"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run the default liver scene (see `demo --help` for what it does today).
    Demo(cmd::demo::Args),
    /// Compliance blocks C(n, k) of a mesh as one JSON object on stdout.
    Compliance(cmd::compliance::Args),
    /// Benchmarks that print figures.
    #[command(subcommand)]
    Bench(cmd::bench::Bench),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Demo(args) => cmd::demo::run(args),
        Command::Compliance(args) => cmd::compliance::run(args),
        Command::Bench(bench) => cmd::bench::run(bench),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

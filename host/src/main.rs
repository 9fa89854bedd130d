//! `host`: the command-line front end. Machine-readable outputs go to stdout, progress and
//! errors to stderr; every failure exits non-zero with a message naming what and where.

mod cmd;
mod progress;

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
    /// The default liver scene in the browser: the firmware loop on this PC, the mouse drives
    /// the tool, the organ deforms and the force is shown live.
    Demo(cmd::demo::Args),
    /// Compliance blocks C(n, k) of a mesh as one JSON object on stdout.
    Compliance(cmd::compliance::Args),
    /// Firmware banks: build from a scene file, inspect, sweep the truncation radius.
    #[command(subcommand)]
    Bank(cmd::bank::BankCmd),
    /// Contact at any point of the organ: the patch compliance W and the rendered force.
    #[command(subcommand)]
    Contact(cmd::contact::ContactCmd),
    /// Bench calibration: tissue law Q, display law P, motor torque constants.
    #[command(subcommand)]
    Calibrate(cmd::calibrate::Calibrate),
    /// Benchmarks that print figures.
    #[command(subcommand)]
    Bench(cmd::bench::Bench),
    /// Software in the loop: the firmware image under QEMU against a simulated device.
    Sil(cmd::sil::Args),
    /// Write the board image and a bank to the STM32F405 through a debug probe (probe-rs),
    /// checked before and after; --dry-run prints the plan without a probe.
    Flash(cmd::flash::Args),
    /// A device on a serial port at bring-up: `check` prints its live joints, tip and state;
    /// `arm` arms it in a mode (constant currents for the load cell) and disarms it after.
    #[command(subcommand)]
    Device(cmd::device::DeviceCmd),
    /// Speed against error for every knob, and the hard cases, on one generated page.
    Report(cmd::report::Args),
    /// A closed surface (STL, OBJ, PLY, VTK polydata, VTP) to a tetrahedral mesh through Gmsh:
    /// units, surface checks and repairs, fine where a scene's tool reaches, quality.
    Mesh(cmd::mesh::Args),
    /// Scene files: `new` writes a complete scene for a mesh, aimed from a trocar.
    #[command(subcommand)]
    Scene(cmd::scene::SceneCmd),
    /// A compression experiment marker by marker: the predicted marker positions and the
    /// platen force at each nominal strain, linear or large-deformation model.
    Specimen(cmd::specimen::Args),
}

fn main() -> ExitCode {
    // Behave like other Unix tools when stdout is a closed pipe (`host bank inspect x | head`):
    // end quietly instead of panicking in `println!`.
    #[cfg(unix)]
    // SAFETY: restoring the default disposition of SIGPIPE at start-up, before any thread exists.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    let cli = Cli::parse();
    // Test hook: with HOST_PARSE_ONLY set, exit 0 once the arguments parse (clap's usage error
    // and exit 2 otherwise) without running anything; host/tests/docs.rs checks the guide's
    // `sh` lines this way.
    if std::env::var_os("HOST_PARSE_ONLY").is_some() {
        return ExitCode::SUCCESS;
    }
    let result = match cli.command {
        Command::Demo(args) => cmd::demo::run(args),
        Command::Compliance(args) => cmd::compliance::run(args),
        Command::Bench(bench) => cmd::bench::run(bench),
        Command::Calibrate(c) => cmd::calibrate::run(c),
        Command::Bank(bank) => cmd::bank::run(bank),
        Command::Contact(c) => cmd::contact::run(c),
        Command::Sil(args) => cmd::sil::run(args),
        Command::Flash(args) => cmd::flash::run(args),
        Command::Device(c) => cmd::device::run(c),
        Command::Report(args) => cmd::report::run(args),
        Command::Mesh(args) => cmd::mesh::run(args),
        Command::Scene(c) => cmd::scene::run(c),
        Command::Specimen(args) => cmd::specimen::run(args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

//! The `fogplanes` command line: a thin layer over the core library (`crates/core`). It parses
//! and checks arguments, shows progress, measures CPU time and memory, and runs the experiments
//! of [`experiments`], which draw with [`pictures`].

mod args;
mod commands;
mod experiments;
mod page;
mod pictures;
mod report;
mod system;
mod watch;

use args::{Cli, Command};
use clap::Parser;
use commands::*;
use std::io::Write;
use std::process::ExitCode;

fn main() -> ExitCode {
    system::keep_freed_memory();
    // The zero of the timeline `FOGPLANES_TRACE=1` prints (fogplanes::trace).
    drop(fogplanes::trace::span("process started"));
    STARTED.get_or_init(std::time::Instant::now);
    let cli = Cli::parse();
    // Ctrl-C, SIGTERM or SIGHUP: remove any half-written output before leaving, so no truncated
    // file remains (a checkpoint's file under way is finished first: the note tells what it
    // holds), and say which outputs were written whole before it, if any.
    let _ = ctrlc::set_handler(|| {
        let left = watch::checkpoint_left();
        let written = fogplanes::film::remove_unfinished_files();
        let note = watch::interrupted_note(left, &written);
        let _ = writeln!(std::io::stderr(), "\ninterrupted: {note}");
        std::process::exit(130);
    });
    let result = match cli.command {
        Command::Render(a) => cmd_render(a),
        Command::Reference(a) => cmd_reference(a),
        Command::Compare(a) => cmd_compare(a),
        Command::Merge(a) => cmd_merge(a),
        Command::Table(a) => cmd_table(a),
        Command::Scaling(a) => cmd_scaling(a),
        Command::Info(a) => cmd_info(a),
        Command::Export(a) => cmd_export(a),
        Command::Devices => cmd_devices(),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(f) => {
            let _ = writeln!(std::io::stderr(), "error: {:#}", f.error);
            ExitCode::from(f.code)
        }
    }
}

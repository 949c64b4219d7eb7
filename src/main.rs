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
use commands::*;
use std::io::Write;
use std::process::ExitCode;

/// The arguments, every value of every subcommand allowed to start with `-` and a digit: `--seed
/// -1` is then refused for what it is (not a whole number of the setting's range), where clap took
/// `-1` for an unknown flag and advised `-- -1`, which a value cannot be. A negative float in any
/// form Rust reads (`--lobes -0.5`, `-1e-3`, `-.5`, `-inf`; clap's own test of a negative number
/// knows only the first) reaches the library's range check, which names the flag.
fn parse() -> Cli {
    fn negatives(c: clap::Command) -> clap::Command {
        c.mut_args(|a| {
            if !a.get_action().takes_values() {
                return a;
            }
            let a = a.allow_negative_numbers(true);
            let float = [std::any::TypeId::of::<f64>(), std::any::TypeId::of::<f32>()];
            let a = if float.iter().any(|&t| a.get_value_parser().type_id() == t) {
                a.allow_hyphen_values(true)
            } else {
                a
            };
            // clap reads a u32 as an i64 in a range, which it words itself ("-2 is not in
            // 0..=4294967295"): read as a u32, it is told as every other count is ([`plainer`]).
            if a.get_value_parser().type_id() == std::any::TypeId::of::<u32>() {
                a.value_parser(|s: &str| s.parse::<u32>())
            } else {
                a
            }
        })
        .mut_subcommands(negatives)
    }
    let mut command = negatives(<Cli as clap::CommandFactory>::command());
    let args = negative_pairs(std::env::args_os().collect());
    let matches = command.try_get_matches_from_mut(&args).unwrap_or_else(|e| plainer(e, &mut command, &args).exit());
    <Cli as clap::FromArgMatches>::from_arg_matches(&matches).unwrap_or_else(|e| e.exit())
}

/// The pairs `WxH` and `A:B` (`--resolution`, `--resolutions`, `--plane-range`, `--rows`) whose
/// value starts with `-` and a digit, given as `--flag=value`: clap then takes the value as a
/// value, to be refused by its parser as one ("\"-5\" in \"-5x3\": expected a whole number"),
/// where it took `-5x3` for an unknown flag (a pair is no number to `allow_negative_numbers`).
/// A flag after one of these is still a flag: its missing value is said as such.
fn negative_pairs(args: Vec<std::ffi::OsString>) -> Vec<std::ffi::OsString> {
    const PAIRS: [&str; 4] = ["--resolution", "--resolutions", "--plane-range", "--rows"];
    let mut out: Vec<std::ffi::OsString> = Vec::with_capacity(args.len());
    let negative = |v: &std::ffi::OsString| {
        v.to_str().is_some_and(|v| v.strip_prefix('-').is_some_and(|r| r.starts_with(|c: char| c.is_ascii_digit())))
    };
    let mut args = args.into_iter().peekable();
    while let Some(a) = args.next() {
        if let Some(flag) = a.to_str().filter(|f| PAIRS.contains(f))
            && let Some(v) = args.next_if(negative)
        {
            out.push(format!("{flag}={}", v.to_string_lossy()).into());
        } else {
            out.push(a);
        }
    }
    out
}

/// A count, seed or index that is no whole number said as such: Rust's own words for `-1` or
/// `1.5` are "invalid digit found in string". Every error of a value (one of these, or clap's
/// own for a value outside a list, `-e foo`) shows the usage of the subcommand that `args`
/// names, as clap's errors of a missing or unknown argument do (it showed the root's,
/// `fogplanes <COMMAND>`, or none).
fn plainer(mut e: clap::Error, command: &mut clap::Command, args: &[std::ffi::OsString]) -> clap::Error {
    use clap::error::{ContextKind, ContextValue, ErrorKind};
    use std::error::Error;
    // The root takes no values, so that the first argument naming a subcommand is the one
    // parsed (no value can come before it).
    let named = args.iter().skip(1).filter_map(|a| a.to_str()).find(|a| command.find_subcommand(a).is_some());
    let command = match named.and_then(|name| command.find_subcommand_mut(name)) {
        Some(sub) => sub,
        None => command,
    };
    let parse = e.source().and_then(|s| s.downcast_ref::<std::num::ParseIntError>()).map(|p| *p.kind());
    let (arg, value) = (e.get(ContextKind::InvalidArg).cloned(), e.get(ContextKind::InvalidValue).cloned());
    if let (Some(kind), Some(arg), Some(value)) = (parse, arg, value) {
        let why = match kind {
            std::num::IntErrorKind::PosOverflow => "too large for the setting",
            _ => "expected a whole number, 0 or more",
        };
        return command.error(ErrorKind::ValueValidation, format!("invalid value '{value}' for '{arg}': {why}"));
    }
    let of_a_value = matches!(e.kind(), ErrorKind::InvalidValue | ErrorKind::ValueValidation);
    if of_a_value && e.get(ContextKind::Usage).is_none() {
        e.insert(ContextKind::Usage, ContextValue::StyledStr(command.render_usage()));
    }
    e
}

fn main() -> ExitCode {
    fogplanes::limits::keep_freed_memory();
    // The zero of the timeline `FOGPLANES_TRACE=1` prints (fogplanes::trace).
    drop(fogplanes::trace::span("process started"));
    STARTED.get_or_init(std::time::Instant::now);
    let cli = parse();
    // Ctrl-C, SIGTERM or SIGHUP: remove any half-written output before leaving, so no truncated
    // file remains (a checkpoint's file under way is finished first: the note tells what it
    // holds), and say which outputs were written whole before it, if any.
    let _ = ctrlc::set_handler(|| {
        let left = watch::checkpoint_left();
        let written = fogplanes::film::remove_unfinished_files();
        let note = watch::interrupted_note(left, &written);
        let _ = writeln!(std::io::stderr(), "\ninterrupted: {}", fogplanes::error::one_line(&note));
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
            // One line, whatever it quotes (a path's or a name's escape sequence or newline).
            let _ = writeln!(std::io::stderr(), "error: {}", fogplanes::error::one_line(&format!("{:#}", f.error)));
            ExitCode::from(f.code)
        }
    }
}

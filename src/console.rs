//! The command's messages on stdout and stderr, written so that they can
//! never stop the work. Rust's `println!` panics when stdout is a pipe whose
//! reader has gone (`dpp run … | head -1`), and a panic halfway through a run
//! leaves the outputs after that message unwritten. Here a closed pipe only
//! ends the messages: the run goes on, writes every output and exits as it
//! would have (0 on success, quietly, as `cat` and ripgrep do). Any other
//! failure to write stdout (a full disk behind `> file`) is remembered and
//! reported once the work is done ([`stdout_failure`]), with status 1.
//! Failures to write stderr are ignored: there is nowhere left to say so.

use std::fmt;
use std::io::{self, Write};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Mutex;

/// Set once stdout has failed: nothing more is written to it.
static STDOUT_CLOSED: AtomicBool = AtomicBool::new(false);
/// The first failure to write stdout that was not a closed pipe.
static STDOUT_FAILURE: Mutex<Option<String>> = Mutex::new(None);

/// Writes to stdout (see [`outln!`](crate::outln)).
pub fn stdout(args: fmt::Arguments<'_>) {
    if STDOUT_CLOSED.load(Ordering::Relaxed) {
        return;
    }
    let mut out = io::stdout().lock();
    if let Err(error) = out.write_fmt(args).and_then(|()| out.flush()) {
        STDOUT_CLOSED.store(true, Ordering::Relaxed);
        if error.kind() != io::ErrorKind::BrokenPipe {
            let mut failure = STDOUT_FAILURE.lock().unwrap_or_else(|e| e.into_inner());
            failure.get_or_insert_with(|| error.to_string());
        }
    }
}

/// Writes to stderr (see [`errln!`](crate::errln)), ignoring failures. The
/// text goes out in one write, so that the lines of processes sharing the
/// stream (ranks under mpirun) never interleave within a line.
pub fn stderr(args: fmt::Arguments<'_>) {
    let text = args.to_string();
    let mut err = io::stderr().lock();
    let _ = err.write_all(text.as_bytes()).and_then(|()| err.flush());
}

/// Set on every rank but 0 of a distributed run: the run's final error is
/// every rank's (agreed), and rank 0 says it once for all.
static FINAL_ERROR_SILENCED: AtomicBool = AtomicBool::new(false);

/// Leaves the final error to rank 0 (see [`final_error_silenced`]).
pub fn silence_final_error() {
    FINAL_ERROR_SILENCED.store(true, Ordering::Relaxed);
}

pub fn final_error_silenced() -> bool {
    FINAL_ERROR_SILENCED.load(Ordering::Relaxed)
}

/// Why stdout could not be written, unless it was only a closed pipe.
pub fn stdout_failure() -> Option<String> {
    STDOUT_FAILURE
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .clone()
}

/// `println!` that survives a closed stdout.
macro_rules! outln {
    ($($arg:tt)*) => {
        $crate::console::stdout(format_args!("{}\n", format_args!($($arg)*)))
    };
}

/// `print!` that survives a closed stdout.
macro_rules! out {
    ($($arg:tt)*) => {
        $crate::console::stdout(format_args!($($arg)*))
    };
}

/// `eprintln!` that survives a closed stderr.
macro_rules! errln {
    ($($arg:tt)*) => {
        $crate::console::stderr(format_args!("{}\n", format_args!($($arg)*)))
    };
}

/// `eprint!` that survives a closed stderr.
macro_rules! err {
    ($($arg:tt)*) => {
        $crate::console::stderr(format_args!($($arg)*))
    };
}

//! What a process says on its stderr (a failure, a warning), which the launcher relays.

/// Prints a child process's failure on its stderr, which the launcher relays. A write error
/// is ignored: the launcher that read the pipe may be gone (killed), and `eprintln!` would then
/// panic on the broken pipe instead of exiting with the failure's status.
pub fn print_failure(message: std::fmt::Arguments<'_>) {
    use std::io::Write as _;
    let _ = writeln!(std::io::stderr(), "{message}");
}

/// Prints a warning of a child process on its stderr, which the launcher relays (a write error
/// is ignored, as for [`print_failure`]).
pub fn print_warning(message: std::fmt::Arguments<'_>) {
    print_failure(message)
}

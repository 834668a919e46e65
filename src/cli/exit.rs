//! `gpustar`'s exit statuses, one name each (README, "Exit status").

use std::process::ExitCode;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Exit {
    /// Every input got a record and none is an error record (with --resume: none in the
    /// whole file); `--help` and `--version`.
    Ok = 0,
    /// Some input has an error record.
    ErrorRecords = 1,
    /// The run could not start (bad options, unreadable camera or catalog, GPU asked for but
    /// absent, an output gpustar may not write), or merge found inputs missing, repeated or
    /// torn.
    NotStarted = 2,
    /// The records could not be written (a full disk): those written are whole.
    WriteFailed = 3,
    /// `solve`'s frame was read but not solved.
    Unsolved = 4,
    /// Interrupted (Ctrl-C, SIGTERM): the records written so far are complete.
    Interrupted = 130,
}

impl From<Exit> for ExitCode {
    fn from(e: Exit) -> ExitCode {
        ExitCode::from(e as u8)
    }
}

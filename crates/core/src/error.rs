//! The error type of every stage: each variant names the file (or manifest
//! field) it is about, and says whether the user can fix it (exit code 2) or
//! it is an internal failure (exit code 1).

use std::path::{Path, PathBuf};

/// Errors raised by stages and the helpers in this crate.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// Reading or writing a file failed at the operating-system level.
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// A file exists but is not what it should be (another kind of file, a
    /// wrong schema, values out of range): the user gave the wrong file.
    #[error("{}: {what}", path.display())]
    BadFile { path: PathBuf, what: String },
    /// A file of the right kind whose bytes fail its own checks (a
    /// checksum, a CRC, an end too early): damaged data.
    #[error("{}: damaged: {what}", path.display())]
    Damaged { path: PathBuf, what: String },
    /// A parameter or an input value the user can correct.
    #[error("{0}")]
    Invalid(String),
    /// A simulation or computation left its valid domain (e.g. blew up).
    #[error("{0}")]
    Diverged(String),
    /// Stored data is not what its record says it is (a hash mismatch, a
    /// missing file): nothing the user's input can fix.
    #[error("{0}")]
    Corrupt(String),
}

impl Error {
    /// An I/O error on `path`.
    pub fn io(path: &Path, source: std::io::Error) -> Self {
        Error::Io {
            path: path.to_path_buf(),
            source,
        }
    }

    /// A malformed file at `path`.
    pub fn bad_file(path: &Path, what: impl std::fmt::Display) -> Self {
        Error::BadFile {
            path: path.to_path_buf(),
            what: what.to_string(),
        }
    }

    /// A damaged file at `path`: `what` says which check its bytes fail.
    pub fn damaged(path: &Path, what: impl std::fmt::Display) -> Self {
        Error::Damaged {
            path: path.to_path_buf(),
            what: what.to_string(),
        }
    }

    /// The same error with `context` (e.g. `variant `x`, stage simulate`)
    /// put before its message.
    pub fn context(self, context: &str) -> Self {
        match self {
            Error::Invalid(m) => Error::Invalid(format!("{context}: {m}")),
            Error::Diverged(m) => Error::Diverged(format!("{context}: {m}")),
            Error::Corrupt(m) => Error::Corrupt(format!("{context}: {m}")),
            other => other,
        }
    }

    /// The process exit code for this error: 2 for what the user can fix
    /// (a missing or unreadable input, the wrong file, bad parameters, an
    /// unstable scene), 1 otherwise (a damaged file, corrupt stored data, a
    /// full disk).
    pub fn exit_code(&self) -> i32 {
        use std::io::ErrorKind::{
            FileTooLarge, IsADirectory, NotADirectory, NotFound, PermissionDenied,
        };
        match self {
            Error::Io { source, .. } => match source.kind() {
                NotFound | PermissionDenied | IsADirectory | NotADirectory | FileTooLarge => 2,
                _ => 1,
            },
            Error::BadFile { .. } | Error::Invalid(_) | Error::Diverged(_) => 2,
            Error::Damaged { .. } | Error::Corrupt(_) => 1,
        }
    }
}

/// Result with the stage error type.
pub type Result<T, E = Error> = std::result::Result<T, E>;

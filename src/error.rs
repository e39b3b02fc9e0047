//! The library's error type: a kind, the file it concerns (when there is one) and one line of text.
//!
//! The binary prints `Error` as a single line, `path: message`, so every failure a user sees names the
//! file and the problem. `anyhow` is used only in `main.rs` and `cli/`, never in the library.

use std::fmt;
use std::path::{Path, PathBuf};

/// What went wrong, coarsely, so callers (the batch runner, tests) can react without parsing text.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ErrorKind {
    /// The operating system refused a read or write.
    Io,
    /// The file is not in any format ndfit recognises.
    UnknownFormat,
    /// The file is in a known format but is truncated, corrupt or self-contradictory.
    Corrupt,
    /// The file is valid but uses a feature of its format that ndfit does not read.
    Unsupported,
    /// A raw format needs an option the user did not give (for example `--dx`).
    MissingOption,
    /// The data are readable but unusable: all invalid, non-finite, too small.
    BadData,
    /// An argument or a parameter is out of its domain.
    InvalidInput,
    /// A numerical procedure produced no usable result.
    Numerical,
    /// The file declares more data than the memory budget allows (`crate::budget`).
    TooLarge,
}

/// The one error type of the `ndfit` library.
#[derive(Debug)]
pub struct Error {
    kind: ErrorKind,
    path: Option<PathBuf>,
    message: String,
    source: Option<Box<dyn std::error::Error + Send + Sync + 'static>>,
}

/// `Result` with the library's [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;

impl Error {
    /// A new error of `kind` with a one-line `message` (no trailing period, no newline).
    pub fn new(kind: ErrorKind, message: impl Into<String>) -> Self {
        Error { kind, path: None, message: message.into(), source: None }
    }

    /// Attach the file the error concerns. An existing path is kept: the innermost file is the precise one.
    pub fn with_path(mut self, path: impl AsRef<Path>) -> Self {
        if self.path.is_none() {
            self.path = Some(path.as_ref().to_path_buf());
        }
        self
    }

    /// Attach an underlying cause (shown after the message).
    pub fn with_source(mut self, source: impl std::error::Error + Send + Sync + 'static) -> Self {
        self.source = Some(Box::new(source));
        self
    }

    /// Shorthand for an [`ErrorKind::Corrupt`] error.
    pub fn corrupt(message: impl Into<String>) -> Self {
        Self::new(ErrorKind::Corrupt, message)
    }

    /// Shorthand for an [`ErrorKind::InvalidInput`] error.
    pub fn invalid(message: impl Into<String>) -> Self {
        Self::new(ErrorKind::InvalidInput, message)
    }

    /// Shorthand for an [`ErrorKind::Io`] error wrapping `err`.
    pub fn io(err: std::io::Error) -> Self {
        Self::new(ErrorKind::Io, err.to_string())
    }

    /// The kind of failure.
    pub fn kind(&self) -> ErrorKind {
        self.kind
    }

    /// The file the error concerns, if any.
    pub fn path(&self) -> Option<&Path> {
        self.path.as_deref()
    }

    /// The message without the path.
    pub fn message(&self) -> &str {
        &self.message
    }
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if let Some(p) = &self.path {
            write!(f, "{}: ", p.display())?;
        }
        f.write_str(&self.message)?;
        if let Some(s) = &self.source {
            write!(f, " ({s})")?;
        }
        Ok(())
    }
}

impl std::error::Error for Error {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        self.source.as_ref().map(|b| b.as_ref() as &(dyn std::error::Error + 'static))
    }
}

impl From<std::io::Error> for Error {
    fn from(err: std::io::Error) -> Self {
        Error::io(err)
    }
}

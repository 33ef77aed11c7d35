//! One error type for the crate, with structured variants that name the file, the object and
//! what was expected.

use std::path::PathBuf;

/// Everything that can go wrong when loading, posing or building.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A file could not be read or written.
    #[error("{path}: {err}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying I/O error (shown in the message, so not repeated as a source).
        err: std::io::Error,
    },
    /// A file's content is malformed: `object` names the part (e.g. `accessor 3`), `what` says
    /// what was wrong or expected.
    #[error("{path}: {object}: {what}")]
    Malformed {
        /// The file.
        path: PathBuf,
        /// The object inside the file (accessor, node, animation channel, line number, ...).
        object: String,
        /// What was wrong or what was expected.
        what: String,
    },
    /// The input is valid but asks for something the engine does not do.
    #[error("{path}: {object}: unsupported: {what}")]
    Unsupported {
        /// The file.
        path: PathBuf,
        /// The object inside the file.
        object: String,
        /// What is not supported.
        what: String,
    },
    /// An argument given through the library API is out of range.
    #[error("invalid argument: {0}")]
    InvalidArgument(String),
}

/// `Result` with the crate's [`Error`].
pub type Result<T> = std::result::Result<T, Error>;

impl Error {
    /// Shorthand for [`Error::Malformed`].
    pub fn malformed(
        path: impl Into<PathBuf>,
        object: impl Into<String>,
        what: impl Into<String>,
    ) -> Self {
        Error::Malformed {
            path: path.into(),
            object: object.into(),
            what: what.into(),
        }
    }

    /// Shorthand for [`Error::Io`].
    pub fn io(path: impl Into<PathBuf>, err: std::io::Error) -> Self {
        Error::Io {
            path: path.into(),
            err,
        }
    }
}

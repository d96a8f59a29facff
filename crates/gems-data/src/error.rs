//! Error types of the data layer.
//!
//! Every failure that comes from a file names that file: callers print one line and the user knows
//! which input to fix.

use std::path::PathBuf;

/// A format violation found by one of the byte/text parsers, before a file name is attached.
///
/// The parsers work on in-memory bytes (so they can be fuzzed); the readers that open files wrap
/// this into [`DataError::Format`] together with the path.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct FormatError(pub String);

impl FormatError {
    pub(crate) fn new(msg: impl Into<String>) -> Self {
        Self(msg.into())
    }
}

/// Errors of the data layer. Each variant names the file or folder at fault.
#[derive(Debug, thiserror::Error)]
pub enum DataError {
    /// Reading or writing a file failed at the OS level.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file or folder involved.
        path: PathBuf,
        /// The OS error.
        source: std::io::Error,
    },
    /// The file exists but its content is malformed (truncated, wrong counts, NaN poses, ...).
    #[error("{}: {source}", path.display())]
    Format {
        /// The malformed file.
        path: PathBuf,
        /// What is wrong with it.
        source: FormatError,
    },
    /// A file or folder the layout requires is absent.
    #[error("{}: missing {what}", path.display())]
    Missing {
        /// The path that was expected.
        path: PathBuf,
        /// What was expected there.
        what: String,
    },
    /// The input is well-formed but uses something gems does not handle (e.g. a distorted camera).
    #[error("{}: unsupported: {msg}", path.display())]
    Unsupported {
        /// The file or folder involved.
        path: PathBuf,
        /// What is not supported and what to do about it.
        msg: String,
    },
    /// Decoding or encoding an image failed.
    #[error("{}: {source}", path.display())]
    Image {
        /// The image file.
        path: PathBuf,
        /// The codec error.
        source: image::ImageError,
    },
    /// Reading event data failed (the error names the file).
    #[error(transparent)]
    Events(gems_events::EventError),
}

impl DataError {
    pub(crate) fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Self::Io {
            path: path.into(),
            source,
        }
    }

    pub(crate) fn format(path: impl Into<PathBuf>, msg: impl Into<String>) -> Self {
        Self::Format {
            path: path.into(),
            source: FormatError::new(msg),
        }
    }

    pub(crate) fn from_format(path: impl Into<PathBuf>, source: FormatError) -> Self {
        Self::Format {
            path: path.into(),
            source,
        }
    }
}

/// A failed write or folder listing (gems-fs) is an I/O error on the path it names.
impl From<gems_fs::FsError> for DataError {
    fn from(e: gems_fs::FsError) -> Self {
        Self::io(e.path, e.source)
    }
}

/// Result alias of the data layer.
pub type Result<T, E = DataError> = std::result::Result<T, E>;

//! Path-annotated reads (atomic writes and image listing are gems-fs's).

use std::path::Path;

use crate::error::{DataError, Result};

/// Reads a whole file, naming it in the error.
pub(crate) fn read_bytes(path: &Path) -> Result<Vec<u8>> {
    std::fs::read(path).map_err(|e| DataError::io(path, e))
}

/// Reads a whole UTF-8 text file, naming it in the error.
pub(crate) fn read_text(path: &Path) -> Result<String> {
    let bytes = read_bytes(path)?;
    String::from_utf8(bytes).map_err(|_| DataError::format(path, "not valid UTF-8 text"))
}

//! Filesystem primitives shared by the gems crates, so that each has one implementation:
//!
//! * [`write_atomic`] / [`write_atomic_with`] — a file appears complete or not at all: it is
//!   written to a temporary file in the destination's folder, synced and renamed over the
//!   destination, so a crash or a concurrent reader never sees a half-written file
//!   (`write_atomic` also creates a missing folder, the streaming `write_atomic_with` does not).
//! * [`list_images`] — the image files of a folder, as every scene layout and the SfM see them.
//!
//! Errors are an [`FsError`] naming the file or folder at fault; each crate converts it into its
//! own error type, keeping that path.

use std::ffi::OsString;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

/// A filesystem operation failed on `path`.
#[derive(Debug, thiserror::Error)]
#[error("{}: {source}", path.display())]
pub struct FsError {
    /// The file or folder involved.
    pub path: PathBuf,
    /// The OS error (kind `InvalidInput` when `path` cannot name a file).
    pub source: std::io::Error,
}

impl FsError {
    fn new(path: &Path, source: std::io::Error) -> Self {
        Self {
            path: path.to_path_buf(),
            source,
        }
    }
}

/// Writes `bytes` to `path` atomically (see [`write_atomic_with`]), creating `path`'s folder and
/// its parents first if they are missing: callers write results into output folders they have
/// not made yet (a COLMAP model's `sparse/0`, a run's output folder).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), FsError> {
    let dir = parent_dir(path);
    std::fs::create_dir_all(dir).map_err(|e| FsError::new(dir, e))?;
    write_atomic_with(path, |w| w.write_all(bytes))
}

/// Writes what `fill` writes to `path` atomically: `fill` streams into a buffered temporary file
/// in `path`'s folder, which is flushed, synced to disk and renamed over `path`. On any failure
/// the temporary file is removed and `path` is left as it was.
///
/// Unlike [`write_atomic`], a missing folder is not created but is an error naming `path`: the
/// event-file and splat writers that stream through this function have always failed there, and
/// gems-events' tests hold them to it. The writer is seekable, for formats (zip, PNG) whose
/// encoders need that.
pub fn write_atomic_with(
    path: &Path,
    fill: impl FnOnce(&mut BufWriter<File>) -> std::io::Result<()>,
) -> Result<(), FsError> {
    let dir = parent_dir(path);
    let file_name = path.file_name().ok_or_else(|| {
        FsError::new(
            path,
            std::io::Error::new(std::io::ErrorKind::InvalidInput, "not a file path"),
        )
    })?;
    // Unique per process and per call, so concurrent writers never share a temporary file.
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    let n = COUNTER.fetch_add(1, Ordering::Relaxed);
    let mut tmp_name = OsString::from(".");
    tmp_name.push(file_name);
    tmp_name.push(format!(".tmp{}-{n}", std::process::id()));
    let tmp = dir.join(tmp_name);
    let result = (|| {
        // A large buffer: the streaming writers (event files, PLY) emit many small writes.
        let mut w = BufWriter::with_capacity(1 << 20, File::create(&tmp)?);
        fill(&mut w)?;
        w.into_inner().map_err(|e| e.into_error())?.sync_all()?;
        std::fs::rename(&tmp, path)
    })();
    if let Err(e) = result {
        // Best effort: the temporary file must not linger next to the user's data.
        let _ = std::fs::remove_file(&tmp);
        return Err(FsError::new(path, e));
    }
    Ok(())
}

/// The folder `path` is in; `.` for a bare file name.
fn parent_dir(path: &Path) -> &Path {
    match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    }
}

/// Whether `path` has an image extension gems reads: png, jpg or jpeg, in any case.
fn is_image_file_name(path: &Path) -> bool {
    path.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| matches!(e.to_ascii_lowercase().as_str(), "png" | "jpg" | "jpeg"))
}

/// The folder holding a scene's photos: `<dir>/images` when it exists (a scene folder), else
/// `dir` itself (a folder of photos).
pub fn image_folder(dir: &Path) -> PathBuf {
    let images = dir.join("images");
    if images.is_dir() {
        images
    } else {
        dir.to_path_buf()
    }
}

/// The image files (png/jpg/jpeg, any case) directly inside `dir`, sorted by path. Hidden files
/// (name starting with `.`, e.g. macOS `._x.jpg` resource forks) and folders are left out.
pub fn list_images(dir: &Path) -> Result<Vec<PathBuf>, FsError> {
    let rd = std::fs::read_dir(dir).map_err(|e| FsError::new(dir, e))?;
    let mut out = Vec::new();
    for entry in rd {
        let p = entry.map_err(|e| FsError::new(dir, e))?.path();
        let hidden = p
            .file_name()
            .and_then(|n| n.to_str())
            .is_some_and(|n| n.starts_with('.'));
        if p.is_file() && is_image_file_name(&p) && !hidden {
            out.push(p);
        }
    }
    out.sort();
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn write_atomic_replaces_the_file_and_leaves_no_temporary() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("sub").join("a.txt");
        write_atomic(&path, b"first").unwrap();
        write_atomic(&path, b"second").unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), b"second");
        let names: Vec<_> = std::fs::read_dir(path.parent().unwrap())
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names, vec![OsString::from("a.txt")]);
    }

    #[test]
    fn a_failing_writer_keeps_the_old_file_and_names_the_path() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.bin");
        write_atomic(&path, b"old").unwrap();
        let err = write_atomic_with(&path, |w| {
            w.write_all(b"partial")?;
            Err(std::io::Error::other("encoder failed"))
        })
        .unwrap_err();
        assert_eq!(err.path, path);
        assert!(err.to_string().ends_with("a.bin: encoder failed"), "{err}");
        assert_eq!(std::fs::read(&path).unwrap(), b"old");
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
    }

    #[test]
    fn only_write_atomic_creates_a_missing_folder() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("missing").join("a.bin");
        let err = write_atomic_with(&path, |w| w.write_all(b"x")).unwrap_err();
        assert_eq!(err.path, path);
        assert!(!path.parent().unwrap().exists());
        write_atomic(&path, b"x").unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), b"x");
    }

    #[test]
    fn write_atomic_rejects_a_path_without_file_name() {
        let dir = tempfile::tempdir().unwrap();
        let err = write_atomic(&dir.path().join(".."), b"x").unwrap_err();
        assert_eq!(err.source.kind(), std::io::ErrorKind::InvalidInput);
    }

    #[test]
    fn list_images_keeps_visible_image_files_sorted() {
        let dir = tempfile::tempdir().unwrap();
        for name in ["b.JPG", "a.png", "c.jpeg", "notes.txt", ".hidden.png", "d"] {
            std::fs::write(dir.path().join(name), b"").unwrap();
        }
        std::fs::create_dir(dir.path().join("e.png")).unwrap();
        let names: Vec<_> = list_images(dir.path())
            .unwrap()
            .iter()
            .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
            .collect();
        assert_eq!(names, ["a.png", "b.JPG", "c.jpeg"]);
        let missing = dir.path().join("missing");
        assert_eq!(list_images(&missing).unwrap_err().path, missing);
    }

    #[test]
    fn image_folder_is_images_inside_a_scene_else_the_folder_itself() {
        let dir = tempfile::tempdir().unwrap();
        assert_eq!(image_folder(dir.path()), dir.path());
        std::fs::write(dir.path().join("images"), b"").unwrap();
        assert_eq!(image_folder(dir.path()), dir.path(), "a file named images");
        std::fs::remove_file(dir.path().join("images")).unwrap();
        std::fs::create_dir(dir.path().join("images")).unwrap();
        assert_eq!(image_folder(dir.path()), dir.path().join("images"));
    }
}

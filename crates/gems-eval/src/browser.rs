//! Headless Chromium for the viewer's tests and measurements: a screenshot of a page, or its DOM
//! after the scripts ran. SwiftShader gives software WebGL2 on machines without a GPU.

use std::path::{Path, PathBuf};
use std::process::Command;

use crate::EvalError;

/// The Chromium binary: `GEMS_CHROMIUM` when set, else Debian's `/usr/bin/chromium` or another
/// usual name. `None` when there is none.
pub fn find_chromium() -> Option<PathBuf> {
    if let Some(p) = std::env::var_os("GEMS_CHROMIUM") {
        return Some(PathBuf::from(p));
    }
    [
        "/usr/bin/chromium",
        "/usr/bin/chromium-browser",
        "/usr/bin/google-chrome",
    ]
    .iter()
    .map(PathBuf::from)
    .find(|p| p.is_file())
}

fn run(url: &str, w: u32, h: u32, profile: &Path, extra: &[String]) -> Result<Vec<u8>, EvalError> {
    let bin = find_chromium().ok_or_else(|| {
        EvalError::Input(
            "headless Chromium is needed: install Debian's `chromium` package or set \
             GEMS_CHROMIUM to a Chromium/Chrome binary"
                .into(),
        )
    })?;
    let out = Command::new(&bin)
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--use-angle=swiftshader",
            "--enable-unsafe-swiftshader",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--no-first-run",
            "--hide-scrollbars",
            "--force-device-scale-factor=1",
        ])
        .arg(format!("--user-data-dir={}", profile.display()))
        .arg(format!("--window-size={w},{h}"))
        .args(extra)
        .arg(url)
        .output()
        .map_err(|source| EvalError::Io {
            path: bin.clone(),
            source,
        })?;
    if !out.status.success() {
        return Err(EvalError::Input(format!(
            "{} failed ({}): {}",
            bin.display(),
            out.status,
            String::from_utf8_lossy(&out.stderr)
        )));
    }
    Ok(out.stdout)
}

/// A `file://` URL of `path` with `fragment` (already URL-encoded) after `#`.
pub fn file_url(path: &Path, fragment: &str) -> Result<String, EvalError> {
    let abs = std::fs::canonicalize(path).map_err(|source| EvalError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let mut url = format!("file://{}", abs.display());
    if !fragment.is_empty() {
        url.push('#');
        url.push_str(fragment);
    }
    Ok(url)
}

/// Percent-encodes everything but unreserved characters (RFC 3986) for a URL fragment value.
pub fn encode_component(s: &str) -> String {
    s.bytes()
        .map(|b| {
            if b.is_ascii_alphanumeric() || b"-._~".contains(&b) {
                (b as char).to_string()
            } else {
                format!("%{b:02X}")
            }
        })
        .collect()
}

/// Screenshot of `url` in a `w`×`h` window (headless Chromium windows are at least 500 pixels
/// wide), written to `png`; `work` holds the browser profile.
pub fn screenshot(url: &str, w: u32, h: u32, png: &Path, work: &Path) -> Result<(), EvalError> {
    run(
        url,
        w,
        h,
        &work.join("chromium-profile"),
        &[format!("--screenshot={}", png.display())],
    )?;
    if !png.is_file() {
        return Err(EvalError::Input(format!(
            "Chromium wrote no screenshot {}",
            png.display()
        )));
    }
    Ok(())
}

/// The DOM of `url` after its scripts ran, as HTML.
pub fn dump_dom(url: &str, w: u32, h: u32, work: &Path) -> Result<String, EvalError> {
    let out = run(
        url,
        w,
        h,
        &work.join("chromium-profile"),
        &["--dump-dom".to_owned()],
    )?;
    Ok(String::from_utf8_lossy(&out).into_owned())
}

//! TUM trajectory text files: one pose per line, `timestamp tx ty tz qx qy qz qw`, camera-to-world
//! (the camera centre and orientation in the world), as evo reads them.

use std::fmt::Write as _;
use std::path::Path;

use gems_math::Se3;

use crate::EvalError;

/// Formats timestamped camera-to-world poses as TUM text.
pub fn format_tum(poses: &[(f64, Se3)]) -> String {
    let mut s = String::from("# timestamp tx ty tz qx qy qz qw\n");
    for (t, p) in poses {
        let (tr, q) = p.to_translation_quat_wxyz();
        // 17 significant digits round-trip f64 exactly.
        let _ = writeln!(
            s,
            "{t:.9} {:.17e} {:.17e} {:.17e} {:.17e} {:.17e} {:.17e} {:.17e}",
            tr[0], tr[1], tr[2], q[1], q[2], q[3], q[0]
        );
    }
    s
}

/// Writes a TUM file atomically.
pub fn write_tum(path: &Path, poses: &[(f64, Se3)]) -> Result<(), EvalError> {
    gems_fs::write_atomic(path, format_tum(poses).as_bytes())?;
    Ok(())
}

/// Reads a TUM file; `#` lines and blank lines are skipped. Errors name the file and line.
pub fn read_tum(path: &Path) -> Result<Vec<(f64, Se3)>, EvalError> {
    let text = std::fs::read_to_string(path).map_err(|source| EvalError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let bad = |line: usize, reason: &str| EvalError::Format {
        path: path.to_path_buf(),
        reason: format!("line {line}: {reason}"),
    };
    let mut out = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let v: Vec<f64> = line
            .split_whitespace()
            .map(|w| w.parse::<f64>())
            .collect::<Result<_, _>>()
            .map_err(|_| bad(i + 1, "not a number"))?;
        if v.len() != 8 {
            return Err(bad(i + 1, &format!("expected 8 values, found {}", v.len())));
        }
        if !v.iter().all(|x| x.is_finite()) || v[4..].iter().all(|&q| q == 0.0) {
            return Err(bad(i + 1, "non-finite value or zero quaternion"));
        }
        out.push((
            v[0],
            Se3::from_translation_quat_wxyz([v[1], v[2], v[3]], [v[7], v[4], v[5], v[6]]),
        ));
    }
    Ok(out)
}

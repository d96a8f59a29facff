//! LLFF `poses_bounds.npy` / ExBluRF sub-frame tests.

use gems_data::llff::*;
use gems_math::Pose;
use proptest::prelude::*;

fn rot_pose(angle: f64, t: [f64; 3]) -> Pose {
    // Rotation about an oblique axis so all three axes are exercised.
    let axis = [1.0 / 3f64.sqrt(); 3];
    let q = [
        (angle / 2.0).cos(),
        axis[0] * (angle / 2.0).sin(),
        axis[1] * (angle / 2.0).sin(),
        axis[2] * (angle / 2.0).sin(),
    ];
    Pose::from_quaternion(q, t)
}

fn rows(n: usize) -> Vec<LlffRow> {
    (0..n)
        .map(|i| {
            let p = rot_pose(0.3 * i as f64, [i as f64, -0.5, 2.0]);
            LlffRow::from_pose(&p, 270.0, 400.0, 350.0 + i as f64, 0.5, 10.0 + i as f64)
        })
        .collect()
}

#[test]
fn poses_bounds_round_trip_is_exact() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("poses_bounds.npy");
    let r = rows(5);
    write_poses_bounds(&path, &r).unwrap();
    let back = read_poses_bounds(&path).unwrap();
    assert_eq!(back, r);
    // And the bytes are stable under a second write.
    let b1 = std::fs::read(&path).unwrap();
    write_poses_bounds(&path, &back).unwrap();
    assert_eq!(b1, std::fs::read(&path).unwrap());
}

#[test]
fn subframes_round_trip_is_exact() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("poses_bounds_subframes.npy");
    let r: Vec<Vec<LlffRow>> = (0..3).map(|i| rows(4 + i)[i..i + 4].to_vec()).collect();
    write_subframes(&path, &r).unwrap();
    assert_eq!(read_subframes(&path).unwrap(), r);
    let ragged = vec![rows(2), rows(3)];
    let err = write_subframes(&path, &ragged).unwrap_err().to_string();
    assert!(err.contains("sub-frames"), "{err}");
    // The failed write left the previous file intact.
    assert_eq!(read_subframes(&path).unwrap(), r);
}

/// The LLFF column order, checked on a hand-written row: an identity OpenCV camera (x right,
/// y down, z forward) at centre (1,2,3) is stored as columns [down, right, back] = [y, x, −z].
#[test]
fn hand_written_row_matches_llff_convention() {
    #[rustfmt::skip]
    let v: [f64; 17] = [
        0.0, 1.0, 0.0, 1.0, 270.0,
        1.0, 0.0, 0.0, 2.0, 400.0,
        0.0, 0.0, -1.0, 3.0, 350.0,
        0.5, 9.0,
    ];
    let mut bytes = Vec::new();
    // Build the .npy by hand (NEP-01 v1.0) so the test does not depend on our writer.
    let header = "{'descr': '<f8', 'fortran_order': False, 'shape': (1, 17), }";
    let mut h = header.to_owned();
    while !(10 + h.len() + 1).is_multiple_of(64) {
        h.push(' ');
    }
    h.push('\n');
    bytes.extend_from_slice(b"\x93NUMPY\x01\x00");
    bytes.extend_from_slice(&(h.len() as u16).to_le_bytes());
    bytes.extend_from_slice(h.as_bytes());
    for x in v {
        bytes.extend_from_slice(&x.to_le_bytes());
    }
    let r = parse_poses_bounds(&bytes).unwrap();
    let p = r[0].pose();
    for i in 0..3 {
        for j in 0..3 {
            let e = if i == j { 1.0 } else { 0.0 };
            assert!((p.rotation[i][j] - e).abs() < 1e-15, "{:?}", p.rotation);
        }
    }
    assert_eq!(p.center(), [1.0, 2.0, 3.0]);
    let k = r[0].intrinsics();
    assert_eq!(
        (k.width, k.height, k.fx, k.cx, k.cy),
        (400, 270, 350.0, 200.0, 135.0)
    );
    assert_eq!((r[0].near, r[0].far), (0.5, 9.0));
}

#[test]
fn float32_files_are_accepted() {
    // Same as a float64 file but '<f4' payload.
    let v: Vec<f32> = vec![
        0.0, 1.0, 0.0, 0.0, 10.0, 1.0, 0.0, 0.0, 0.0, 20.0, 0.0, 0.0, -1.0, 0.0, 30.0, 1.0, 2.0,
    ];
    let mut h = "{'descr': '<f4', 'fortran_order': False, 'shape': (1, 17), }".to_owned();
    while !(10 + h.len() + 1).is_multiple_of(64) {
        h.push(' ');
    }
    h.push('\n');
    let mut bytes = b"\x93NUMPY\x01\x00".to_vec();
    bytes.extend_from_slice(&(h.len() as u16).to_le_bytes());
    bytes.extend_from_slice(h.as_bytes());
    for x in &v {
        bytes.extend_from_slice(&x.to_le_bytes());
    }
    let r = parse_poses_bounds(&bytes).unwrap();
    assert_eq!(r[0].focal(), 30.0);
}

#[test]
fn malformed_poses_files_name_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("poses_bounds.npy");
    // NaN pose.
    let mut r = rows(3);
    r[1].matrix[0][3] = f64::NAN;
    write_poses_bounds(&path, &r).unwrap();
    let e = read_poses_bounds(&path).unwrap_err().to_string();
    assert!(
        e.contains("poses_bounds.npy") && e.contains("row 1") && e.contains("NaN"),
        "{e}"
    );
    // Not a rotation.
    let mut r = rows(2);
    r[0].matrix[0][0] = 2.0;
    write_poses_bounds(&path, &r).unwrap();
    let e = read_poses_bounds(&path).unwrap_err().to_string();
    assert!(e.contains("rotation"), "{e}");
    // Zero image width.
    let mut r = rows(2);
    r[1].matrix[1][4] = 0.0;
    write_poses_bounds(&path, &r).unwrap();
    let e = read_poses_bounds(&path).unwrap_err().to_string();
    assert!(
        e.contains("row 1") && e.contains("[height, width, focal]"),
        "{e}"
    );
    // Wrong shape: a sub-frame file read as poses_bounds, and vice versa.
    write_subframes(&path, &[rows(2)]).unwrap();
    let e = read_poses_bounds(&path).unwrap_err().to_string();
    assert!(e.contains("(N, 17)"), "{e}");
    write_poses_bounds(&path, &rows(2)).unwrap();
    let e = read_subframes(&path).unwrap_err().to_string();
    assert!(e.contains("(N, S, 17)"), "{e}");
    // Truncated.
    let bytes = std::fs::read(&path).unwrap();
    std::fs::write(&path, &bytes[..bytes.len() - 3]).unwrap();
    let e = read_poses_bounds(&path).unwrap_err().to_string();
    assert!(
        e.contains("poses_bounds.npy") && e.contains("truncated"),
        "{e}"
    );
    // Missing.
    let e = read_poses_bounds(&dir.path().join("nope.npy"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("nope.npy"), "{e}");
}

proptest! {
    #[test]
    fn pose_conversion_round_trips(angle in -3.0f64..3.0, tx in -5.0f64..5.0, tz in -5.0f64..5.0) {
        let p = rot_pose(angle, [tx, 1.0, tz]);
        let q = LlffRow::from_pose(&p, 10.0, 20.0, 30.0, 1.0, 2.0).pose();
        for i in 0..3 {
            prop_assert!((p.translation[i] - q.translation[i]).abs() < 1e-12);
            for j in 0..3 {
                prop_assert!((p.rotation[i][j] - q.rotation[i][j]).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn arbitrary_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..400)) {
        let _ = parse_poses_bounds(&bytes);
        let _ = parse_subframes(&bytes);
        // Also with a valid magic so the header parser is exercised.
        let mut b = b"\x93NUMPY\x01\x00".to_vec();
        b.extend_from_slice(&bytes);
        let _ = parse_poses_bounds(&b);
        let _ = parse_subframes(&b);
    }

    #[test]
    fn corrupted_headers_never_panic(pos in 0usize..128, val in any::<u8>()) {
        let mut b = poses_bounds_to_bytes(&rows(2));
        b[pos] = val;
        let _ = parse_poses_bounds(&b);
        let _ = parse_subframes(&b);
    }
}

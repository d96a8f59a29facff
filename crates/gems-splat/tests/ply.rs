//! Inria PLY: round trips at every SH degree, the channel-major f_rest layout, foreign files
//! with extra properties, and clear errors on malformed files.

#![allow(clippy::needless_range_loop)]

mod common;

use gems_splat::ply::{read_ply, write_ply};
use gems_splat::{Gaussians, SplatError};

#[test]
fn round_trip_every_degree() {
    let dir = tempfile::tempdir().unwrap();
    for degree in 0..=3 {
        let (mut g, _, _) =
            common::random_scene(40 + degree as u64, 37, 1, 8, 8, degree, (-3.0, -1.0));
        // Coefficients above the degree are not stored; zero them for the comparison.
        let k = ((degree + 1) * (degree + 1)) as usize;
        for sh in &mut g.sh {
            for row in sh.iter_mut().skip(k) {
                *row = [0.0; 3];
            }
        }
        let path = dir.path().join(format!("scene{degree}.ply"));
        write_ply(&path, &g).unwrap();
        let back = read_ply(&path).unwrap();
        assert_eq!(back, g, "degree {degree}");
    }
}

#[test]
fn reads_ascii_with_normals_extra_properties_and_channel_major_rest() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("a.ply");
    let mut header =
        String::from("ply\nformat ascii 1.0\ncomment made by hand\nelement vertex 2\n");
    let mut props = vec![
        "x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2",
    ]
    .into_iter()
    .map(String::from)
    .collect::<Vec<_>>();
    for i in 0..9 {
        props.push(format!("f_rest_{i}"));
    }
    for p in [
        "opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3",
    ] {
        props.push(p.into());
    }
    props.push("red_extra".into());
    for p in &props {
        header.push_str(&format!("property float {p}\n"));
    }
    header.push_str("end_header\n");
    let row = |base: f32| {
        (0..props.len())
            .map(|k| format!("{}", base + k as f32))
            .collect::<Vec<_>>()
            .join(" ")
    };
    std::fs::write(&path, format!("{header}{}\n{}\n", row(0.0), row(100.0))).unwrap();
    let g = read_ply(&path).unwrap();
    assert_eq!(g.len(), 2);
    assert_eq!(g.sh_degree, 1);
    assert_eq!(g.means[1], [100.0, 101.0, 102.0]);
    assert_eq!(g.sh[0][0], [6.0, 7.0, 8.0]);
    // f_rest_0..2 are red of coefficients 1..3, f_rest_3..5 green, f_rest_6..8 blue.
    assert_eq!(g.sh[0][1], [9.0, 12.0, 15.0]);
    assert_eq!(g.sh[0][3], [11.0, 14.0, 17.0]);
    assert_eq!(g.opacity_logits[0], 18.0);
    assert_eq!(g.log_scales[0], [19.0, 20.0, 21.0]);
    assert_eq!(g.quats[0], [22.0, 23.0, 24.0, 25.0]);
}

fn write_and_read(name: &str, content: &[u8]) -> SplatError {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join(name);
    std::fs::write(&path, content).unwrap();
    let e = read_ply(&path).unwrap_err();
    assert!(
        e.to_string().contains(name),
        "error should name the file: {e}"
    );
    e
}

#[test]
fn malformed_files_give_clear_errors() {
    let e = write_and_read("junk.ply", b"not a ply file at all");
    assert!(matches!(e, SplatError::Ply { .. }));
    let minimal = "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nend_header\n1 2 3\n";
    let e = write_and_read("points.ply", minimal.as_bytes());
    assert!(e.to_string().contains("f_dc_0"), "{e}");
    // Truncated binary body.
    let dir = tempfile::tempdir().unwrap();
    let good = dir.path().join("good.ply");
    let (g, _, _) = common::random_scene(3, 5, 1, 8, 8, 2, (-3.0, -1.0));
    write_ply(&good, &g).unwrap();
    let bytes = std::fs::read(&good).unwrap();
    write_and_read("truncated.ply", &bytes[..bytes.len() - 10]);
    // A wrong number of f_rest properties.
    let text = String::from_utf8_lossy(&bytes[..bytes.len().min(2000)]).to_string();
    assert!(text.contains("f_rest_23"));
    let mut header = String::from("ply\nformat ascii 1.0\nelement vertex 1\n");
    let mut vals = Vec::new();
    for p in [
        "x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2", "f_rest_0", "f_rest_1", "opacity",
    ]
    .into_iter()
    .chain([
        "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3",
    ]) {
        header.push_str(&format!("property float {p}\n"));
        vals.push("1");
    }
    header.push_str("end_header\n");
    let e = write_and_read(
        "rest.ply",
        format!("{header}{}\n", vals.join(" ")).as_bytes(),
    );
    assert!(e.to_string().contains("f_rest"), "{e}");
    let e = read_ply(dir.path().join("missing.ply")).unwrap_err();
    assert!(e.to_string().contains("missing.ply"), "{e}");
}

#[test]
fn failed_write_leaves_no_file() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bad.ply");
    let mut g = Gaussians::with_degree(1);
    g.means.push([0.0; 3]);
    assert!(write_ply(&path, &g).is_err());
    assert!(!path.exists());
    assert_eq!(
        std::fs::read_dir(dir.path()).unwrap().count(),
        0,
        "no temporary left behind"
    );
}

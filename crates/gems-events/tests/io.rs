//! Readers and writers: round trips, the real AEDAT4 fixture, malformed files, fuzzing.

use std::path::{Path, PathBuf};

use gems_events::*;
use proptest::prelude::*;

const AEDAT: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../../testdata/events/davis346_street.aedat4"
);

fn sample_stream() -> EventStream {
    EventStream::from_columns(
        40,
        30,
        vec![-5, 0, 0, 17, 1_000_000, 2_097_134, 9_000_001],
        vec![0, 39, 5, 6, 7, 8, 1],
        vec![0, 29, 5, 6, 7, 8, 2],
        vec![1, -1, 1, -1, 1, -1, 1],
    )
    .unwrap()
}

fn write_npy<T: npyz::Serialize + npyz::AutoSerialize>(
    path: &Path,
    shape: impl AsRef<[u64]>,
    data: Vec<T>,
) -> std::io::Result<()> {
    use npyz::WriterBuilder;
    let f = std::io::BufWriter::new(std::fs::File::create(path)?);
    let mut w = npyz::WriteOptions::<T>::new()
        .default_dtype()
        .shape(shape.as_ref())
        .writer(f)
        .begin_nd()?;
    w.extend(data)?;
    w.finish()
}

fn write(dir: &Path, name: &str, body: &[u8]) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, body).unwrap();
    p
}

#[test]
fn windows_are_inclusive_and_zero_copy() {
    let s = sample_stream();
    let w = s.window(0, 17);
    assert_eq!(w.t(), &[0, 0, 17]);
    assert!(
        std::ptr::eq(w.t().as_ptr(), s.t()[1..].as_ptr()),
        "window must borrow, not copy"
    );
    assert!(s.window(18, 999_999).is_empty());
    assert!(s.window(10, 5).is_empty());
    assert_eq!(w.window(1, 100).t(), &[17]);
    assert_eq!(s.time_span(), Some((-5, 9_000_001)));
}

#[test]
fn unsorted_columns_are_sorted_stably_and_invalid_ones_rejected() {
    let s = EventStream::from_columns(
        4,
        4,
        vec![5, 1, 5, 0],
        vec![0, 1, 2, 3],
        vec![0; 4],
        vec![1, 1, -1, 1],
    )
    .unwrap();
    assert_eq!(s.t(), &[0, 1, 5, 5]);
    assert_eq!(s.x(), &[3, 1, 0, 2], "equal times keep input order");
    assert!(EventStream::from_columns(4, 4, vec![0], vec![4], vec![0], vec![1]).is_err());
    assert!(EventStream::from_columns(4, 4, vec![0], vec![0], vec![4], vec![1]).is_err());
    assert!(EventStream::from_columns(4, 4, vec![0], vec![0], vec![0], vec![0]).is_err());
    assert!(EventStream::from_columns(4, 4, vec![0, 1], vec![0], vec![0], vec![1]).is_err());
}

#[test]
fn bin_counts_follow_e2nerf_bins() {
    // window [0, 100], 4 bins: (0,25], (25,50], (50,75], (75,100]; t = 0 goes to bin 0
    let s = EventStream::from_columns(
        2,
        1,
        vec![0, 25, 26, 50, 75, 99, 100, 101],
        vec![0, 0, 1, 0, 1, 0, 0, 0],
        vec![0; 8],
        vec![1, 1, -1, -1, 1, 1, -1, 1],
    )
    .unwrap();
    let c = s.as_slice().bin_counts(0, 100, 4).unwrap();
    assert_eq!((c.views, c.bins, c.height, c.width), (1, 4, 1, 2));
    assert_eq!(c.bin(0, 0), &[2.0, 0.0]);
    assert_eq!(c.bin(0, 1), &[-1.0, -1.0]);
    assert_eq!(c.bin(0, 2), &[0.0, 1.0]);
    assert_eq!(
        c.bin(0, 3),
        &[0.0, 0.0],
        "+1 at 99 and −1 at 100 cancel; 101 is outside"
    );
    assert!(s.as_slice().bin_counts(5, 5, 4).is_err());
}

#[test]
fn text_round_trip_and_ecd_parsing() {
    let dir = tempfile::tempdir().unwrap();
    let s = sample_stream();
    let p = dir.path().join("events.txt");
    write_events_text(&p, &s).unwrap();
    assert_eq!(read_events(&p, &ReadOptions::default()).unwrap(), s);

    // ECD/v2e style: comments, ns-precision seconds, 0/1 polarity, optional 5th column, CRLF
    let body = b"#!events.txt\n# This is a v2e file\n2.097134001 162 27 0\r\n2.097135 3 4 1 1\n\n2.1 0 0 1\n";
    let p = write(dir.path(), "ecd.txt", body);
    let e = read_events(&p, &ReadOptions::default()).unwrap();
    assert_eq!(e.t(), &[2_097_134, 2_097_135, 2_100_000]);
    assert_eq!(e.x(), &[162, 3, 0]);
    assert_eq!(e.p(), &[-1, 1, 1]);
    assert_eq!(
        (e.width(), e.height()),
        (163, 28),
        "size from the event bounding box"
    );
    let e = read_events(
        &p,
        &ReadOptions {
            size: Some((240, 180)),
            ..ReadOptions::default()
        },
    )
    .unwrap();
    assert_eq!((e.width(), e.height()), (240, 180));
}

#[test]
fn big_text_file_parses_across_chunks_in_order() {
    let dir = tempfile::tempdir().unwrap();
    let n = 600_000;
    let t: Vec<i64> = (0..n).map(|i| i as i64 * 3).collect();
    let x: Vec<u16> = (0..n).map(|i| (i * 7 % 640) as u16).collect();
    let y: Vec<u16> = (0..n).map(|i| (i * 13 % 480) as u16).collect();
    let p: Vec<i8> = (0..n).map(|i| if i % 3 == 0 { 1 } else { -1 }).collect();
    let s = EventStream::from_columns(640, 480, t, x, y, p).unwrap();
    let path = dir.path().join("big.txt");
    write_events_text(&path, &s).unwrap();
    assert!(
        std::fs::metadata(&path).unwrap().len() > 8 << 20,
        "must span several parse chunks"
    );
    assert_eq!(read_events(&path, &ReadOptions::default()).unwrap(), s);
}

#[test]
fn npz_round_trip_and_foreign_npy_layouts() {
    let dir = tempfile::tempdir().unwrap();
    let s = sample_stream();
    let p = dir.path().join("ev.npz");
    write_events_npz(&p, &s).unwrap();
    assert_eq!(read_events(&p, &ReadOptions::default()).unwrap(), s);

    // tub-rip style N×4 float (t[s], x, y, p∈{0,1})
    let rows: Vec<f64> = vec![0.5, 3.0, 4.0, 1.0, 0.75, 1.0, 2.0, 0.0];
    let p4 = dir.path().join("events.npy");
    write_npy(&p4, [2u64, 4], rows).unwrap();
    let e = read_events(&p4, &ReadOptions::default()).unwrap();
    assert_eq!(
        (e.t(), e.x(), e.y(), e.p()),
        (
            &[500_000i64, 750_000][..],
            &[3u16, 1][..],
            &[4u16, 2][..],
            &[1i8, -1][..]
        )
    );

    // BeNeRF style N×4 (x, y, t[µs ints], p); column 0 unsorted, column 2 sorted
    let rows: Vec<i64> = vec![9, 1, 100, 1, 2, 3, 200, 0, 5, 0, 300, 1];
    let p4 = dir.path().join("xytp.npy");
    write_npy(&p4, [3u64, 4], rows).unwrap();
    let e = read_events(&p4, &ReadOptions::default()).unwrap();
    assert_eq!(e.t(), &[100, 200, 300]);
    assert_eq!(e.x(), &[9, 2, 5]);

    // rpg_vid2e style npz with int64 ns
    let p5 = dir.path().join("vid2e.npz");
    {
        let f = std::fs::File::create(&p5).unwrap();
        let mut npz = npyz::npz::NpzWriter::new(std::io::BufWriter::new(f));
        use npyz::WriterBuilder;
        for (name, v) in [
            ("t", vec![1_000i64, 2_600]),
            ("x", vec![1, 2]),
            ("y", vec![0, 0]),
            ("p", vec![-1, 1]),
        ] {
            let mut a = npz
                .array::<i64>(name, Default::default())
                .unwrap()
                .default_dtype()
                .shape(&[2])
                .begin_nd()
                .unwrap();
            a.extend(v).unwrap();
            a.finish().unwrap();
        }
    }
    let opts = ReadOptions {
        int_time_unit: TimeUnit::Nanoseconds,
        ..ReadOptions::default()
    };
    let e = read_events(&p5, &opts).unwrap();
    assert_eq!(e.t(), &[1, 3]);
    assert_eq!(e.p(), &[-1, 1]);
}

#[test]
fn bin_count_tensors_round_trip() {
    let dir = tempfile::tempdir().unwrap();
    let c = BinCounts {
        views: 2,
        bins: 3,
        height: 2,
        width: 4,
        data: (0..48).map(|i| i as f32 - 20.0).collect(),
    };
    let p = dir.path().join("bins.npy");
    write_bin_counts(&p, &c).unwrap();
    assert_eq!(read_bin_counts(&p, None).unwrap(), c);
    // the E2NeRF [views, bins, H·W] flavour needs the size
    let flat = dir.path().join("flat.npy");
    write_npy(
        &flat,
        [2u64, 3, 8],
        c.data.iter().map(|&v| f64::from(v)).collect::<Vec<_>>(),
    )
    .unwrap();
    assert!(read_bin_counts(&flat, None).is_err());
    assert!(read_bin_counts(&flat, Some((3, 3))).is_err());
    assert_eq!(read_bin_counts(&flat, Some((4, 2))).unwrap(), c);
}

#[test]
fn exposure_windows() {
    let dir = tempfile::tempdir().unwrap();
    write(
        dir.path(),
        "exposure_start_ts.txt",
        b"1000\n# comment\n2000\n",
    );
    write(dir.path(), "exposure_end_ts.txt", b"1500\n2600\n");
    let w = read_exposure_windows(dir.path(), TimeUnit::Microseconds).unwrap();
    assert_eq!(
        w,
        vec![
            ExposureWindow {
                start: 1000,
                end: 1500
            },
            ExposureWindow {
                start: 2000,
                end: 2600
            }
        ]
    );
    assert_eq!(w[1].mid(), 2300);
    write(dir.path(), "exposure_end_ts.txt", b"1500\n");
    let e = read_exposure_windows(dir.path(), TimeUnit::Microseconds)
        .unwrap_err()
        .to_string();
    assert!(e.contains("exposure_end_ts.txt"), "{e}");
    write(dir.path(), "exposure_end_ts.txt", b"1500\n1999\n");
    assert!(read_exposure_windows(dir.path(), TimeUnit::Microseconds).is_err());
}

#[test]
fn aedat4_fixture_matches_its_published_contents() {
    let rec = read_aedat4(Path::new(AEDAT)).unwrap();
    let e = &rec.events;
    assert_eq!((e.width(), e.height()), (346, 260));
    assert_eq!(e.len(), 78_830);
    assert_eq!(e.p().iter().filter(|&&p| p > 0).count(), 41_257);
    let (t0, t1) = e.time_span().unwrap();
    assert!(
        (2_300_000..2_400_000).contains(&(t1 - t0)),
        "≈2.36 s of events, got {} µs",
        t1 - t0
    );
    assert_eq!(rec.frames.len(), 59);
    for f in &rec.frames {
        assert_eq!((f.width, f.height, f.channels), (346, 260, 1));
        assert_eq!(f.pixels.len(), 346 * 260);
        assert!(
            (f.exposure_end - f.exposure_begin - 500).abs() <= 5,
            "500 µs exposure"
        );
    }
    let dt: Vec<i64> = rec.frames.windows(2).map(|w| w[1].t - w[0].t).collect();
    let mean = dt.iter().sum::<i64>() as f64 / dt.len() as f64;
    assert!(
        (mean - 40_000.0).abs() < 2_000.0,
        "25 Hz frames, mean spacing {mean} µs"
    );
    assert_eq!(
        read_events(Path::new(AEDAT), &ReadOptions::default()).unwrap(),
        rec.events
    );
}

#[test]
fn malformed_files_give_one_clear_error_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let cases: Vec<(&str, &[u8], &str)> = vec![
        ("bad_t.txt", b"0.1 1 2 1\nabc 1 2 1\n", "line 2"),
        ("bad_p.txt", b"0.1 1 2 7\n", "polarity"),
        ("short.txt", b"0.1 1 2\n", "missing polarity"),
        ("neg_x.txt", b"0.1 -1 2 1\n", "bad x"),
        ("garbage.npy", b"\x93NUMPY garbage", "npy"),
        ("garbage.npz", b"PK\x03\x04 nope", "npz"),
        ("trunc.aedat4", b"#!AER-DAT4.0\r\n\x10\x00", "truncated"),
        ("nomagic.aedat4", b"hello", "AEDAT"),
        ("events.h5", b"\x89HDF\r\n", "HDF5"),
        ("events.bin", b"", "unknown event file type"),
    ];
    for (name, body, needle) in cases {
        let p = write(dir.path(), name, body);
        let err = read_events(&p, &ReadOptions::default())
            .unwrap_err()
            .to_string();
        assert!(
            err.contains(name),
            "{name}: error must name the file: {err}"
        );
        assert!(
            err.contains(needle),
            "{name}: expected '{needle}' in: {err}"
        );
    }
    // npy with the wrong shape and a truncated copy of the real AEDAT4 file
    let p = dir.path().join("wrong_shape.npy");
    write_npy(&p, [2u64, 3], vec![0f64; 6]).unwrap();
    assert!(
        read_events(&p, &ReadOptions::default())
            .unwrap_err()
            .to_string()
            .contains("N×4")
    );
    let full = std::fs::read(AEDAT).unwrap();
    let p = write(dir.path(), "cut.aedat4", &full[..full.len() / 2]);
    let err = read_events(&p, &ReadOptions::default())
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("cut.aedat4") && err.contains("packet"),
        "{err}"
    );
    let missing = dir.path().join("absent.txt");
    assert!(
        read_events(&missing, &ReadOptions::default())
            .unwrap_err()
            .to_string()
            .contains("absent.txt")
    );
}

#[test]
fn writers_are_atomic_and_leave_no_temp_files() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("ev.npz");
    write_events_npz(&p, &sample_stream()).unwrap();
    write_events_text(&dir.path().join("ev.txt"), &sample_stream()).unwrap();
    let names: Vec<String> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert_eq!(names.len(), 2, "{names:?}");
    // writing into a missing folder fails cleanly, naming the target
    let err = write_events_npz(&dir.path().join("nope/ev.npz"), &sample_stream())
        .unwrap_err()
        .to_string();
    assert!(err.contains("ev.npz"), "{err}");
}

fn parse_bytes(name: &str, bytes: &[u8]) {
    let dir = tempfile::tempdir().unwrap();
    let p = write(dir.path(), name, bytes);
    let _ = read_events(&p, &ReadOptions::default());
    if name.ends_with(".npy") {
        let _ = read_bin_counts(&p, Some((4, 4)));
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 96, ..ProptestConfig::default() })]
    #[test]
    fn arbitrary_bytes_never_panic_aedat4(tail in proptest::collection::vec(any::<u8>(), 0..512)) {
        let mut b = b"#!AER-DAT4.0\r\n".to_vec();
        b.extend(tail);
        parse_bytes("f.aedat4", &b);
    }
    #[test]
    fn corrupted_real_aedat4_never_panics(pos in 0usize..20_000, val in any::<u8>(), cut in 1000usize..40_000) {
        let mut b = std::fs::read(AEDAT).unwrap();
        b.truncate(cut);
        let i = pos % b.len();
        b[i] = val;
        parse_bytes("f.aedat4", &b);
    }
    #[test]
    fn arbitrary_bytes_never_panic_npy(tail in proptest::collection::vec(any::<u8>(), 0..256)) {
        let mut b = b"\x93NUMPY\x01\x00".to_vec();
        b.extend(tail);
        parse_bytes("f.npy", &b);
    }
    #[test]
    fn arbitrary_bytes_never_panic_npz(tail in proptest::collection::vec(any::<u8>(), 0..256)) {
        let mut b = b"PK\x03\x04".to_vec();
        b.extend(tail);
        parse_bytes("f.npz", &b);
    }
    #[test]
    fn arbitrary_bytes_never_panic_text(b in proptest::collection::vec(any::<u8>(), 0..256)) {
        parse_bytes("f.txt", &b);
    }
}

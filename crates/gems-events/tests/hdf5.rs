//! HDF5 reader: files written here with the hdf5 crate in the layouts of v2e, EvDeblurNeRF/LSENeRF
//! (root x/y/t/p), DSEC/TUM-VIE (`events/` group) and xs/ys/ts/ps float-seconds files, read back
//! through `read_events` and compared exactly; malformed files must give one error naming the file.
#![cfg(feature = "hdf5")]

use std::path::{Path, PathBuf};

use gems_events::{EventError, ReadOptions, TimeUnit, read_events, read_events_hdf5};

fn ds<T: hdf5::H5Type>(g: &hdf5::Group, name: &str, data: &[T]) {
    g.new_dataset_builder()
        .with_data(data)
        .create(name)
        .unwrap();
}

fn scalar_attr(g: &hdf5::Group, name: &str, v: u32) {
    g.new_attr::<u32>()
        .shape(())
        .create(name)
        .unwrap()
        .write_scalar(&v)
        .unwrap();
}

fn cols(s: &gems_events::EventStream) -> (Vec<i64>, Vec<u16>, Vec<u16>, Vec<i8>, u16, u16) {
    (
        s.t().to_vec(),
        s.x().to_vec(),
        s.y().to_vec(),
        s.p().to_vec(),
        s.width(),
        s.height(),
    )
}

#[test]
fn flat_root_integer_columns_read_exactly() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("events.h5");
    {
        let f = hdf5::File::create(&path).unwrap();
        // Times beyond 2^53 µs would lose precision through f64: integers must stay exact.
        let big = 1_i64 << 60;
        ds(&f, "t", &[big, big + 1, big + 3]);
        ds(&f, "x", &[0_u16, 7, 3]);
        ds(&f, "y", &[5_u16, 0, 2]);
        ds(&f, "p", &[1_i8, -1, 1]);
    }
    let s = read_events(&path, &ReadOptions::default()).unwrap();
    let big = 1_i64 << 60;
    assert_eq!(
        cols(&s),
        (
            vec![big, big + 1, big + 3],
            vec![0, 7, 3],
            vec![5, 0, 2],
            vec![1, -1, 1],
            8, // bounding box: max x + 1
            6,
        )
    );
    // Integer times in ns are rounded to µs by int_time_unit.
    let ns = ReadOptions {
        int_time_unit: TimeUnit::Nanoseconds,
        size: Some((640, 480)),
        ..ReadOptions::default()
    };
    let s = read_events(&path, &ns).unwrap();
    let expect = big / 1000; // 2^60 ns: big % 1000 = 976 → rounds up
    assert_eq!(s.t(), &[expect + 1, expect + 1, expect + 1]);
    assert_eq!((s.width(), s.height()), (640, 480));
}

#[test]
fn events_group_with_float_seconds_and_01_polarity() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("rec.hdf5");
    {
        let f = hdf5::File::create(&path).unwrap();
        // A sibling group without event columns must not confuse the search.
        let other = f.create_group("calib").unwrap();
        ds(&other, "K", &[1.0_f64, 2.0, 3.0]);
        let g = f.create_group("events").unwrap();
        ds(&g, "ts", &[0.5_f64, 0.500_001, 1.25]);
        ds(&g, "xs", &[1.0_f32, 2.0, 345.0]);
        ds(&g, "ys", &[0.0_f32, 259.0, 4.0]);
        ds(&g, "ps", &[0_u8, 1, 0]);
        scalar_attr(&g, "width", 346);
        scalar_attr(&g, "height", 260);
    }
    let s = read_events(&path, &ReadOptions::default()).unwrap();
    assert_eq!(
        cols(&s),
        (
            vec![500_000, 500_001, 1_250_000],
            vec![1, 2, 345],
            vec![0, 259, 4],
            vec![-1, 1, -1],
            346,
            260,
        )
    );
    // float_time_unit applies to float time columns.
    let ms = ReadOptions {
        float_time_unit: TimeUnit::Milliseconds,
        ..ReadOptions::default()
    };
    assert_eq!(read_events(&path, &ms).unwrap().t(), &[500, 500, 1250]);
}

#[test]
fn unsorted_file_is_sorted_stably_and_matches_npz_reader() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("unsorted.h5");
    let t = [30_i64, 10, 20, 10];
    let x = [1_u16, 2, 3, 4];
    let y = [4_u16, 3, 2, 1];
    let p = [1_i8, 1, -1, -1];
    {
        let f = hdf5::File::create(&path).unwrap();
        ds(&f, "t", &t);
        ds(&f, "x", &x);
        ds(&f, "y", &y);
        ds(&f, "p", &p);
    }
    let h5 = read_events_hdf5(&path, &ReadOptions::default()).unwrap();
    let npz_path = dir.path().join("same.npz");
    let direct = gems_events::EventStream::from_columns(
        5,
        5,
        t.to_vec(),
        x.to_vec(),
        y.to_vec(),
        p.to_vec(),
    )
    .unwrap();
    gems_events::write_events_npz(&npz_path, &direct).unwrap();
    let npz = read_events(&npz_path, &ReadOptions::default()).unwrap();
    assert_eq!(cols(&h5), cols(&npz));
    assert_eq!(h5.t(), &[10, 10, 20, 30]);
    assert_eq!(h5.x(), &[2, 4, 3, 1]);
}

#[test]
fn v2e_n_by_4_events_dataset() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("v2e.h5");
    {
        let f = hdf5::File::create(&path).unwrap();
        let d = f
            .new_dataset::<u32>()
            .shape((3, 4))
            .create("events")
            .unwrap();
        // rows: t µs, x, y, p ∈ {0, 1}
        d.write_raw(&[100_u32, 3, 4, 1, 150, 0, 1, 0, 4_000_000_000, 9, 2, 1])
            .unwrap();
    }
    let s = read_events(&path, &ReadOptions::default()).unwrap();
    assert_eq!(
        cols(&s),
        (
            vec![100, 150, 4_000_000_000],
            vec![3, 0, 9],
            vec![4, 1, 2],
            vec![1, -1, 1],
            10,
            5,
        )
    );
}

fn expect_err(path: &Path, needle: &str) {
    let err = read_events(path, &ReadOptions::default()).unwrap_err();
    assert!(matches!(err, EventError::Format { .. }), "{err:?}");
    let msg = err.to_string();
    let name = path.file_name().unwrap().to_string_lossy();
    assert!(msg.contains(&*name), "error must name the file: {msg}");
    assert!(msg.contains(needle), "expected '{needle}' in: {msg}");
}

fn write_file(dir: &Path, name: &str, build: impl FnOnce(&hdf5::File)) -> PathBuf {
    let path = dir.join(name);
    let f = hdf5::File::create(&path).unwrap();
    build(&f);
    drop(f);
    path
}

#[test]
fn malformed_files_give_one_error_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let p = write_file(d, "no_p.h5", |f| {
        ds(f, "t", &[1_i64, 2]);
        ds(f, "x", &[1_u16, 2]);
        ds(f, "y", &[1_u16, 2]);
    });
    expect_err(&p, "missing dataset p");
    let p = write_file(d, "in_group_no_y.h5", |f| {
        let g = f.create_group("events").unwrap();
        ds(&g, "t", &[1_i64, 2]);
        ds(&g, "x", &[1_u16, 2]);
        ds(&g, "p", &[1_i8, 0]);
    });
    expect_err(&p, "missing dataset events/y");
    let p = write_file(d, "lengths.h5", |f| {
        ds(f, "t", &[1_i64, 2, 3]);
        ds(f, "x", &[1_u16, 2]);
        ds(f, "y", &[1_u16, 2, 3]);
        ds(f, "p", &[1_i8, 0, 1]);
    });
    expect_err(&p, "differ in length");
    let p = write_file(d, "empty.h5", |f| {
        f.create_group("nothing").unwrap();
    });
    expect_err(&p, "no event datasets");
    let p = write_file(d, "bad_pol.h5", |f| {
        ds(f, "t", &[1_i64]);
        ds(f, "x", &[1_u16]);
        ds(f, "y", &[1_u16]);
        ds(f, "p", &[2_i8]);
    });
    expect_err(&p, "polarity");
    let p = write_file(d, "frac_x.h5", |f| {
        ds(f, "t", &[1.0_f64]);
        ds(f, "x", &[1.5_f32]);
        ds(f, "y", &[1.0_f32]);
        ds(f, "p", &[1_i8]);
    });
    expect_err(&p, "not a pixel index");
    let p = write_file(d, "two_d.h5", |f| {
        f.new_dataset::<i64>()
            .shape((2, 2))
            .create("t")
            .unwrap()
            .write_raw(&[1_i64, 2, 3, 4])
            .unwrap();
        ds(f, "x", &[1_u16, 2]);
        ds(f, "y", &[1_u16, 2]);
        ds(f, "p", &[1_i8, 0]);
    });
    expect_err(&p, "must be 1-D");
    let p = write_file(d, "v2e_shape.h5", |f| ds(f, "events", &[1_u32, 2, 3]));
    expect_err(&p, "N×4");

    let p = d.join("not_hdf5.h5");
    std::fs::write(&p, b"this is not an HDF5 file at all").unwrap();
    expect_err(&p, "not a readable HDF5 file");

    // A missing file is an I/O error, still naming the file.
    let p = d.join("absent.h5");
    let err = read_events(&p, &ReadOptions::default()).unwrap_err();
    assert!(matches!(err, EventError::Io { .. }), "{err:?}");
    assert!(err.to_string().contains("absent.h5"));
}

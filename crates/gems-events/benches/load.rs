//! Loading a 50 M-event file (the benchmark) in our npz and in ECD text, plus windowing.
//! The files are generated once into a temporary folder before timing.

use std::path::PathBuf;
use std::sync::OnceLock;

use gems_events::{EventStream, ReadOptions, read_events, write_events_npz, write_events_text};

const N: usize = 50_000_000;

fn main() {
    divan::main();
}

struct Files {
    _dir: tempfile::TempDir,
    npz: PathBuf,
    txt: PathBuf,
}

fn stream() -> EventStream {
    // a cheap deterministic pseudo-random pattern: 346×260 sensor, ~5 s at 10 M ev/s
    let mut s: u64 = 0x9E37_79B9_7F4A_7C15;
    let mut next = || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        s
    };
    let t = (0..N as i64).map(|i| i / 10).collect();
    let x = (0..N).map(|_| (next() % 346) as u16).collect();
    let y = (0..N).map(|_| (next() % 260) as u16).collect();
    let p = (0..N)
        .map(|_| if next() & 1 == 0 { 1 } else { -1 })
        .collect();
    EventStream::from_columns(346, 260, t, x, y, p).unwrap()
}

fn files() -> &'static Files {
    static FILES: OnceLock<Files> = OnceLock::new();
    FILES.get_or_init(|| {
        let dir = tempfile::tempdir().unwrap();
        let s = stream();
        let npz = dir.path().join("events.npz");
        let txt = dir.path().join("events.txt");
        write_events_npz(&npz, &s).unwrap();
        write_events_text(&txt, &s).unwrap();
        Files {
            _dir: dir,
            npz,
            txt,
        }
    })
}

#[divan::bench(sample_count = 3, sample_size = 1)]
fn load_npz_50m(bencher: divan::Bencher) {
    let f = files();
    bencher.bench(|| read_events(&f.npz, &ReadOptions::default()).unwrap());
}

#[divan::bench(sample_count = 3, sample_size = 1)]
fn load_text_50m(bencher: divan::Bencher) {
    let f = files();
    bencher.bench(|| read_events(&f.txt, &ReadOptions::default()).unwrap());
}

#[divan::bench(sample_count = 3, sample_size = 1)]
fn write_npz_50m(bencher: divan::Bencher) {
    let s = stream();
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("w.npz");
    bencher.bench(|| write_events_npz(&p, &s).unwrap());
}

#[divan::bench]
fn window_1ms_of_50m(bencher: divan::Bencher) {
    static S: OnceLock<EventStream> = OnceLock::new();
    let s = S.get_or_init(stream);
    bencher.bench(|| s.window(2_000_000, 2_001_000).len());
}

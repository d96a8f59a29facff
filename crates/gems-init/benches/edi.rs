//! EDI of one 400×270 RGB view with 2 M events in its exposure (issue 5's benchmark), exact and
//! binned (b = 13), including the per-pixel grouping of the events; and the threshold search on
//! that view (grid of 17 + 12 golden-section steps, each one exact EDI + normalised sparsity).

use gems_events::EventStream;
use gems_init::edi::{
    EdiConfig, Image, PixelEvents, SearchConfig, Thresholds, edi_binned, edi_exact,
    estimate_thresholds,
};
use rand::{RngExt, SeedableRng};

const W: usize = 400;
const H: usize = 270;
const N: usize = 2_000_000;
const T: i64 = 40_000;

fn main() {
    divan::main();
}

fn setup() -> (Image, EventStream) {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
    let mut t: Vec<i64> = (0..N).map(|_| rng.random_range(0..=T)).collect();
    t.sort_unstable();
    let x = (0..N).map(|_| rng.random_range(0..W as u16)).collect();
    let y = (0..N).map(|_| rng.random_range(0..H as u16)).collect();
    let p = (0..N)
        .map(|_| if rng.random_bool(0.5) { 1 } else { -1 })
        .collect();
    let ev = EventStream::from_columns(W as u16, H as u16, t, x, y, p).unwrap();
    let img = Image::new(
        W,
        H,
        3,
        (0..W * H * 3)
            .map(|_| rng.random_range(0.05..0.95))
            .collect(),
    )
    .unwrap();
    (img, ev)
}

#[divan::bench(sample_count = 5)]
fn group_events(bencher: divan::Bencher) {
    let (_, ev) = setup();
    bencher.bench(|| PixelEvents::new(ev.as_slice(), 0, T).unwrap());
}

#[divan::bench(sample_count = 5)]
fn exact_including_grouping(bencher: divan::Bencher) {
    let (img, ev) = setup();
    let cfg = EdiConfig::default();
    bencher.bench(|| {
        let pe = PixelEvents::new(ev.as_slice(), 0, T).unwrap();
        edi_exact(&img, &pe, T / 2, Thresholds::equal(0.2), &cfg).unwrap()
    });
}

#[divan::bench(sample_count = 5)]
fn binned13_including_grouping(bencher: divan::Bencher) {
    let (img, ev) = setup();
    let cfg = EdiConfig::default();
    bencher.bench(|| {
        let pe = PixelEvents::new(ev.as_slice(), 0, T).unwrap();
        edi_binned(&img, &pe.bin_on_off(13), 13, Thresholds::equal(0.2), &cfg).unwrap()
    });
}

#[divan::bench(sample_count = 3)]
fn threshold_search_one_view(bencher: divan::Bencher) {
    let (img, ev) = setup();
    let pe = PixelEvents::new(ev.as_slice(), 0, T).unwrap();
    let cfg = EdiConfig::default();
    let search = SearchConfig::default();
    bencher.bench(|| estimate_thresholds(&[(&img, &pe, T / 2)], &search, &cfg));
}

//! Generation time of the presets (whole scene folder, events included).

use gems_synth::{SynthConfig, generate};

fn main() {
    divan::main();
}

#[divan::bench(sample_count = 3)]
fn tiny(bencher: divan::Bencher) {
    bench_preset(bencher, SynthConfig::tiny());
}

#[divan::bench(sample_count = 2)]
fn small(bencher: divan::Bencher) {
    bench_preset(bencher, SynthConfig::small());
}

fn bench_preset(bencher: divan::Bencher, config: SynthConfig) {
    bencher.bench(|| {
        let dir = tempfile::tempdir().unwrap();
        generate(&config, &dir.path().join("scene")).unwrap()
    });
}

//! The fused training loss runs every training step at ~400×270: its cost matters.
use gems_metrics::TrainingLoss;

fn main() {
    divan::main();
}

fn image(h: usize, w: usize, seed: u32) -> Vec<f32> {
    (0..h * w * 3)
        .map(|i| {
            let v = (i as u32)
                .wrapping_mul(2654435761)
                .wrapping_add(seed.wrapping_mul(40503));
            (v >> 8) as f32 / (1u32 << 24) as f32
        })
        .collect()
}

#[divan::bench]
fn training_loss_400x270(bencher: divan::Bencher) {
    let (h, w) = (270, 400);
    let (r, t) = (image(h, w, 1), image(h, w, 2));
    let mut loss = TrainingLoss::new(h, w, 0.3).unwrap();
    let mut grad = vec![0.0; r.len()];
    bencher.bench_local(|| loss.compute(&r, &t, &mut grad).unwrap());
}

#[divan::bench]
fn eval_ssim_400x270(bencher: divan::Bencher) {
    let (h, w) = (270, 400);
    let (r, t) = (image(h, w, 1), image(h, w, 2));
    bencher.bench(|| gems_metrics::ssim(&r, &t, h, w).unwrap());
}

#[divan::bench(sample_count = 5)]
fn lpips_alex_400x270(bencher: divan::Bencher) {
    let (h, w) = (270, 400);
    let (r, t) = (image(h, w, 1), image(h, w, 2));
    let weights = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../testdata/metrics/lpips_alex_random_weights.safetensors"
    );
    let net = gems_metrics::Lpips::load(&[weights]).unwrap();
    bencher.bench_local(|| net.distance(&r, &t, h, w).unwrap());
}

//! Cost of test-time pose refinement (100 forward+backward renders per held-out view).
fn main() {
    divan::main();
}

#[divan::bench(sample_count = 3)]
fn refine_100_steps_128x96_2k_gaussians(bencher: divan::Bencher) {
    let (g, k, c2w) = gems_eval_bench_scene();
    let mut renderer = gems_gpu::Engine::cpu();
    let gt = gems_eval::refine::render(&mut renderer, &g, &c2w, &k).unwrap();
    let start = c2w
        * gems_math::Se3::exp(&gems_math::Vector6::from([
            0.01, -0.01, 0.0, 0.0, 0.01, 0.0,
        ]));
    bencher.bench_local(|| {
        gems_eval::refine_pose(
            &mut renderer,
            &g,
            &start,
            &k,
            &gt,
            &gems_eval::PoseRefineConfig::default(),
        )
        .unwrap()
    });
}

fn gems_eval_bench_scene() -> (gems_splat::Gaussians, gems_math::Intrinsics, gems_math::Se3) {
    let mut g = gems_splat::Gaussians::with_degree(0);
    for i in 0..2000u32 {
        let f = |s: u32| {
            ((i.wrapping_mul(2654435761)
                .wrapping_add(s.wrapping_mul(40503))
                >> 8) as f32
                / (1u32 << 24) as f32)
                - 0.5
        };
        let mut sh = [[0.0f32; 3]; 16];
        sh[0] = [f(4) * 3.0, f(5) * 3.0, f(6) * 3.0];
        g.push(
            [f(1) * 4.0, f(2) * 3.0, f(3) * 2.0],
            [1.0, 0.0, 0.0, 0.0],
            [-2.5; 3],
            1.0,
            sh,
        );
    }
    let k = gems_math::Intrinsics {
        fx: 110.0,
        fy: 110.0,
        cx: 64.0,
        cy: 48.0,
        width: 128,
        height: 96,
    };
    let c2w = gems_math::look_at_c2w(
        &gems_math::Vector3::new(0.0, 0.0, -6.0),
        &gems_math::Vector3::zeros(),
        &gems_math::Vector3::new(0.0, -1.0, 0.0),
    )
    .unwrap();
    (g, k, c2w)
}

//! Divan benchmark of the whole pipeline on one 512×512 image: from a file on disk to written outputs.

use rangeseg::Config;

fn main() {
    divan::main();
}

/// Reads `abw.train.0.range`, runs every stage and writes all outputs, on the calling thread.
#[divan::bench(sample_count = 10)]
fn file_to_outputs(b: divan::Bencher) {
    let dir = tempfile::tempdir().expect("temp dir");
    let (params, seed) = scenegen::benchmark_image(false, 0);
    let scene = scenegen::generate(&params, seed);
    let input = dir.path().join("abw.train.0.range");
    let range = scene.range.map(|&v| if v == 0 { f32::NAN } else { f32::from(v) });
    rangeio::abw::write_range(&input, &range).expect("write input");
    let out = dir.path().join("out");
    std::fs::create_dir_all(&out).expect("out dir");
    let config = Config::default();
    b.bench(|| {
        let frame = rangeio::read(&input, &Default::default()).expect("read");
        let result = rangeseg::segment(&frame.range, &frame.camera, &config);
        rangeseg::write_outputs(&out, "abw.train.0", &frame, &result).expect("write")
    });
}

/// The stages alone, from an in-memory range image to the final segmentation.
#[divan::bench(sample_count = 10)]
fn stages_in_memory(b: divan::Bencher) {
    let (params, seed) = scenegen::benchmark_image(false, 0);
    let scene = scenegen::generate(&params, seed);
    let range = scene.range.map(|&v| if v == 0 { f32::NAN } else { f32::from(v) });
    let config = Config::default();
    b.bench(|| rangeseg::segment(&range, &rangeimage::Camera::ABW0, &config));
}

/// The vectorial Canny from a range image to C2: the local planes (`features::fit_planes`) and
/// `vcanny::detect_planes` on them, on `abw.train.0` in memory.
#[divan::bench]
fn range_to_c2(b: divan::Bencher) {
    let (params, seed) = scenegen::benchmark_image(false, 0);
    let scene = scenegen::generate(&params, seed);
    let range = scene.range.map(|&v| if v == 0 { f32::NAN } else { f32::from(v) });
    let config = Config::default();
    b.bench(|| {
        let planes = features::fit_planes(divan::black_box(&range), config.features.window_px);
        let valid = rangeimage::valid_mask(&range);
        vcanny::detect_planes(&planes, &valid, &config.vcanny)
    });
}

//! Divan benchmarks of the whole pipeline on one 512×512 image (from a file on disk to written outputs, and in
//! memory), of the whole method in memory on the ABW-like 512² image and the 640×480 Kinect frame of `data/real`
//! (depth → labels + planes; on the Kinect frame also decimated, as `configs/fast.toml` runs it), of the range image
//! → C2 path, and of the features stage on frames with no-data.

use rangeseg::Config;

fn main() {
    divan::main();
}

/// Reads `abw.train.0.range`, runs every stage and writes all outputs, on the calling thread, with one
/// `Segmenter` for all iterations (as the CLI's workers run a stream of images).
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
    let mut seg = rangeseg::pipeline::Segmenter::new(Config::default());
    b.bench_local(|| {
        let frame = rangeio::read(&input, &Default::default()).expect("read");
        let result = seg.segment(&frame.range, &frame.camera);
        rangeseg::write_outputs(&out, "abw.train.0", &frame, result).expect("write")
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

/// A bench frame by name: `abw.train.0` (the synthetic ABW-like 512×512 image) or `tum-kinect` (the TUM RGB-D
/// Kinect frame of `data/real`, 640×480, 19 % no data), with its camera.
fn frame(name: &str) -> (rangeimage::RangeImage, rangeimage::Camera) {
    match name {
        "abw.train.0" => {
            let (params, seed) = scenegen::benchmark_image(false, 0);
            let range = scenegen::generate(&params, seed)
                .range
                .map(|&v| if v == 0 { f32::NAN } else { f32::from(v) });
            (range, rangeimage::Camera::ABW0)
        }
        _ => {
            let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("data/real/open3d-testdata/RGBD/other_formats/TUM_depth.png");
            let f = rangeio::read(&path, &Default::default()).expect("read the TUM frame");
            (f.range, f.camera)
        }
    }
}

/// The whole method in memory, from the depth array to the final labels and the regions' planes
/// (`segment` + `planes`), one frame after another on the calling thread.
#[divan::bench(args = ["abw.train.0", "tum-kinect"], sample_count = 20)]
fn depth_to_planes(b: divan::Bencher, name: &str) {
    let (range, camera) = frame(name);
    let config = Config::default();
    b.bench_local(|| {
        let out = rangeseg::segment(divan::black_box(&range), &camera, &config);
        let planes = rangeseg::planes(&range, &out.fin.labels, &camera);
        (out, planes)
    });
}

/// [`depth_to_planes`] with one `Segmenter` for all frames (a stream of frames of one size).
#[divan::bench(args = ["abw.train.0", "tum-kinect"], sample_count = 20)]
fn stream_depth_to_planes(b: divan::Bencher, name: &str) {
    let (range, camera) = frame(name);
    let mut seg = rangeseg::pipeline::Segmenter::new(Config::default());
    b.bench_local(|| {
        let out = seg.segment(divan::black_box(&range), &camera);
        rangeseg::planes(&range, &out.fin.labels, &camera)
    });
}

/// [`stream_depth_to_planes`] on the Kinect frame with `pipeline.decimate` = 2 or 3 (`configs/fast.toml` sets 3): the
/// stages on f × f blocks, the labels carried back to every pixel.
#[divan::bench(args = [2, 3], sample_count = 20)]
fn stream_depth_to_planes_decimated(b: divan::Bencher, decimate: u32) {
    let (range, camera) = frame("tum-kinect");
    let pipeline = rangeseg::PipelineParams { decimate, ..Default::default() };
    let mut seg = rangeseg::pipeline::Segmenter::new(Config { pipeline, ..Default::default() });
    b.bench_local(|| {
        let out = seg.segment(divan::black_box(&range), &camera);
        rangeseg::planes(&range, &out.fin.labels, &camera)
    });
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

/// `features::compute_into` (the output grids of the previous frame reused) on frames with no-data, whose windows
/// take the general path: `abw.train.0` (projector shadows and dropouts, 512×512) and the TUM RGB-D Kinect frame of
/// `data/real` (640×480, 19 % no data).
#[divan::bench(args = ["abw.train.0", "tum-kinect"])]
fn features_with_holes(b: divan::Bencher, frame: &str) {
    let range = match frame {
        "abw.train.0" => {
            let (params, seed) = scenegen::benchmark_image(false, 0);
            scenegen::generate(&params, seed).range.map(|&v| if v == 0 { f32::NAN } else { f32::from(v) })
        }
        _ => {
            let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("data/real/open3d-testdata/RGBD/other_formats/TUM_depth.png");
            rangeio::read(&path, &Default::default()).expect("read the TUM frame").range
        }
    };
    let params = Config::default().features;
    let mut out = features::compute(&range, &params);
    b.bench_local(|| features::compute_into(divan::black_box(&range), &params, &mut out));
}

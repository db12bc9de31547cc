//! `Segmenter` on a stream of frames: after the first frame it allocates nothing image-sized, final segmentation
//! included (a counting global allocator in this test binary), and the output equals the one-shot `segment`'s.
#![allow(unsafe_code)]

use rangeimage::{Camera, RangeImage};
use rangeseg::Config;
use rangeseg::pipeline::{Output, Segmenter};
use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

/// Allocations of at least this many bytes count as image-sized (a 256×256 grid of `bool`).
const LARGE: usize = 64 * 1024;

/// The system allocator, counting the large allocations (and reallocations) while `COUNTING` is set.
struct Counting;

static COUNTING: AtomicBool = AtomicBool::new(false);
static LARGE_ALLOCS: AtomicUsize = AtomicUsize::new(0);
static LARGEST: AtomicUsize = AtomicUsize::new(0);

impl Counting {
    fn note(size: usize) {
        if size >= LARGE && COUNTING.load(Ordering::Relaxed) {
            LARGE_ALLOCS.fetch_add(1, Ordering::Relaxed);
            LARGEST.fetch_max(size, Ordering::Relaxed);
        }
    }
}

// SAFETY: every call forwards to `System` with the caller's arguments; the counters are atomics.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        Self::note(layout.size());
        // SAFETY: forwarded unchanged.
        unsafe { System.alloc(layout) }
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        Self::note(layout.size());
        // SAFETY: forwarded unchanged.
        unsafe { System.alloc_zeroed(layout) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: forwarded unchanged.
        unsafe { System.dealloc(ptr, layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        Self::note(new_size);
        // SAFETY: forwarded unchanged.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

/// The counters are global (every thread's allocations count): each test holds this from its first line, so
/// no other test prepares its inputs while one measures.
static SERIAL: Mutex<()> = Mutex::new(());

/// Runs `f` in a one-thread rayon pool, so the counts do not depend on how the work is split among threads.
fn one_thread<T: Send>(f: impl FnOnce() -> T + Send) -> T {
    rayon::ThreadPoolBuilder::new().num_threads(1).build().expect("a one-thread pool").install(f)
}

/// `(large allocations, largest size)` while `f` runs on this thread.
fn count_large<T>(f: impl FnOnce() -> T) -> (T, usize, usize) {
    LARGE_ALLOCS.store(0, Ordering::SeqCst);
    LARGEST.store(0, Ordering::SeqCst);
    COUNTING.store(true, Ordering::SeqCst);
    let r = f();
    COUNTING.store(false, Ordering::SeqCst);
    (r, LARGE_ALLOCS.load(Ordering::SeqCst), LARGEST.load(Ordering::SeqCst))
}

/// Synthetic ABW-like 512×512 frames (the benchmark's training images, all different).
fn abw_frames(n: u32) -> Vec<RangeImage> {
    (0..n)
        .map(|i| {
            let (params, seed) = scenegen::benchmark_image(false, i);
            scenegen::generate(&params, seed).range.map(|&v| if v == 0 { f32::NAN } else { f32::from(v) })
        })
        .collect()
}

/// The bits of every `f32` of a slice (NaN equals NaN of the same bits).
fn bits<const N: usize>(v: impl IntoIterator<Item = [f32; N]>) -> Vec<u32> {
    v.into_iter().flatten().map(f32::to_bits).collect()
}

/// The bits of a region list's fields.
fn region_bits(r: &[rangeimage::Region]) -> Vec<u32> {
    r.iter()
        .flat_map(|r| {
            let f =
                [r.mean_k, r.normal[0], r.normal[1], r.normal[2], r.offset, r.rms_residual].map(f32::to_bits);
            [r.label, r.size_px].into_iter().chain(f)
        })
        .collect()
}

/// The fields of two outputs that any consumer reads, compared bit for bit.
fn assert_same(a: &Output, b: &Output) {
    let scalar = |g: &rangeimage::Grid<f32>| bits(g.as_slice().iter().map(|&v| [v]));
    let (fa, fb) = (&a.features, &b.features);
    assert_eq!(bits(fa.plane.as_slice().iter().copied()), bits(fb.plane.as_slice().iter().copied()));
    for (x, y) in [(&fa.k, &fb.k), (&fa.h, &fb.h), (&fa.curvedness, &fb.curvedness), (&fa.k_std, &fb.k_std)] {
        assert_eq!(scalar(x), scalar(y));
    }
    assert_eq!((&a.regions.labels, &a.regions.c1), (&b.regions.labels, &b.regions.c1));
    assert_eq!(region_bits(&a.regions.regions), region_bits(&b.regions.regions));
    assert_eq!(a.canny.edges, b.canny.edges);
    assert_eq!(scalar(&a.canny.magnitude), scalar(&b.canny.magnitude));
    assert_eq!(a.fin.relaxed, b.fin.relaxed);
    assert_eq!(format!("{:?}", a.fin.relax_info), format!("{:?}", b.fin.relax_info));
    assert_eq!(a.fin.labels, b.fin.labels);
    assert_eq!(region_bits(&a.fin.final_regions), region_bits(&b.fin.final_regions));
    assert_eq!(a.fin.edges, b.fin.edges);
}

/// Runs `frames` through one segmenter (each frame twice, so a frame also follows itself) and checks that
/// frames after the first give what `segment` gives and allocate nothing image-sized.
/// The caller holds [`SERIAL`].
fn stream(frames: &[RangeImage], camera: &Camera, config: &Config) {
    one_thread(|| stream_here(frames, camera, config));
}

/// [`stream`] on the calling thread.
fn stream_here(frames: &[RangeImage], camera: &Camera, config: &Config) {
    let mut s = Segmenter::new(config.clone());
    s.segment(&frames[0], camera);
    for (i, f) in frames.iter().chain(frames).enumerate().skip(1) {
        let ((), n, largest) = count_large(|| {
            s.segment(f, camera);
        });
        let out = s.segment(f, camera);
        assert_same(out, &rangeseg::segment(f, camera, config));
        assert_eq!(n, 0, "frame {i}: {n} allocations of ≥ {LARGE} bytes, the largest {largest} bytes");
    }
}

#[test]
fn a_stream_of_abw_frames_allocates_nothing_image_sized_after_the_first() {
    let _g = SERIAL.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
    stream(&abw_frames(3), &Camera::ABW0, &Config::default());
}

#[test]
fn a_stream_of_staircase_frames_dequantised_too() {
    let _g = SERIAL.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
    let frames: Vec<RangeImage> = (0..2)
        .map(|i| {
            let (params, seed) = scenegen::family_image(scenegen::Family::Staircase, 1.33, false, i);
            scenegen::generate(&params, seed).range.map(|&v| if v == 0 { f32::NAN } else { f32::from(v) })
        })
        .collect();
    let mut noise = Vec::new();
    for f in &frames {
        assert!(rangeseg::dequantise::staircase(f, &mut noise, true).step.is_some(), "a staircase frame");
    }
    // After a frame that is not a staircase, too.
    let abw = abw_frames(1).remove(0);
    stream(&[abw, frames[0].clone(), frames[1].clone()], &Camera::ABW0, &Config::default());
}

#[test]
fn the_paper_configuration_too() {
    let _g = SERIAL.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
    let config = Config::load(&std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/paper.toml"))
        .expect("configs/paper.toml");
    stream(&abw_frames(2), &Camera::ABW0, &config);
}

/// The TUM Kinect frame of `data/real` and a second one, the same scene with a band of no data, with their camera.
fn kinect_frames() -> ([RangeImage; 2], Camera) {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("data/real/open3d-testdata/RGBD/other_formats/TUM_depth.png");
    let frame = rangeio::read(&path, &Default::default()).expect("read the TUM frame");
    let mut other = frame.range.clone();
    for y in 100..140 {
        for x in 0..other.width() {
            other[(x, y)] = f32::NAN;
        }
    }
    ([frame.range, other], frame.camera)
}

#[test]
fn a_stream_of_kinect_frames_too() {
    let _g = SERIAL.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
    let (frames, camera) = kinect_frames();
    stream(&frames, &camera, &Config::default());
}

#[test]
fn decimated_kinect_frames_too() {
    // Stages on 2 × 2 and 3 × 3 blocks (`configs/fast.toml`), the maps carried back to full size: still nothing
    // image-sized after the first frame.
    let _g = SERIAL.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
    let (frames, camera) = kinect_frames();
    for decimate in [2, 3] {
        let pipeline = rangeseg::PipelineParams { decimate, ..Default::default() };
        stream(&frames, &camera, &Config { pipeline, ..Default::default() });
    }
}

/// The stages before the final segmentation, each with its own buffers, as `Segmenter` chains them.
#[test]
fn the_stages_before_the_final_segmentation_allocate_nothing_image_sized_after_the_first_frame() {
    one_thread(stages_before_the_final_segmentation);
}

/// The body of the test above, on the calling thread.
fn stages_before_the_final_segmentation() {
    let _g = SERIAL.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("data/real/open3d-testdata/RGBD/other_formats/TUM_depth.png");
    let kinect = rangeio::read(&path, &Default::default()).expect("read the TUM frame");
    let abw = abw_frames(2);
    let config = Config::default();
    for (frames, camera) in [(abw, Camera::ABW0), (vec![kinect.range.clone(), kinect.range], kinect.camera)] {
        let mut features = Default::default();
        let (mut rg_scratch, mut regions) = (regiongrow::Scratch::default(), Default::default());
        let (mut vc_scratch, mut canny) = (vcanny::Scratch::default(), Default::default());
        let (mut rx_scratch, mut relaxed) = (relax::Scratch::default(), Default::default());
        let (mut valid, mut s1) = (rangeimage::Grid::default(), rangeimage::Grid::default());
        let mut run = |f: &RangeImage| {
            features::compute_into(f, &config.features, &mut features);
            let p = &config.regiongrow;
            regiongrow::grow_into(f, &features, &camera, p, config.seed, &mut rg_scratch, &mut regions);
            valid.map_from(f, |v| v.is_finite());
            vcanny::detect_planes_into(&features.plane, &valid, &config.vcanny, &mut vc_scratch, &mut canny);
            s1.map_from(&features.curvedness, |&c| if c.is_finite() { c } else { 0.0 });
            let input = relax::Input {
                c1: &regions.c1,
                s1: &s1,
                c2: &canny.edges,
                magnitude: &canny.magnitude,
                valid: &valid,
            };
            let _ = relax::relax_into(&input, &config.relax, config.seed, &mut rx_scratch, &mut relaxed);
        };
        run(&frames[0]);
        for (i, f) in frames.iter().chain(&frames).enumerate().skip(1) {
            let ((), n, largest) = count_large(|| run(f));
            assert_eq!(n, 0, "frame {i}: {n} allocations of ≥ {LARGE} bytes, the largest {largest} bytes");
        }
    }
}

#[test]
fn counting_sees_a_large_allocation() {
    let _g = SERIAL.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
    let (v, n, largest) = count_large(|| vec![1u8; LARGE]);
    assert_eq!((v.len(), n, largest), (LARGE, 1, LARGE));
}

//! The whole pipeline in memory: determinism across thread counts, sanity of the outputs.

use rangeseg::Config;

fn run_with_threads(threads: usize, index: u32) -> rangeseg::pipeline::Output {
    let scene = crate::small_scene(index);
    let range = crate::range_of(&scene);
    let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
    pool.install(|| rangeseg::segment(&range, &rangeimage::Camera::ABW0, &Config::default()))
}

#[test]
fn bit_identical_at_one_and_two_threads() {
    let a = run_with_threads(1, 3);
    let b = run_with_threads(2, 3);
    assert_eq!(a.fin.labels, b.fin.labels);
    assert_eq!(a.fin.relaxed.edges, b.fin.relaxed.edges);
    assert_eq!(a.fin.edges, b.fin.edges);
    assert_eq!(a.regions.labels, b.regions.labels);
    assert_eq!(a.canny.edges, b.canny.edges);
    assert_eq!(a.fin.relax_info.energy_after.to_bits(), b.fin.relax_info.energy_after.to_bits());
}

#[test]
fn per_thread_segmenters_give_the_results_of_segment() {
    use rayon::prelude::*;
    let config = Config::default();
    let ranges: Vec<_> = [1, 3, 1, 4].iter().map(|&i| crate::range_of(&crate::small_scene(i))).collect();
    let pool = rayon::ThreadPoolBuilder::new().num_threads(2).build().unwrap();
    let segs = rangeseg::pipeline::Segmenters::new(&config, 2);
    let labels: Vec<_> = pool.install(|| {
        ranges
            .par_iter()
            .map(|r| segs.with(|s| s.segment(r, &rangeimage::Camera::ABW0).fin.labels.clone()))
            .collect()
    });
    for (range, got) in ranges.iter().zip(&labels) {
        assert_eq!(got, &rangeseg::segment(range, &rangeimage::Camera::ABW0, &config).fin.labels);
    }
    // A nested call finds its thread's slot busy and runs on a fresh segmenter, with the same result.
    let nested =
        segs.with(|_| segs.with(|s| s.segment(&ranges[0], &rangeimage::Camera::ABW0).fin.labels.clone()));
    assert_eq!(nested, labels[0]);
}

#[test]
fn labels_are_zero_on_no_data_and_energy_does_not_increase() {
    let scene = crate::small_scene(5);
    let range = crate::range_of(&scene);
    let out = rangeseg::segment(&range, &rangeimage::Camera::ABW0, &Config::default());
    for (x, y, v) in range.enumerate() {
        if v.is_nan() {
            assert_eq!(out.fin.labels[(x, y)], 0, "label on no-data pixel ({x}, {y})");
        }
    }
    assert!(out.fin.relax_info.energy_after <= out.fin.relax_info.energy_before);
    assert!(!out.fin.final_regions.is_empty());
}

#[test]
fn final_edges_are_the_final_segmentation_borders_or_the_relaxed_sets() {
    let scene = crate::small_scene(5);
    let range = crate::range_of(&scene);
    let camera = rangeimage::Camera::ABW0;
    let mut no_gaps = Config::default();
    no_gaps.pipeline.edge_gap_px = 0;
    let out = rangeseg::segment(&range, &camera, &no_gaps);
    assert!(out.fin.edges().as_slice().iter().any(|&b| b), "the scene has several final regions");
    // Without the gap split, C holds exactly the region pixels with a 4-neighbour in another region, and the
    // unlabelled pixels between two regions.
    let labels = &out.fin.labels;
    let neighbours = |x: u32, y: u32| {
        [(1i64, 0i64), (-1, 0), (0, 1), (0, -1)]
            .iter()
            .filter_map(move |&(dx, dy)| labels.get_signed(i64::from(x) + dx, i64::from(y) + dy).copied())
    };
    for (x, y, &l) in labels.enumerate() {
        let nb: Vec<u32> = neighbours(x, y).filter(|&m| m != 0).collect();
        let want = if l != 0 { nb.iter().any(|&m| m != l) } else { nb.iter().any(|&m| m != nb[0]) };
        assert_eq!(out.fin.edges()[(x, y)], want, "pixel ({x}, {y}), label {l}, neighbours {nb:?}");
    }
    // With it (the default), the same labels, and C only gains pixels, each in or beside an unlabelled gap.
    let split = rangeseg::segment(&range, &camera, &Config::default());
    assert_eq!(&split.fin.labels, labels, "the gap split changes the edge map only");
    let mut gained = 0;
    for (x, y, &e) in split.fin.edges().enumerate() {
        let before = out.fin.edges()[(x, y)];
        assert!(e || !before, "pixel ({x}, {y}) left C");
        if e && !before {
            gained += 1;
            let in_gap = labels[(x, y)] == 0 || neighbours(x, y).any(|m| m == 0);
            assert!(in_gap, "pixel ({x}, {y}) joined C away from any gap");
        }
    }
    assert!(gained > 0, "the final segmentation leaves gaps between regions here, and C closes them");
    let mut relaxed = Config::default();
    relaxed.pipeline.final_edges = rangeseg::FinalEdges::Relaxed;
    let out = rangeseg::pipeline::finish(&range, &camera, &relaxed, &out.features, &out.regions, &out.canny);
    assert_eq!(out.edges(), &out.relaxed.edges, "relaxed: C is C1 ∪ the supported relaxed C2");
}

/// One 3D plane seen by the ABW scanner, stored as the scanner stores it (8-bit steps), in a strip
/// `w × h` of the image: a 1000 × 3 or 3 × 1000 strip used to come out as several regions, cut at
/// the rows where the staircase made the clipped feature windows non-growable (issue 16).
fn abw_plane_strip(w: u32, h: u32) -> rangeimage::RangeImage {
    let cal = rangeimage::AbwCalibration::CAL0;
    let (n, z0) = ([0.05f64, 0.02, 1.0], (255.0 - 120.0) / cal.scal);
    let data = (0..h)
        .flat_map(|y| (0..w).map(move |x| (f64::from(x), f64::from(y))))
        .map(|(x, y)| {
            // The point of (x, y) is A + B·v (docs/method.md §2.1); solve n·(A + B·v) = n·(0, 0, z0).
            let f = cal.f.abs();
            let a = [(x - 255.0) * cal.offset / f, (255.0 - y) / cal.c * cal.offset / f, 255.0 / cal.scal];
            let b = [(x - 255.0) / cal.scal / f, (255.0 - y) / cal.c / cal.scal / f, -1.0 / cal.scal];
            let dot = |p: [f64; 3]| n[0] * p[0] + n[1] * p[1] + n[2] * p[2];
            ((n[2] * z0 - dot(a)) / dot(b)).round().clamp(0.0, 255.0) as f32
        })
        .collect();
    rangeimage::RangeImage::from_vec(w, h, data).unwrap()
}

#[test]
fn a_thin_strip_of_one_plane_is_one_region() {
    for (w, h) in [(1000, 3), (3, 1000), (512, 512)] {
        let range = abw_plane_strip(w, h);
        let out = rangeseg::segment(&range, &rangeimage::Camera::ABW0, &Config::default());
        assert_eq!(out.regions.regions.len(), 1, "{w}×{h}: regions grown");
        assert_eq!(out.fin.final_regions.len(), 1, "{w}×{h}: final regions");
        assert!(out.fin.labels.as_slice().iter().all(|&l| l == 1), "{w}×{h}: every pixel in the plane");
    }
}

/// The OpenNI frame of boxes on a floor (`data/real`, millimetres read as metres) and its camera.
fn boxes_frame() -> rangeio::Frame {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("data/real/pcl-test/grabber_sequences/tiff/frame_20121214T142255.814212_depth.tiff");
    rangeio::read(&path, &Default::default()).expect("read the OpenNI frame")
}

#[test]
fn a_kinect_frame_in_metres_is_segmented_into_its_planes() {
    // Run in its own units (metres, noise σ ≈ 1 mm), every distance parameter of a few units let the
    // floor, the boxes and the laptop merge: 4 regions, the largest (the floor and more) with an RMS of
    // 22 mm. In working units (src/units.rs) the floor is one plane of 2–3 mm RMS and the box faces are
    // regions of their own.
    let frame = boxes_frame();
    let out = rangeseg::segment(&frame.range, &frame.camera, &Config::default());
    let units = out.units.expect("units of the frame");
    assert!(units.factor > 100.0, "metres are scaled up: {units:?}");
    let planes = rangeseg::planes(&frame.range, &out.fin.labels, &frame.camera);
    let floor = planes.iter().max_by_key(|p| p.pixels).expect("planes");
    assert!(floor.rms < 0.005, "the largest region is one plane: RMS {} m", floor.rms);
    let big = planes.iter().filter(|p| p.pixels >= 1000).count();
    assert!(big >= 8, "{big} planes of ≥ 1000 pixels");

    let off = Config {
        pipeline: rangeseg::PipelineParams { normalize_units: false, ..Default::default() },
        ..Default::default()
    };
    let raw = rangeseg::segment(&frame.range, &frame.camera, &off);
    let raw_planes = rangeseg::planes(&frame.range, &raw.fin.labels, &frame.camera);
    let raw_floor = raw_planes.iter().max_by_key(|p| p.pixels).expect("planes");
    assert!(
        raw_floor.rms > 0.01,
        "without working units the floor merges with the boxes: RMS {}",
        raw_floor.rms
    );
}

#[test]
fn the_result_does_not_depend_on_the_depth_unit() {
    // Metres and centimetres become the same working image, up to the rounding of the ×100.
    let frame = boxes_frame();
    let metres = rangeseg::segment(&frame.range, &frame.camera, &Config::default());
    let cm = frame.range.map(|&v| v * 100.0);
    let centimetres = rangeseg::segment(&cm, &frame.camera, &Config::default());
    let (a, b) = (metres.fin.labels.as_slice(), centimetres.fin.labels.as_slice());
    let differ = a.iter().zip(b).filter(|(x, y)| x != y).count();
    assert!(differ * 1000 < a.len(), "{differ} of {} labels differ between metres and centimetres", a.len());
}

/// Asserts that the final segmentation `out` of `range` (seen through `camera`) has at least `count` regions of 5000 px
/// or more, each one plane: the RMS of its input points about their plane under `max_rms` (input units).
fn assert_planes_of_5000_px(
    range: &rangeimage::RangeImage,
    out: &rangeseg::pipeline::Output,
    camera: &rangeimage::Camera,
    count: usize,
    max_rms: f64,
) {
    let planes = rangeseg::planes(range, &out.fin.labels, camera);
    let big: Vec<_> = planes.iter().filter(|p| p.pixels >= 5000).collect();
    assert!(big.len() >= count, "{} planes of ≥ 5000 px: {planes:?}", big.len());
    for p in &big {
        assert!(p.rms < max_rms, "each one plane: RMS {} (at most {max_rms})", p.rms);
    }
}

/// A noise-free rendered room as a depth sensor without noise would store it: floor, back wall, two side walls
/// and a slanted panel, seen by a 640 × 480 pinhole camera, depth in metres rounded to whole millimetres.
fn noise_free_room() -> (rangeimage::RangeImage, rangeimage::Camera) {
    render_room(
        &[
            ([0.0, -1.0, 0.0], -1.2, None),
            ([0.0, 0.0, 1.0], 4.0, None),
            ([1.0, 0.0, 0.0], 1.8, None),
            ([-1.0, 0.0, 0.0], 1.6, None),
            ([0.3, 0.0, 1.0], 2.6, Some([200.0, 100.0, 420.0, 300.0])),
        ],
        true,
    )
}

/// A plane `n · p = d` (y down) of [`render_room`], limited to a pixel box `[x0, y0, x1, y1]` if it has one.
type RoomPlane = ([f64; 3], f64, Option<[f64; 4]>);

/// Planes `n · p = d` (y down), each limited to a pixel box if it has one, seen by a 640 × 480 pinhole camera
/// without noise: depth in metres, rounded to whole millimetres if `rounded` (else as a renderer writes it, in
/// floats).
fn render_room(planes: &[RoomPlane], rounded: bool) -> (rangeimage::RangeImage, rangeimage::Camera) {
    let (range, camera, _) = render_room_gt(planes, rounded);
    (range, camera)
}

/// [`render_room`] and its ground truth: at each pixel, 10 + the index of the plane seen there (0: none).
fn render_room_gt(
    planes: &[RoomPlane],
    rounded: bool,
) -> (rangeimage::RangeImage, rangeimage::Camera, rangeimage::LabelImage) {
    let (fx, cx, cy) = (525.0, 319.5, 239.5);
    let hit = |u: u32, v: u32| {
        let (u, v) = (f64::from(u), f64::from(v));
        let ray = [(u - cx) / fx, (v - cy) / fx, 1.0];
        let mut nearest = (f64::INFINITY, 0);
        for (k, (n, d, bounds)) in planes.iter().enumerate() {
            let t = d / (n[0] * ray[0] + n[1] * ray[1] + n[2] * ray[2]);
            let inside = bounds.is_none_or(|[x0, y0, x1, y1]| u > x0 && u < x1 && v > y0 && v < y1);
            if t > 0.3 && t < 8.0 && inside && t < nearest.0 {
                nearest = (t, 10 + k as u32);
            }
        }
        nearest
    };
    let range = rangeimage::Grid::from_fn(640, 480, |u, v| {
        let (z, _) = hit(u, v);
        match (z.is_finite(), rounded) {
            (false, _) => f32::NAN,
            (true, true) => ((z * 1000.0).round() / 1000.0) as f32,
            (true, false) => z as f32,
        }
    });
    let gt = rangeimage::Grid::from_fn(640, 480, |u, v| hit(u, v).1);
    (range, rangeimage::Camera::Pinhole { fx, fy: fx, cx, cy, depth_scale: 1.0 }, gt)
}

#[test]
fn noise_free_quantised_depth_is_segmented_into_its_planes() {
    // Most 5 × 5 windows of 1-mm-rounded noise-free depth hold one value, so the noise estimate reads ~1e-11 m.
    // Scaled by it, every 1 mm step became a jump of thousands of units and region growing grew one region (3
    // final regions). The working units take at least the rounding's own σ, 1 mm / √12.
    let (range, camera) = noise_free_room();
    let out = rangeseg::segment(&range, &camera, &Config::default());
    let units = out.units.expect("units of the frame");
    let rounding = 0.001 / 12f64.sqrt();
    assert!(units.factor <= 1.01 * rangeseg::units::PINHOLE_SIGMA / rounding, "{units:?}");
    assert_planes_of_5000_px(&range, &out, &camera, 5, 0.002);
}

#[test]
fn noise_free_float_depth_is_segmented_into_its_planes() {
    // A renderer's depth in metres, of a hall whose back wall and a box's front face the camera: most 5 × 5 windows
    // hold one depth, so σ read 0, the frame ran in metres, and region growing's 3-unit limits grew the hall into one
    // region. The pixel pitch gives σ a floor.
    let (range, camera) = hall();
    let out = rangeseg::segment(&range, &camera, &Config::default());
    let units = out.units.expect("units of the frame");
    let (_, pitch) = planefit::noise::step_geometry(&range, &camera, 0.0).expect("a pitch");
    let expected = rangeseg::units::PINHOLE_SIGMA / (rangeseg::units::PINHOLE_PITCH_SHARE * pitch);
    assert!((units.factor / expected - 1.0).abs() < 1e-9, "{units:?}, expected a factor of {expected}");
    assert_planes_of_5000_px(&range, &out, &camera, 5, 0.001);
}

/// The hall of `noise_free_float_depth_is_segmented_into_its_planes`: a floor, a back wall and a side wall facing the
/// camera or not, a box's front face and a slanted panel.
fn hall() -> (rangeimage::RangeImage, rangeimage::Camera) {
    let (range, camera, _) = hall_gt();
    (range, camera)
}

/// [`hall`] and its ground truth (each plane is one connected region).
pub(crate) fn hall_gt() -> (rangeimage::RangeImage, rangeimage::Camera, rangeimage::LabelImage) {
    render_room_gt(
        &[
            ([0.0, -1.0, 0.0], -1.0, None),
            ([0.0, 0.0, 1.0], 3.0, None),
            ([1.0, 0.0, 0.0], -1.5, None),
            ([0.0, 0.0, 1.0], 2.0, Some([350.0, 150.0, 500.0, 380.0])),
            ([0.3, 0.0, 1.0], 2.6, Some([120.0, 100.0, 300.0, 300.0])),
        ],
        false,
    )
}

#[test]
fn noisy_depth_is_stretched_across_and_its_normals_tilted_back() {
    // The hall with depth noise growing with the square of depth, 2 mm at 1 m (a Kinect has about 1.4): σ reads 3.1
    // pixel pitches, so the 5 × 5 windows' normals were mostly noise and 2 of its 5 planes were found. Stretched
    // across to 2 pitches (1.55 times), 5 (2.5 mm at 1 m: 0 → 4 of 5; 1.4 mm: 4 → 5); their normals are the planes'
    // own in the input's geometry.
    let (clean, camera, gt) = hall_gt();
    let mut state = 0x2545_f491_4f6c_dd1d_u64;
    let mut uniform = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    let range = clean.map(|&z| {
        // A normal deviate from twelve uniform ones.
        let g = (0..12).map(|_| uniform()).sum::<f64>() - 6.0;
        let z = f64::from(z);
        (z + 0.002 * z * z * g) as f32
    });
    let out = rangeseg::segment(&range, &camera, &Config::default());
    let units = out.units.expect("units of the frame");
    assert!(units.stretch > 1.4, "{units:?}");
    let h = rangeseg::evaluate::hoover(&gt, &out.fin.labels, &out.fin.final_regions, &[]);
    assert_eq!((h.correct, h.gt_regions), (5, 5), "{h:?}");
    // The back wall (z = 3 m, the largest region) faces the camera: its normal points back along the view axis.
    let wall = out.fin.final_regions.iter().max_by_key(|r| r.size_px).expect("regions");
    assert!(wall.normal[2] < -0.995, "the back wall's normal {:?}", wall.normal);
    let floor = out.fin.final_regions.iter().find(|r| r.normal[1] < -0.9);
    assert!(floor.is_some(), "a region whose normal points up (the floor): {:?}", out.fin.final_regions);
    // The panel (0.3 x + z = 2.6) is slanted: the stretch tilts its working normal by about 6°, which is tilted back.
    let len = 1.09f64.sqrt();
    let panel = [-0.3 / len, 0.0, -1.0 / len];
    let closest = out
        .fin
        .final_regions
        .iter()
        .map(|r| (0..3).map(|k| f64::from(r.normal[k]) * panel[k]).sum::<f64>())
        .fold(-1.0, f64::max);
    assert!(closest > 2f64.to_radians().cos(), "no region's normal within 2° of the panel's: cos {closest}");
}

#[test]
fn noise_free_float_disparity_is_segmented_into_its_planes() {
    // The hall as a renderer's float disparity (525 px × 10 cm / depth) on the grid camera: its slopes are
    // 0.01–0.2 px a pixel, so every plane's normal lay within 11° of the others'. σ = 0 left it as it was and region
    // growing grew it into one region (2 final regions of ≥ 5000 px). Scaled until its steep slopes are
    // `GRID_STEEP_SLOPE` a pixel, the normals spread.
    let (depth, _) = hall();
    let range = depth.map(|&z| 52.5 / z);
    let out = rangeseg::segment(&range, &rangeimage::Camera::Grid, &Config::default());
    assert!(out.units.is_some_and(|u| u.factor > 10.0), "{:?}", out.units);
    assert_planes_of_5000_px(&range, &out, &rangeimage::Camera::Grid, 5, 0.01);
}

#[test]
fn rendered_disparity_is_segmented_into_its_planes() {
    // Stereo ground truth: noise-free disparity in steps of 2, where planes stay planes on the grid camera.
    // Dequantised, its windows fit planes to ~1e-6, and the working units scaled that σ to the grid band's 0.25:
    // 25 to 60,000 times, and 2 of these 61 GT regions were found. Since the dequantised σ has a floor (a share of
    // the rounding error), 59.
    let (mut correct, mut total) = (0, 0);
    let floor = rangeseg::dequantise::SIGMA_FLOOR_SHARE * 2.0 / 12f64.sqrt();
    for index in 0..4 {
        let (params, seed) = scenegen::family_image(scenegen::Family::Disparity, 2.0, false, index);
        let scene = scenegen::generate(&params, seed);
        let range = crate::range_of(&scene);
        let out = rangeseg::segment(&range, &rangeimage::Camera::Grid, &Config::default());
        assert_eq!(out.dequantised, Some(2.0), "training image {index}");
        let factor = out.units.map_or(1.0, |u| u.factor);
        assert!(
            factor <= 1.0001 * rangeseg::units::GRID_SIGMA_BAND.0 / floor,
            "image {index}: scaled {factor} times"
        );
        let h =
            rangeseg::evaluate::hoover(&scene.labels, &out.fin.labels, &out.fin.final_regions, &scene.angles);
        correct += h.correct;
        total += h.gt_regions;
    }
    assert!(f64::from(correct) >= 0.85 * f64::from(total), "{correct} of {total} GT regions correct");
}

#[test]
fn dequantised_depth_makes_no_small_faces() {
    // Rendered disparity in steps of 2 runs dequantised; the dequantiser's ramps along the steps are left unlabelled,
    // and six of them on this image passed the small-face tests (groups of 75–86 px inside one GT face, which
    // `compare` then counted as an over-segmentation of it) until the pipeline turned the step off on such frames.
    let (params, seed) = scenegen::family_image(scenegen::Family::Disparity, 2.0, true, 1);
    let range = crate::range_of(&scenegen::generate(&params, seed));
    let camera = rangeimage::Camera::Grid;
    let out = rangeseg::segment(&range, &camera, &Config::default());
    assert_eq!(out.dequantised, Some(2.0));
    let mut off = Config::default();
    off.segment.small_face_min_px = 0;
    let without = rangeseg::segment(&range, &camera, &off);
    assert_eq!(out.fin.labels, without.fin.labels);
}

/// The pixels whose label in `b` is not the one that `a`'s label there mostly became in `b` (labels compared up to
/// their numbers).
fn relabelled(a: &rangeimage::LabelImage, b: &rangeimage::LabelImage) -> usize {
    let mut overlap = std::collections::BTreeMap::new();
    for (&x, &y) in a.as_slice().iter().zip(b.as_slice()) {
        *overlap.entry((x, y)).or_insert(0usize) += 1;
    }
    // Per label of `a`: the label of `b` it overlaps most (the smallest of equals, as the map is ordered).
    let mut became = std::collections::BTreeMap::new();
    for (&(x, y), &n) in &overlap {
        let e = became.entry(x).or_insert((0, y));
        if n > e.0 {
            *e = (n, y);
        }
    }
    a.as_slice().iter().zip(b.as_slice()).filter(|&(x, y)| became[x].1 != *y).count()
}

/// The default configuration with `pipeline.decimate = f`.
fn decimated(f: u32) -> Config {
    Config { pipeline: rangeseg::PipelineParams { decimate: f, ..Default::default() }, ..Default::default() }
}

#[test]
fn a_decimated_frame_comes_back_at_full_size_with_its_planes() {
    // The hall, run on 2 × 2 and 3 × 3 blocks: every map has the frame's size, the five planes are correct at full
    // resolution, and no more than 1 % of the hall's pixels are labelled otherwise than at full resolution.
    let (range, camera, gt) = hall_gt();
    let full = rangeseg::segment(&range, &camera, &Config::default());
    for f in [2, 3] {
        let out = rangeseg::segment(&range, &camera, &decimated(f));
        assert_eq!(out.decimation, f);
        let maps = [out.fin.edges.dimensions(), out.regions.c1.dimensions(), out.canny.edges.dimensions()];
        let sizes = [out.fin.labels.dimensions(), out.regions.labels.dimensions()].into_iter().chain(maps);
        assert!(sizes.into_iter().all(|d| d == range.dimensions()), "f {f}: every map at the frame's size");
        assert_eq!(out.features.k.dimensions(), (640 / f, 480 / f), "the features stay decimated");
        let h = rangeseg::evaluate::hoover(&gt, &out.fin.labels, &out.fin.final_regions, &[]);
        assert_eq!((h.correct, h.gt_regions), (5, 5), "f {f}: {h:?}");
        assert_planes_of_5000_px(&range, &out, &camera, 5, 0.001);
        // Compared up to their numbers, the labels are those of full resolution but at a few pixels.
        let differ = relabelled(&full.fin.labels, &out.fin.labels);
        assert!(differ * 100 < range.len(), "f {f}: {differ} pixels labelled otherwise");
        // The sizes are counted at full resolution; the labels are numbered in raster order of their first pixels.
        for r in &out.fin.final_regions {
            let n = out.fin.labels.as_slice().iter().filter(|&&l| l == r.label).count();
            assert_eq!(n, r.size_px as usize);
        }
        let mut firsts = Vec::new();
        for &l in out.fin.labels.as_slice().iter().filter(|&&l| l != 0) {
            if !firsts.contains(&l) {
                firsts.push(l);
            }
        }
        assert!(firsts.iter().enumerate().all(|(k, &l)| l == k as u32 + 1), "{firsts:?}");
    }
}

#[test]
fn frames_of_odd_sizes_come_back_whole() {
    // The hall cropped to 637 × 479: the last column and row join no 2 × 2 block and take the nearest block's
    // labels where its plane explains them.
    let (range, camera, gt) = hall_gt();
    let crop = |g: &rangeimage::LabelImage| rangeimage::Grid::from_fn(637, 479, |x, y| g[(x, y)]);
    let range = rangeimage::Grid::from_fn(637, 479, |x, y| range[(x, y)]);
    let out = rangeseg::segment(&range, &camera, &decimated(2));
    assert_eq!(
        (out.decimation, out.fin.labels.dimensions(), out.fin.edges.dimensions()),
        (2, (637, 479), (637, 479))
    );
    let h = rangeseg::evaluate::hoover(&crop(&gt), &out.fin.labels, &out.fin.final_regions, &[]);
    assert_eq!((h.correct, h.gt_regions), (5, 5), "{h:?}");
    let last_column_labelled = (0..479).filter(|&y| out.fin.labels[(636, y)] != 0).count();
    assert!(last_column_labelled > 400, "{last_column_labelled} of 479 pixels of the last column labelled");
}

#[test]
fn frames_without_a_pinhole_camera_run_at_full_resolution() {
    // An ABW image and a grid image have no decimated camera, and a pinhole frame of 30 × 30 pixels is under 16
    // blocks a side: the same output as without decimation.
    let abw = crate::range_of(&scenegen::generate(&scenegen::benchmark_image(false, 0).0, 1));
    let (depth, camera) = hall();
    let grid = depth.map(|&z| 52.5 / z);
    let small = rangeimage::Grid::from_fn(30, 30, |x, y| depth[(300 + x, 200 + y)]);
    let frames = [(&abw, rangeimage::Camera::ABW0), (&grid, rangeimage::Camera::Grid), (&small, camera)];
    for (range, camera) in frames {
        let a = rangeseg::segment(range, &camera, &Config::default());
        let b = rangeseg::segment(range, &camera, &decimated(2));
        assert_eq!((a.decimation, b.decimation), (1, 1));
        assert_eq!(a.fin.labels, b.fin.labels);
        assert_eq!(a.fin.edges, b.fin.edges);
    }
}

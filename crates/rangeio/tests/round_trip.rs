//! Every writer round-trips through its reader; label and dataset rules.

use rangeimage::{Camera, Grid, LabelImage, range_image};
use rangeio::abw::{self, AdjacentAngle, Dataset, Split};
use rangeio::{Format, ReadError, ReadOptions, png};
use std::path::{Path, PathBuf};

/// A fresh, empty scratch directory for one test.
fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("rangeio-test-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

#[test]
fn range_round_trip_odd_width() {
    let dir = scratch("range");
    let p = dir.join("abw.test.19.range");
    let r = range_image![f32::NAN, 1.4, 300.0; 0.2, 254.6, 17.0; 3.0, f32::NAN, 9.5];
    abw::write_range(&p, &r).unwrap();
    // 32-byte header + 3 rows padded to 4 bytes.
    assert_eq!(std::fs::metadata(&p).unwrap().len(), 32 + 12);
    let back = abw::read_range(&p).unwrap();
    let want = [f32::NAN, 1.0, 255.0, 1.0, 255.0, 17.0, 3.0, f32::NAN, 10.0];
    for (a, b) in back.as_slice().iter().zip(want) {
        assert!(a == &b || (a.is_nan() && b.is_nan()), "{a} vs {b}");
    }
    // Through the generic reader: calibration 1 chosen by name.
    let f = rangeio::read(&p, &ReadOptions::default()).unwrap();
    assert_eq!((f.format, f.camera), (Format::SunRaster, Camera::ABW1));
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn little_endian_sun_header_and_colour_map_are_accepted() {
    let img = Grid::from_fn(3, 2, |x, y| (10 + x + 3 * y) as u8);
    let be = abw::raster_to_bytes(&img);
    let mut le = Vec::new();
    for w in 0..8 {
        let v = u32::from_be_bytes(be[4 * w..4 * w + 4].try_into().unwrap());
        le.extend_from_slice(&v.to_le_bytes());
    }
    // maptype 1, maplength 6: six colour-map bytes before the pixels.
    le[24..28].copy_from_slice(&1u32.to_le_bytes());
    le[28..32].copy_from_slice(&6u32.to_le_bytes());
    le.extend_from_slice(&[9; 6]);
    le.extend_from_slice(&be[32..]);
    assert_eq!(abw::raster_from_bytes(&le, Path::new("le.ras")).unwrap(), img);
}

#[test]
fn sun_header_errors_name_the_problem() {
    let img = Grid::new(4, 4, 20u8);
    let good = abw::raster_to_bytes(&img);
    let p = Path::new("x.range");
    let with = |word: usize, v: u32| {
        let mut b = good.clone();
        b[4 * word..4 * word + 4].copy_from_slice(&v.to_be_bytes());
        b
    };
    let cases: Vec<(Vec<u8>, &str)> = vec![
        (good[..20].to_vec(), "x.range: truncated sun rasterfile header: expected 32 bytes, found 20"),
        (good[..40].to_vec(), "x.range: truncated sun rasterfile pixel data: expected 48 bytes, found 40"),
        (
            b"GIF89a-not-a-raster-file-at-all-".to_vec(),
            "x.range: not a sun rasterfile: bad magic number 47494638",
        ),
        (with(3, 24), "x.range: unsupported sun rasterfile depth 24 (only 8-bit rasters are read)"),
        (with(1, 0), "x.range: unsupported image size 0x4 (each side must be 1..=32768)"),
        (with(2, 100_000), "x.range: unsupported image size 4x100000"),
        (with(5, 2), "x.range: unsupported sun rasterfile type 2 (run-length encoded)"),
        (with(7, 1 << 30), "x.range: truncated sun rasterfile pixel data"),
    ];
    for (bytes, msg) in cases {
        let e = abw::raster_from_bytes(&bytes, p).unwrap_err().to_string();
        assert!(e.starts_with(msg), "{e}");
    }
    let e = abw::read_range(Path::new("/no/such/file.range")).unwrap_err();
    assert!(matches!(e, ReadError::Io { .. }) && e.to_string().starts_with("/no/such/file.range: "));
}

#[test]
fn labels_round_trip_unchanged_when_they_fit() {
    let dir = scratch("labels");
    let p = dir.join("a.ms-seg");
    let l: LabelImage = Grid::from_vec(3, 2, vec![0, 10, 11, 11, 12, 0]).unwrap();
    let pairs = abw::write_labels(&p, &l).unwrap();
    assert_eq!(pairs, vec![(10, 10), (11, 11), (12, 12)]);
    assert_eq!(abw::read_labels(&p, true).unwrap(), l);
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn labels_beyond_246_keep_the_largest() {
    let dir = scratch("labels-cap");
    let p = dir.join("b.ms-seg");
    // 300 regions: region k (1..=300) has k pixels, so regions 55..=300 are the 246 largest.
    let mut data = Vec::new();
    for k in (1..=300u32).rev() {
        data.extend(std::iter::repeat_n(k, k as usize));
    }
    data.resize(300 * 151, 0);
    let l = Grid::from_vec(300, 151, data).unwrap();
    let pairs = abw::write_labels(&p, &l).unwrap();
    assert_eq!(pairs.len(), 246);
    // Raster order of first appearance: 300 first → 10, 299 → 11, …, 55 → 255.
    assert_eq!(pairs[0], (300, 10));
    assert_eq!(pairs[245], (55, 255));
    let back = abw::read_labels(&p, true).unwrap();
    for (a, b) in l.as_slice().iter().zip(back.as_slice()) {
        let want = pairs.iter().find(|(old, _)| old == a).map_or(0, |&(_, new)| u32::from(new));
        assert_eq!(*b, want);
    }
    // Small labels (1..9) are renumbered too.
    let small: LabelImage = Grid::from_vec(2, 2, vec![1, 2, 2, 0]).unwrap();
    assert_eq!(abw::write_labels(&p, &small).unwrap(), vec![(1, 10), (2, 11)]);
    assert_eq!(abw::read_labels(&p, true).unwrap().as_slice(), &[10, 11, 11, 0]);
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn label_rules_are_checked() {
    let p = Path::new("g.gt-seg");
    let raw = |v: Vec<u8>| abw::raster_to_bytes(&Grid::from_vec(3, 2, v).unwrap());
    // 1..3 read as unlabelled.
    let ok = abw::labels_from_bytes(&raw(vec![0, 1, 3, 10, 11, 10]), p, true).unwrap();
    assert_eq!(ok.as_slice(), &[0, 0, 0, 10, 11, 10]);
    let e = abw::labels_from_bytes(&raw(vec![0, 10, 10, 10, 7, 10]), p, true).unwrap_err().to_string();
    assert_eq!(
        e,
        "g.gt-seg: illegal label 7 at pixel (x 1, y 1): labels 4..9 are reserved (0..3 unlabelled, regions from 10)"
    );
    let e = abw::labels_from_bytes(&raw(vec![10, 10, 13, 11, 0, 0]), p, true).unwrap_err().to_string();
    assert_eq!(e, "g.gt-seg: region labels are not consecutive from 10: 12 is missing but 13 is used");
    // Without the check the values are kept.
    let l = abw::labels_from_bytes(&raw(vec![10, 10, 13, 11, 7, 0]), p, false).unwrap();
    assert_eq!(l.as_slice(), &[10, 10, 13, 11, 7, 0]);
}

#[test]
fn angles_and_normals_round_trip_and_report_lines() {
    let dir = scratch("text");
    let a = dir.join("x.gt-ang");
    let angles = vec![
        AdjacentAngle { a: 10, b: 11, angle_deg: 90.0 },
        AdjacentAngle { a: 11, b: 14, angle_deg: 33.25 },
    ];
    abw::write_angles(&a, &angles).unwrap();
    assert_eq!(abw::read_angles(&a).unwrap(), angles);
    let n = dir.join("x.ms-nor");
    let normals = vec![(10, [0.0, 0.6, -0.8]), (12, [1.0, 0.0, 0.0])];
    abw::write_normals(&n, &normals).unwrap();
    assert_eq!(abw::read_normals(&n).unwrap(), normals);
    std::fs::write(&a, "2\n10 11 90\n11 x 3\n").unwrap();
    let e = abw::read_angles(&a).unwrap_err().to_string();
    assert_eq!(e, format!("{}: line 3: expected a label, found `x`", a.display()));
    let e = abw::angles_from_str("3\n10 11 90\n", Path::new("y.gt-ang")).unwrap_err().to_string();
    assert_eq!(e, "y.gt-ang: line 2: header says 3 entries but the file has 1");
    let e = abw::normals_from_str("1\n10 0 1\n", Path::new("y.ms-nor")).unwrap_err().to_string();
    assert_eq!(e, "y.ms-nor: line 2: expected 4 fields, found 3");
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn dataset_discovery() {
    let dir = scratch("dataset");
    let r = Grid::new(4, 4, 50.0f32);
    for name in ["abw.test.19", "abw.test.2", "abw.train.10", "abw.train.3"] {
        abw::write_range(&dir.join(format!("{name}.range")), &r).unwrap();
    }
    std::fs::write(dir.join("abw.test.2.gt-seg"), b"x").unwrap();
    std::fs::write(dir.join("abw.test.2.gt-ang"), b"0\n").unwrap();
    std::fs::write(dir.join("abw.test.x.range"), b"x").unwrap();
    std::fs::write(dir.join("notes.txt"), b"x").unwrap();
    let ds = Dataset::discover(&dir).unwrap();
    let idx = |v: &[abw::AbwImage]| v.iter().map(|i| i.index).collect::<Vec<_>>();
    assert_eq!(idx(&ds.train), vec![3, 10]);
    assert_eq!(idx(&ds.test), vec![2, 19]);
    assert_eq!(ds.test[0].stem, "abw.test.2");
    assert_eq!(ds.test[0].split, Split::Test);
    assert_eq!(ds.test[0].gt_seg.as_deref(), Some(dir.join("abw.test.2.gt-seg").as_path()));
    assert!(ds.test[0].gt_ang.is_some() && ds.test[1].gt_seg.is_none());
    assert_eq!(
        (ds.test[0].camera, ds.test[1].camera, ds.train[0].camera),
        (Camera::ABW0, Camera::ABW1, Camera::ABW0)
    );
    let empty = scratch("dataset-empty");
    let e = Dataset::discover(&empty).unwrap_err();
    assert!(matches!(e, ReadError::NoAbwFiles { .. }), "{e}");
    assert!(matches!(Dataset::discover(&dir.join("missing")).unwrap_err(), ReadError::Io { .. }));
    std::fs::remove_dir_all(dir).unwrap();
    std::fs::remove_dir_all(empty).unwrap();
}

#[test]
fn png_writers_round_trip() {
    let dir = scratch("png");
    let r = range_image![1.0, 2.0, f32::NAN; 3.0, 3.0, 1.5];
    let p = dir.join("depth.png");
    png::write_depth_png(&p, &r).unwrap();
    let f = rangeio::read(&p, &ReadOptions::default()).unwrap();
    assert_eq!((f.format, f.bits_per_sample, f.camera), (Format::Png, 8, Camera::Grid));
    let back: Vec<f32> = f.range.as_slice().to_vec();
    assert_eq!(back[0], 255.0); // nearest
    assert_eq!(back[3], 1.0); // farthest
    assert!(back[2].is_nan()); // no data = 0
    assert_eq!(back[1], 128.0);

    let e = Grid::from_fn(5, 4, |x, y| (x + y) % 3 == 0);
    let pe = dir.join("edges.png");
    png::write_edge_png(&pe, &e).unwrap();
    assert_eq!(png::read_edge_png(&pe).unwrap(), e);

    let g = Grid::from_fn(7, 3, |x, y| (x * 30 + y) as u8);
    let pg = dir.join("gray.png");
    png::write_gray_png(&pg, &g).unwrap();
    let f = rangeio::read(&pg, &ReadOptions::default()).unwrap();
    assert_eq!(f.range.as_slice()[1], 30.0);

    let labels: LabelImage = Grid::from_fn(6, 6, |x, y| if x == 0 { 0 } else { x + 6 * y });
    let pl = dir.join("labels.png");
    png::write_label_png(&pl, &labels).unwrap();
    let decoded = image::open(&pl).unwrap().into_rgb8();
    let mut colours = std::collections::BTreeSet::new();
    for (x, y, px) in decoded.enumerate_pixels() {
        assert_eq!(px.0, png::label_color(labels[(x, y)]));
        if labels[(x, y)] != 0 {
            assert_ne!(px.0, [0, 0, 0]);
            colours.insert(px.0);
        }
    }
    assert_eq!(colours.len(), 30, "every label its own colour");

    let rgb = Grid::from_fn(2, 2, |x, y| [x as u8, y as u8, 200]);
    let pr = dir.join("rgb.png");
    png::write_rgb_png(&pr, &rgb).unwrap();
    assert_eq!(image::open(&pr).unwrap().into_rgb8().get_pixel(1, 0).0, [1, 0, 200]);

    let g16 = Grid::from_fn(3, 3, |x, y| (x * 5000 + y * 7) as u16);
    let p16 = dir.join("d16.png");
    png::write_gray16_png(&p16, &g16).unwrap();
    let f = rangeio::read(&p16, &ReadOptions::default()).unwrap();
    approx::assert_relative_eq!(f.range[(2, 1)], (10007.0 / 5000.0) as f32);

    let err = png::write_gray_png(&dir.join("empty.png"), &Grid::new(0, 0, 0u8)).unwrap_err();
    assert!(err.to_string().ends_with("cannot write an empty image as png"), "{err}");
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn label_colours_are_distinct_for_many_labels() {
    let colours: std::collections::BTreeSet<_> = (1..100_000).map(png::label_color).collect();
    assert_eq!(colours.len(), 99_999);
    assert!(!colours.contains(&[0, 0, 0]));
}

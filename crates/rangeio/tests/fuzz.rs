//! Property tests: no reader panics on random or mutated bytes, and writers round-trip.

use proptest::prelude::*;
use rangeimage::Grid;
use rangeio::{Format, ReadOptions, abw, lzf, pcd, pgm};
use std::io::Cursor;
use std::path::Path;

/// Small valid files of every format the generic reader knows.
fn seeds() -> Vec<(Vec<u8>, &'static str)> {
    let raw = Grid::from_fn(5, 3, |x, y| (10 + x * 7 + y) as u8);
    let s16 = Grid::from_fn(4, 3, |x, y| (x * 1000 + y * 3 + 1) as u16);
    let z = Grid::from_fn(4, 3, |x, y| 1.0 + 0.1 * x as f32 + 0.01 * y as f32);
    let xs = Grid::from_fn(4, 3, |x, y| (x as f32 - 1.5) * z[(x, y)] / 500.0);
    let ys = Grid::from_fn(4, 3, |x, y| (y as f32 - 1.0) * z[(x, y)] / 500.0);
    let mut png16 = Vec::new();
    image::ImageBuffer::<image::Luma<u16>, _>::from_raw(4, 3, s16.as_slice().to_vec())
        .unwrap()
        .write_to(&mut Cursor::new(&mut png16), image::ImageFormat::Png)
        .unwrap();
    let mut tiff16 = Vec::new();
    image::ImageBuffer::<image::Luma<u16>, _>::from_raw(4, 3, s16.as_slice().to_vec())
        .unwrap()
        .write_to(&mut Cursor::new(&mut tiff16), image::ImageFormat::Tiff)
        .unwrap();
    vec![
        (abw::raster_to_bytes(&raw), "a.range"),
        (pgm::pgm_to_bytes(&s16), "a.pgm"),
        (b"P2 2 2 9\n1 2\n3 9\n".to_vec(), "b.pgm"),
        (png16, "a.png"),
        (tiff16, "a.tiff"),
        (pcd::pcd_to_bytes(&xs, &ys, &z, Format::PcdAscii), "a.pcd"),
        (pcd::pcd_to_bytes(&xs, &ys, &z, Format::PcdBinary), "b.pcd"),
        (pcd::pcd_to_bytes(&xs, &ys, &z, Format::PcdBinaryCompressed), "c.pcd"),
    ]
}

/// Runs every reader on `bytes`; any error must name the file.
fn read_all(bytes: &[u8], name: &str) {
    let path = Path::new(name);
    let check = |msg: String| assert!(msg.starts_with(&format!("{name}: ")), "{msg}");
    for opts in [
        ReadOptions::default(),
        ReadOptions { pgm_little_endian: true, nyu_disparity_to_depth: true, ..Default::default() },
    ] {
        if let Err(e) = rangeio::read_bytes(bytes, path, &opts) {
            check(e.to_string());
        }
    }
    if let Err(e) = abw::raster_from_bytes(bytes, path) {
        check(e.to_string());
    }
    if let Err(e) = abw::labels_from_bytes(bytes, path, true) {
        check(e.to_string());
    }
    if let Err(e) = pgm::pgm_from_bytes(bytes, path, false) {
        check(e.to_string());
    }
    if let Err(e) = pcd::pcd_from_bytes(bytes, path) {
        check(e.to_string());
    }
    if let Err(e) = rangeio::png::edge_png_from_bytes(bytes, path) {
        check(e.to_string());
    }
    let text = String::from_utf8_lossy(bytes);
    if let Err(e) = abw::angles_from_str(&text, path) {
        check(e.to_string());
    }
    if let Err(e) = abw::normals_from_str(&text, path) {
        check(e.to_string());
    }
    let _ = lzf::decompress(bytes, bytes.len() * 3);
}

proptest! {
    // Seeded and bounded: the same cases on every run, a few seconds in all.
    #![proptest_config(ProptestConfig {
        cases: 256,
        rng_seed: proptest::test_runner::RngSeed::Fixed(16),
        failure_persistence: None,
        ..ProptestConfig::default()
    })]

    #[test]
    fn random_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..300), k in 0usize..8) {
        let (_, name) = seeds()[k];
        read_all(&bytes, name);
    }

    #[test]
    fn random_bytes_after_a_magic_never_panic(k in 0usize..8, tail in proptest::collection::vec(any::<u8>(), 0..200)) {
        let (seed, name) = &seeds()[k];
        let mut bytes = seed[..seed.len().min(8)].to_vec();
        bytes.extend(tail);
        read_all(&bytes, name);
    }

    #[test]
    fn mutated_files_never_panic(
        k in 0usize..8,
        edits in proptest::collection::vec((any::<proptest::sample::Index>(), any::<u8>()), 1..6),
        cut in any::<proptest::sample::Index>(),
        truncate in any::<bool>(),
    ) {
        let (seed, name) = &seeds()[k];
        let mut bytes = seed.clone();
        for (i, v) in edits {
            let i = i.index(bytes.len());
            bytes[i] = v;
        }
        if truncate {
            bytes.truncate(cut.index(bytes.len() + 1));
        }
        read_all(&bytes, name);
    }

    /// Header words and PGM/PCD sizes set to absurd values (20000 and 30000 per side, the largest
    /// values): no panic, and every error names the file.
    #[test]
    fn absurd_header_sizes_are_refused(k in 0usize..8, at in 0usize..64, v in prop_oneof![
        Just(u32::MAX), Just(20000u32), Just(30000), Just(32768), Just(32769), Just(0), any::<u32>()
    ]) {
        let (seed, name) = &seeds()[k];
        let mut bytes = seed.clone();
        let at = at.min(bytes.len().saturating_sub(4));
        bytes[at..at + 4].copy_from_slice(&v.to_be_bytes());
        read_all(&bytes, name);
        let text = String::from_utf8_lossy(seed).replace(" 4 3 ", &format!(" {v} {v} ")).replace("WIDTH 4", &format!("WIDTH {v}"));
        read_all(text.as_bytes(), name);
    }

    #[test]
    fn mutated_headers_never_panic(k in 0usize..8, at in 0usize..64, v in any::<u32>()) {
        let (seed, name) = &seeds()[k];
        let mut bytes = seed.clone();
        let at = at.min(bytes.len().saturating_sub(4));
        bytes[at..at + 4].copy_from_slice(&v.to_be_bytes());
        read_all(&bytes, name);
    }

    #[test]
    fn lzf_random_streams_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..200), n in 0usize..2000) {
        if let Ok(out) = lzf::decompress(&bytes, n) {
            prop_assert_eq!(out.len(), n);
        }
    }

    #[test]
    fn range_round_trips(img in rangeimage::testing::arbitrary_range_image(1..20, 1..20)) {
        let bytes = abw::raster_to_bytes(&abw::range_to_raw(&img));
        let back = abw::raw_to_range(&abw::raster_from_bytes(&bytes, Path::new("p.range")).unwrap());
        for (a, b) in img.as_slice().iter().zip(back.as_slice()) {
            if a.is_nan() {
                prop_assert!(b.is_nan());
            } else {
                prop_assert_eq!(*b, a.round().clamp(1.0, 255.0));
            }
        }
    }

    #[test]
    fn labels_round_trip(l in rangeimage::testing::arbitrary_label_image(1..30, 1..30, 400)) {
        let (raw, pairs) = abw::labels_to_raw(&l);
        let back = abw::labels_from_bytes(&abw::raster_to_bytes(&raw), Path::new("p.ms-seg"), false).unwrap();
        for (a, b) in l.as_slice().iter().zip(back.as_slice()) {
            let want = pairs.iter().find(|(old, _)| old == a).map_or(0, |&(_, new)| u32::from(new));
            prop_assert_eq!(*b, want);
        }
        prop_assert!(pairs.len() <= 246);
    }

    /// The 8-bit encoding, read a run of labels at a time, is the pixel-by-pixel one (`reference_labels_to_raw`):
    /// few labels (long runs), labels beyond 255 and beyond 246 regions, and labels above the pixel count.
    #[test]
    fn labels_to_raw_matches_the_pixel_by_pixel_encoding(
        (w, h, data) in (1..40u32, 1..30u32).prop_flat_map(|(w, h)| {
            (Just(w), Just(h), proptest::collection::vec(0..400u32, (w * h) as usize))
        }),
        (alphabet, offset, spread) in (prop_oneof![Just(3u32), Just(40), Just(400)], 0..12u32, prop_oneof![Just(1u32), Just(1_000_003)]),
    ) {
        // Labels from a small alphabet come in runs; `offset` moves them into or out of 10..=255.
        let labels = Grid::from_vec(w, h, data.iter().map(|&v| {
            let v = v % alphabet;
            if v == 0 { 0 } else { v * spread + offset }
        }).collect()).unwrap();
        let (raw, pairs) = abw::labels_to_raw(&labels);
        let (want_raw, want_pairs) = reference_labels_to_raw(&labels);
        prop_assert_eq!(pairs, want_pairs);
        prop_assert_eq!(raw.as_slice(), want_raw.as_slice());
    }

    /// `abw::for_each_run` visits maximal runs that tile the slice, in order.
    #[test]
    fn runs_tile_the_labels(v in proptest::collection::vec(0..4u32, 0..200)) {
        let (mut next, mut prev) = (0, None);
        abw::for_each_run(&v, |l, start, len| {
            assert_eq!(start, next, "runs in order, without gaps");
            assert!(len > 0 && v[start..start + len].iter().all(|&x| x == l), "a run of one label");
            assert_ne!(prev, Some(l), "maximal: the next run has another label");
            (next, prev) = (start + len, Some(l));
        });
        prop_assert_eq!(next, v.len());
    }
}

/// `abw::labels_to_raw` as first written, a pixel at a time: labels 0 or in 10..=255 unchanged; otherwise the 246
/// largest regions (ties: earlier first pixel) renumbered from 10 in raster order of their first pixel.
fn reference_labels_to_raw(labels: &rangeimage::LabelImage) -> (Grid<u8>, Vec<(u32, u8)>) {
    if labels.as_slice().iter().all(|&l| l == 0 || (10..=255).contains(&l)) {
        let mut seen = [false; 256];
        for &l in labels.as_slice() {
            seen[l as usize] = true;
        }
        let pairs = (10..256u32).filter(|&l| seen[l as usize]).map(|l| (l, l as u8)).collect();
        return (labels.map(|&l| l as u8), pairs);
    }
    let mut stats = std::collections::BTreeMap::<u32, (u64, usize)>::new();
    for (i, &l) in labels.as_slice().iter().enumerate() {
        if l != 0 {
            stats.entry(l).or_insert((0, i)).0 += 1;
        }
    }
    let mut by_size: Vec<(u32, u64, usize)> = stats.iter().map(|(&l, &(n, first))| (l, n, first)).collect();
    by_size.sort_by(|a, b| b.1.cmp(&a.1).then(a.2.cmp(&b.2)));
    by_size.truncate(246);
    by_size.sort_by_key(|&(_, _, first)| first);
    let pairs: Vec<(u32, u8)> =
        by_size.iter().enumerate().map(|(i, &(l, _, _))| (l, (10 + i) as u8)).collect();
    let raw = labels.map(|l| pairs.iter().find(|(old, _)| old == l).map_or(0, |&(_, new)| new));
    (raw, pairs)
}

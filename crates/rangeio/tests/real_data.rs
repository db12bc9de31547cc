//! Readers on the real sensor frames in `data/real/` (provenance in `data/real/README.md`).

use approx::assert_relative_eq;
use rangeimage::Camera;
use rangeio::{Format, ReadOptions, Units};
use std::path::PathBuf;

fn real(rel: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../data/real").join(rel)
}

const TUM: &str = "open3d-testdata/RGBD/other_formats/TUM_depth.png";
const NYU: &str = "open3d-testdata/RGBD/other_formats/NYU_depth.pgm";
const TIFF: &str = "pcl-test/grabber_sequences/tiff/frame_20121214T142255.814212_depth.tiff";
const PCD: &str = "pcl-test/grabber_sequences/pcd/frame_20121214T142255.814212.pcd";

#[test]
fn tum_png_is_metres_over_5000() {
    let f = rangeio::read(&real(TUM), &ReadOptions::default()).unwrap();
    assert_eq!(f.format, Format::Png);
    assert_eq!(f.range.dimensions(), (640, 480));
    assert_eq!(f.bits_per_sample, 16);
    assert_eq!(f.units, Units::Metres { metres_per_unit: 1.0 / 5000.0 });
    assert_relative_eq!(1.0 - f.valid_fraction(), 0.192, epsilon = 0.0005);
    let (lo, hi) = f.value_range().unwrap();
    assert_relative_eq!(lo, 1.46, epsilon = 0.005);
    assert_relative_eq!(hi, 9.33, epsilon = 0.005);
    assert_eq!(f.camera, Camera::Pinhole { fx: 525.0, fy: 525.0, cx: 319.5, cy: 239.5, depth_scale: 1.0 });
    // An explicit scale replaces the default.
    let mm =
        rangeio::read(&real(TUM), &ReadOptions { depth_scale: Some(1e-3), ..Default::default() }).unwrap();
    assert_relative_eq!(mm.value_range().unwrap().1, 9.33 * 5.0, epsilon = 0.03);
}

#[test]
fn nyu_pgm_raw_and_converted() {
    let raw_opts = ReadOptions { pgm_little_endian: true, ..Default::default() };
    let raw = rangeio::read(&real(NYU), &raw_opts).unwrap();
    assert_eq!((raw.format, raw.units, raw.bits_per_sample), (Format::Pgm, Units::Raw, 16));
    assert_eq!(raw.range.dimensions(), (640, 480));
    assert_eq!(raw.value_range(), Some((839.0, 2047.0)));
    assert_eq!(raw.camera, Camera::Grid);
    let invalid_raw =
        raw.range.as_slice().iter().filter(|&&v| v == 2047.0).count() as f64 / raw.range.len() as f64;
    assert_relative_eq!(invalid_raw, 0.072, epsilon = 0.0005);

    let opts = ReadOptions { pgm_little_endian: true, nyu_disparity_to_depth: true, ..Default::default() };
    let f = rangeio::read(&real(NYU), &opts).unwrap();
    assert_eq!(f.units, Units::NyuDisparity);
    assert_relative_eq!(1.0 - f.valid_fraction(), invalid_raw, epsilon = 1e-12);
    let (lo, hi) = f.value_range().unwrap();
    assert_relative_eq!(lo, 1.39, epsilon = 0.005);
    assert_relative_eq!(hi, 6.69, epsilon = 0.01);
    assert!(matches!(f.camera, Camera::Pinhole { .. }));
}

#[test]
fn nyu_read_big_endian_is_garbage_but_not_an_error() {
    // The standard byte order gives byte-swapped raw values; documented, not detected.
    let f = rangeio::read(&real(NYU), &ReadOptions::default()).unwrap();
    assert!(f.value_range().unwrap().1 > 2047.0);
}

#[test]
fn openni_tiff_is_millimetres() {
    let f = rangeio::read(&real(TIFF), &ReadOptions::default()).unwrap();
    assert_eq!((f.format, f.bits_per_sample), (Format::Tiff, 16));
    assert_eq!(f.range.dimensions(), (640, 480));
    assert_relative_eq!(1.0 - f.valid_fraction(), 0.116, epsilon = 0.0005);
    let (lo, hi) = f.value_range().unwrap();
    assert_relative_eq!(lo, 0.671, epsilon = 1e-6);
    assert_relative_eq!(hi, 1.713, epsilon = 1e-6);
}

#[test]
fn pcd_matches_the_tiff_of_the_same_frame() {
    let tiff = rangeio::read(&real(TIFF), &ReadOptions::default()).unwrap();
    let pcd = rangeio::read(&real(PCD), &ReadOptions::default()).unwrap();
    assert_eq!(pcd.format, Format::PcdBinaryCompressed);
    assert_eq!(pcd.range.dimensions(), (640, 480));
    let mut max_diff = 0f32;
    for (a, b) in pcd.range.as_slice().iter().zip(tiff.range.as_slice()) {
        assert_eq!(a.is_nan(), b.is_nan(), "invalid masks differ");
        if !a.is_nan() {
            max_diff = max_diff.max((a - b).abs());
        }
    }
    assert!(max_diff < 1e-3, "max |pcd − tiff| = {max_diff}");
    let Camera::Pinhole { fx, fy, cx, cy, depth_scale } = pcd.camera else { panic!("{:?}", pcd.camera) };
    assert_relative_eq!(fx, 525.0, epsilon = 1.0);
    assert_relative_eq!(fy, 525.0, epsilon = 1.0);
    assert_relative_eq!(cx, 320.0, epsilon = 1.0);
    assert_relative_eq!(cy, 240.0, epsilon = 1.0);
    assert_eq!(depth_scale, 1.0);
}

#[test]
fn truncated_real_files_are_clear_errors() {
    for rel in [TUM, NYU, TIFF, PCD] {
        let bytes = std::fs::read(real(rel)).unwrap();
        for cut in [10, bytes.len() / 2] {
            let e = rangeio::read_bytes(&bytes[..cut], &real(rel), &ReadOptions::default())
                .expect_err(&format!("{rel} cut at {cut} should fail"));
            let msg = e.to_string();
            assert!(msg.starts_with(&format!("{}: ", real(rel).display())), "{msg}");
            assert!(!msg.ends_with('.'), "{msg}");
        }
    }
}

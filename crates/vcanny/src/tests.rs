//! Unit tests of the vectorial Canny detector.

use super::*;
use crate::canny::{hysteresis, non_max_suppression, quantile};

const NAN: f32 = f32::NAN;

fn abs(low: f32, high: f32) -> Params {
    Params {
        thresholds: Thresholds { mode: ThresholdMode::Absolute, low, high, ..Thresholds::default() },
        ..Params::default()
    }
}

fn cols(e: &EdgeMap) -> Vec<u32> {
    let mut c: Vec<u32> = e.enumerate().filter(|(_, _, v)| **v).map(|(x, _, _)| x).collect();
    c.sort_unstable();
    c.dedup();
    c
}

#[test]
fn hand_worked_step_gives_one_column() {
    // Columns 0..=3 at 0, column 4 at 5 (the only maximum of the gradient), 5.. at 10.
    let img = Grid::from_fn(9, 7, |x, _| match x {
        0..=3 => 0.0,
        4 => 5.0,
        _ => 10.0,
    });
    let e = detect_raw(&img, &abs(0.5, 1.0));
    assert_eq!(cols(&e.edges), vec![4]);
    assert_eq!(e.edges.as_slice().iter().filter(|&&v| v).count(), 7, "the whole column");
    for y in 0..7 {
        let m = e.magnitude[(4, y)];
        assert!(m > e.magnitude[(3, y)] && m > e.magnitude[(5, y)]);
    }
    // Above the magnitude of the step nothing survives.
    assert!(detect_raw(&img, &abs(10.0, 10.0)).edges.as_slice().iter().all(|&v| !v));
}

#[test]
fn nms_interpolates_along_the_direction() {
    // 3×3 magnitudes, direction (0.6, 0.8) at the centre: dy dominates, t = 0.75, so the forward sample is
    // 0.25·m(1, 2) + 0.75·m(2, 2) and the backward one 0.25·m(1, 0) + 0.75·m(0, 0).
    let mag = vec![4.0, 0.0, 0.0, 0.0, 5.0, 0.0, 0.0, 0.0, 6.0];
    let mut dir = vec![[1.0f32, 0.0]; 9];
    dir[4] = [0.6, 0.8];
    let ok = vec![true; 9];
    // Forward = 4.5 < 5, backward = 3 < 5: kept.
    assert!(non_max_suppression(&mag, &dir, &ok, 3, 3)[4]);
    let mut mag2 = mag.clone();
    mag2[8] = 7.0; // forward = 5.25 > 5: suppressed.
    assert!(!non_max_suppression(&mag2, &dir, &ok, 3, 3)[4]);
    // A missing neighbour counts as 0.
    let mut ok2 = ok.clone();
    ok2[8] = false;
    assert!(non_max_suppression(&mag2, &dir, &ok2, 3, 3)[4]);
}

#[test]
fn hysteresis_follows_weak_pixels_8_connected() {
    // One row of candidates: 9 strong, then 3s (weak), a gap (1), then 3s not connected to any strong pixel;
    // a diagonal weak pixel below-right of the last connected one.
    #[rustfmt::skip]
    let mag = vec![
        9.0, 3.0, 3.0, 3.0, 1.0, 3.0, 3.0,
        0.0, 0.0, 0.0, 0.0, 3.0, 0.0, 0.0,
    ];
    let cand = vec![true; 14];
    let out = hysteresis(&mag, &cand, 7, 2, 2.0, 5.0);
    #[rustfmt::skip]
    let want = vec![
        true, true, true, true, false, true, true,
        false, false, false, false, true, false, false,
    ];
    // The diagonal (4,1) joins (3,0), and through it (5,0), (6,0).
    assert_eq!(out, want);
    // Without the strong pixel nothing survives.
    let mut m2 = mag.clone();
    m2[0] = 4.0;
    assert!(hysteresis(&m2, &cand, 7, 2, 2.0, 5.0).iter().all(|&v| !v));
}

/// A vertical step at column 10 whose height falls from 20 (top) to 8 (bottom) over 60 rows.
fn fading_step() -> RangeImage {
    Grid::from_fn(21, 60, |x, y| {
        let hgt = 20.0 - 12.0 * y as f32 / 59.0;
        match x {
            0..=9 => 0.0,
            10 => hgt / 2.0,
            _ => hgt,
        }
    })
}

fn transpose<T: Clone>(g: &Grid<T>) -> Grid<T> {
    Grid::from_fn(g.height(), g.width(), |x, y| g[(y, x)].clone())
}
fn flip_x<T: Clone>(g: &Grid<T>) -> Grid<T> {
    Grid::from_fn(g.width(), g.height(), |x, y| g[(g.width() - 1 - x, y)].clone())
}
fn flip_y<T: Clone>(g: &Grid<T>) -> Grid<T> {
    Grid::from_fn(g.width(), g.height(), |x, y| g[(x, g.height() - 1 - y)].clone())
}

#[test]
fn fading_step_keeps_its_whole_length_in_any_orientation() {
    let img = fading_step();
    let probe = detect_raw(&img, &abs(0.0, 0.0));
    let col: Vec<f32> = (0..60).map(|y| probe.magnitude[(10, y)]).collect();
    let min = col.iter().copied().fold(f32::INFINITY, f32::min);
    // Strong only in the top rows; weak (but far above the plateau slopes) everywhere along the step.
    let high = col[8];
    let low = 0.5 * min;
    assert!(col.iter().filter(|&&m| m >= high).count() < 15, "the test needs a mostly weak edge");
    let p = abs(low, high);
    let e = detect_raw(&img, &p).edges;
    assert_eq!(cols(&e), vec![10]);
    assert_eq!((0..60).filter(|&y| e[(10, y)]).count(), 60, "every row of the step is an edge");
    // The detector commutes with transposition and flips.
    assert_eq!(detect_raw(&transpose(&img), &p).edges, transpose(&e));
    assert_eq!(detect_raw(&flip_x(&img), &p).edges, flip_x(&e));
    assert_eq!(detect_raw(&flip_y(&img), &p).edges, flip_y(&e));
    assert_eq!(detect_raw(&flip_y(&transpose(&img)), &p).edges, flip_y(&transpose(&e)));
}

#[test]
fn no_data_never_makes_nan_or_edges_and_jumps_next_to_it_are_found() {
    // A step at column 8 (ramp pixel 7.5 → column 8), with no data in the top rows and a hole on the left.
    let img = Grid::from_fn(16, 16, |x, y| {
        if y < 4 || (x < 3 && (8..12).contains(&y)) {
            NAN
        } else {
            match x {
                0..=7 => 0.0,
                8 => 10.0,
                _ => 20.0,
            }
        }
    });
    let e = detect_raw(&img, &abs(1.0, 2.0));
    assert!(e.magnitude.as_slice().iter().all(|m| m.is_finite()));
    for (x, y, &v) in e.edges.enumerate() {
        if img[(x, y)].is_nan() {
            assert!(!v && e.magnitude[(x, y)] == 0.0);
        }
    }
    // The step is reported right up to the no-data rows, and the no-data borders themselves add nothing.
    assert_eq!(cols(&e.edges), vec![8]);
    assert!(e.edges[(8, 4)] && e.edges[(8, 15)]);
    assert!(e.magnitude[(3, 9)] < 1e-6, "a no-data neighbour adds no gradient");
}

#[test]
fn plane_channels_find_a_crease_the_depth_hides_and_ignore_quantisation() {
    // A roof z = 100 + 0.5·|x − 32| quantised to integers: depth is continuous at the crease,
    // slopes jump from −0.5 to 0.5.
    let roof = Grid::from_fn(64, 48, |x, y| (100.0 + 0.5 * (x as f32 - 32.0).abs() + 0.3 * y as f32).round());
    let planes = features::fit_planes(&roof, 5);
    let valid = roof.map(|v| v.is_finite());
    let e = detect_planes(&planes, &valid, &Params::default());
    let c = cols(&e.edges);
    assert!(!c.is_empty() && c.iter().all(|&x| (30..=34).contains(&x)), "edge columns {c:?}");
    assert!((4..44).all(|y| (30..=34).any(|x| e.edges[(x, y)])), "the crease is continuous");
    // The quantisation staircases of the two faces fire nowhere (checked above: only crease columns), and on a
    // quantised slanted plane alone, thresholds a little above the noise level find nothing.
    let slope = Grid::from_fn(64, 48, |x, y| (60.0 + 0.37 * x as f32 + 0.23 * y as f32).round());
    let mut p = Params::default();
    p.thresholds.low = 6.0;
    p.thresholds.high = 12.0;
    let e = detect_planes(&features::fit_planes(&slope, 5), &valid, &p);
    assert_eq!(e.edges.as_slice().iter().filter(|&&v| v).count(), 0);
}

#[test]
fn detect_raw_is_detect_on_one_channel() {
    let img = fading_step();
    let p = abs(1.0, 3.0);
    let valid = img.map(|v| v.is_finite());
    assert_eq!(detect_raw(&img, &p), detect(&[&img], &[1.0], &valid, &p));
    // Zero weight on a channel removes it; scaling all weights by s² scales magnitudes by s.
    let zero = Grid::new(21, 60, 0.0f32);
    let e2 = detect(&[&img, &zero], &[4.0, 1.0], &valid, &abs(2.0, 6.0));
    assert_eq!(e2.edges, detect_raw(&img, &p).edges);
    approx::assert_relative_eq!(
        e2.magnitude[(10, 5)],
        2.0 * detect_raw(&img, &p).magnitude[(10, 5)],
        max_relative = 1e-5
    );
}

#[test]
fn threshold_modes() {
    let mut v = vec![5.0, 1.0, 3.0, 2.0, 4.0];
    assert_eq!(quantile(&mut v, 0.0), 1.0);
    assert_eq!(quantile(&mut v, 0.5), 3.0);
    assert_eq!(quantile(&mut v, 1.0), 5.0);
    assert_eq!(quantile(&mut [], 0.5), f32::INFINITY);
    let mag = [1.0, 2.0, 3.0, 100.0];
    let ok = [true, true, true, false];
    let t = Thresholds { mode: ThresholdMode::NoiseRelative, low: 2.0, high: 4.0, noise_floor: 0.1 };
    assert_eq!(canny::absolute_thresholds(&t, &mag, &ok), (4.0, 8.0));
    let t = Thresholds { mode: ThresholdMode::Quantile, low: 0.0, high: 1.0, noise_floor: 0.1 };
    assert_eq!(canny::absolute_thresholds(&t, &mag, &ok), (1.0, 3.0));
    let t = Thresholds { mode: ThresholdMode::NoiseRelative, low: 2.0, high: 4.0, noise_floor: 10.0 };
    assert_eq!(canny::absolute_thresholds(&t, &mag, &ok), (20.0, 40.0));
}

#[test]
fn params_from_toml_and_validation() {
    let p: Params =
        toml::from_str("sigma_px = 1.0\n[thresholds]\nmode = \"quantile\"\nlow = 0.8\nhigh = 0.95\n")
            .unwrap();
    assert_eq!(p.thresholds.mode, ThresholdMode::Quantile);
    assert_eq!(p.kernel_px, 5);
    assert!(p.validate().is_ok());
    assert!(toml::from_str::<Params>("sigma = 1.0").is_err(), "unknown fields are rejected");
    assert!(Params::default().validate().is_ok());
    assert!(Params { kernel_px: 4, ..Params::default() }.validate().unwrap_err().field == "vcanny.kernel_px");
    assert!(abs(3.0, 2.0).validate().is_err());
    assert!(Params { weights: [0.0; 3], ..Params::default() }.validate().is_err());
}

mod fast_path {
    //! The streamed, vectorisable implementation against the straightforward one (`reference.rs`) on random
    //! images with holes: bit-identical magnitudes and identical edges.

    use super::*;
    use crate::reference;
    use rand::{RngExt, SeedableRng, rngs::Xoshiro256PlusPlus};

    /// A random channel: a few planes with steps, noise, and sometimes NaN / infinite values.
    fn channel(rng: &mut Xoshiro256PlusPlus, w: u32, h: u32, holes: f32) -> Grid<f32> {
        let (a, b, c) = (
            rng.random_range(-2.0..2.0f32),
            rng.random_range(-2.0..2.0f32),
            rng.random_range(-50.0..50.0f32),
        );
        let split = rng.random_range(0..=w);
        let step = rng.random_range(-20.0..20.0f32);
        let noise = rng.random_range(0.0..1.0f32);
        let quantise = rng.random_bool(0.5);
        Grid::from_fn(w, h, |x, y| {
            let u: f32 = rng.random();
            if u < holes {
                return if rng.random_bool(0.9) { f32::NAN } else { f32::INFINITY };
            }
            let mut v = a * x as f32 + b * y as f32 + c + if x >= split { step } else { 0.0 };
            v += noise * rng.random_range(-1.0..1.0f32);
            if quantise { v.round() } else { v }
        })
    }

    fn params(rng: &mut Xoshiro256PlusPlus) -> Params {
        let mode = [ThresholdMode::Absolute, ThresholdMode::Quantile, ThresholdMode::NoiseRelative]
            [rng.random_range(0..3usize)];
        let (low, high) = match mode {
            ThresholdMode::Absolute => {
                let l = rng.random_range(0.0..2.0f32);
                (l, l + rng.random_range(0.0..3.0f32))
            }
            ThresholdMode::Quantile => {
                let l = rng.random_range(0.0..1.0f32);
                (l, rng.random_range(l..=1.0))
            }
            ThresholdMode::NoiseRelative => {
                let l = rng.random_range(0.0..3.0f32);
                (l, l + rng.random_range(0.0..5.0f32))
            }
        };
        Params {
            sigma_px: rng.random_range(0.3..3.0),
            kernel_px: [1, 3, 5, 5, 7, 9][rng.random_range(0..6usize)],
            weights: [rng.random_range(0.0..2.0), rng.random_range(0.0..2.0), rng.random_range(0.0..0.2)],
            thresholds: Thresholds { mode, low, high, noise_floor: 1e-3 },
        }
    }

    fn assert_same(fast: &Edges, slow: &Edges, what: &str) {
        let bits = |e: &Edges| e.magnitude.as_slice().iter().map(|m| m.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(fast), bits(slow), "{what}: magnitudes differ");
        assert_eq!(fast.edges, slow.edges, "{what}: edges differ");
    }

    #[test]
    fn streamed_detector_is_bit_identical_to_the_reference_on_random_images_with_holes() {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(17);
        let (mut n_edges, mut n_unit_diff) = (0, 0);
        for case in 0..150 {
            let (w, h) = if case < 20 {
                (rng.random_range(1..=4u32), rng.random_range(1..=4u32))
            } else {
                (rng.random_range(1..=48u32), rng.random_range(1..=40u32))
            };
            let holes = [0.0, 0.02, 0.2, 0.6][case % 4];
            let p = params(&mut rng);
            let n = rng.random_range(1..=3usize);
            let chans: Vec<Grid<f32>> = (0..n).map(|_| channel(&mut rng, w, h, holes)).collect();
            let refs: Vec<&Grid<f32>> = chans.iter().collect();
            let mut weights: Vec<f32> = p.weights[..n].to_vec();
            if case % 5 == 0 {
                weights[0] = 0.0;
            }
            let valid = Grid::from_fn(w, h, |_, _| !rng.random_bool(holes as f64 / 2.0));
            let fast = detect(&refs, &weights, &valid, &p);
            assert_same(
                &fast,
                &reference::detect(&refs, &weights, &valid, &p),
                &format!("detect case {case}"),
            );
            n_edges += fast.edges.as_slice().iter().filter(|&&e| e).count();
            // Against the detector before the fast path (unit directions): the same magnitudes, and the edges
            // differ only where rounding of the direction's ratio flips a near-tie of the suppression.
            let unit = reference::detect_unit_direction(&refs, &weights, &valid, &p);
            let bits = |e: &Edges| e.magnitude.as_slice().iter().map(|m| m.to_bits()).collect::<Vec<_>>();
            assert_eq!(
                bits(&fast),
                bits(&unit),
                "case {case}: magnitudes differ from the unit-direction detector"
            );
            n_unit_diff +=
                fast.edges.as_slice().iter().zip(unit.edges.as_slice()).filter(|(a, b)| a != b).count();

            let raw = detect_raw(&chans[0], &p);
            let all = Grid::new(w, h, true);
            assert_same(&raw, &reference::detect(&refs[..1], &[1.0], &all, &p), &format!("raw case {case}"));

            let c3: Vec<Grid<f32>> = (0..3).map(|_| channel(&mut rng, w, h, holes / 4.0)).collect();
            let plane = Grid::from_fn(w, h, |x, y| [c3[0][(x, y)], c3[1][(x, y)], c3[2][(x, y)]]);
            let planes = detect_planes(&plane, &valid, &p);
            let r3: Vec<&Grid<f32>> = c3.iter().collect();
            assert_same(
                &planes,
                &reference::detect(&r3, &p.weights, &valid, &p),
                &format!("planes case {case}"),
            );
        }
        assert!(n_edges > 1000, "the random cases must exercise the edge paths, got {n_edges} edge pixels");
        assert!(
            n_unit_diff * 1000 <= n_edges,
            "{n_unit_diff} of {n_edges} edge pixels moved with the unit directions"
        );
    }

    #[test]
    fn nms_matches_the_reference_for_any_direction() {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(3);
        for _ in 0..50 {
            let (w, h) = (rng.random_range(1..=12usize), rng.random_range(1..=12usize));
            let mag: Vec<f32> = (0..w * h)
                .map(|_| if rng.random_bool(0.2) { 0.0 } else { rng.random_range(0..4u8) as f32 })
                .collect();
            let dir: Vec<[f32; 2]> = (0..w * h)
                .map(|_| match rng.random_range(0..4u8) {
                    0 => [1.0, 0.0],
                    1 => [0.0, if rng.random_bool(0.5) { 1.0 } else { -1.0 }],
                    _ => {
                        let a = rng.random_range(-4.0..4.0f32);
                        [a.cos(), a.sin()]
                    }
                })
                .collect();
            let ok: Vec<bool> = (0..w * h).map(|_| !rng.random_bool(0.15)).collect();
            assert_eq!(
                non_max_suppression(&mag, &dir, &ok, w, h),
                reference::non_max_suppression(&mag, &dir, &ok, w, h)
            );
        }
    }

    #[test]
    fn hysteresis_and_quantiles_match_the_reference() {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(5);
        for _ in 0..50 {
            let (w, h) = (rng.random_range(1..=30usize), rng.random_range(1..=30usize));
            let mag: Vec<f32> = (0..w * h)
                .map(|_| match rng.random_range(0..5u8) {
                    0 => 0.0,
                    1 => -0.0,
                    2 => rng.random_range(0..6u8) as f32,
                    3 => -rng.random_range(0.0..3.0f32),
                    _ => rng.random_range(0.0..10.0f32),
                })
                .collect();
            let cand: Vec<bool> = (0..w * h).map(|_| rng.random_bool(0.6)).collect();
            let (low, high) = (rng.random_range(0.0..4.0f32), rng.random_range(4.0..8.0f32));
            assert_eq!(
                hysteresis(&mag, &cand, w, h, low, high),
                reference::hysteresis(&mag, &cand, w, h, low, high)
            );
            for q in [0.0, 0.1, 0.5, 0.77, 0.9, 1.0] {
                let mut v: Vec<f32> = mag.iter().zip(&cand).filter(|&(_, &c)| c).map(|(&m, _)| m).collect();
                let want = reference::quantile(&mut v, q);
                assert_eq!(
                    canny::masked_quantiles(&mag, &cand, &[q])[0].to_bits(),
                    want.to_bits(),
                    "q = {q}"
                );
            }
        }
    }
}

#[test]
fn every_instruction_set_gives_the_same_bits() {
    // The detector runs compiled for each instruction set of this CPU (isa::dispatch): the same bits on each.
    use rand::{RngExt, SeedableRng, rngs::Xoshiro256PlusPlus};
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(17);
    let (w, h) = (77, 53);
    let range = Grid::from_fn(w, h, |x, y| {
        let z = if x < 40 { 100.0 + 0.5 * x as f32 } else { 140.0 - 0.3 * x as f32 + 0.2 * y as f32 };
        if (x + 3 * y) % 29 == 0 { NAN } else { z + rng.random_range(-0.5f32..0.5) }
    });
    let plane = Grid::from_fn(w, h, |x, y| {
        let v = range[(x, y)];
        [0.01 * v, if x < 40 { 0.5 } else { -0.3 }, v]
    });
    let valid = rangeimage::valid_mask(&range);
    let bits =
        |e: &Edges| (e.edges.clone(), e.magnitude.as_slice().iter().map(|m| m.to_bits()).collect::<Vec<_>>());
    // Every threshold mode: the quantile selection and hysteresis run in the dispatched code too.
    let quantile = Thresholds { mode: ThresholdMode::Quantile, low: 0.7, high: 0.9, ..Thresholds::default() };
    for params in [
        Params::default(),
        Params { sigma_px: 2.0, kernel_px: 9, weights: [1.0, 0.5, 0.25], ..Params::default() },
        Params { thresholds: quantile, ..Params::default() },
        abs(0.05, 0.2),
    ] {
        let run = || (bits(&detect_planes(&plane, &valid, &params)), bits(&detect_raw(&range, &params)));
        let a = isa::with_isa(isa::Isa::Baseline, run).expect("baseline");
        assert!(a.0.0.as_slice().iter().any(|&e| e) && a.1.0.as_slice().iter().any(|&e| e));
        for other in isa::Isa::available() {
            assert!(
                isa::with_isa(other, run).expect("available") == a,
                "{other:?} differs from the baseline"
            );
        }
    }
}

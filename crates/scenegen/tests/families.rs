//! The artefact families and the noise estimator against each other: the estimate recovers the
//! noise the generator was given, and each family changes the images the way it says.

use planefit::noise::{NoiseEstimate, estimate};
use rangeimage::RangeImage;
use scenegen::{Family, Params, Scene, family_image, generate};

fn range_of(scene: &Scene) -> RangeImage {
    scene.range.map(|&v| if v == 0 { f32::NAN } else { f32::from(v) })
}

fn estimate_scene(p: &Params, seed: u64) -> NoiseEstimate {
    estimate(&range_of(&generate(p, seed)))
}

/// Mean absolute second difference at lag 2 of the range, down the columns and along the rows
/// (planes cancel; noise correlated over more than 2 pixels in one direction cancels in part).
fn second_differences(r: &RangeImage) -> (f64, f64) {
    let (w, h) = r.dimensions();
    let (mut down, mut across, mut nd, mut na) = (0.0, 0.0, 0usize, 0usize);
    for y in 2..h - 2 {
        for x in 2..w - 2 {
            let c = f64::from(r[(x, y)]);
            let d = (f64::from(r[(x, y - 2)]) - 2.0 * c + f64::from(r[(x, y + 2)])).abs();
            let a = (f64::from(r[(x - 2, y)]) - 2.0 * c + f64::from(r[(x + 2, y)])).abs();
            // Skip jumps and missing data.
            if d.is_finite() && d < 8.0 {
                down += d;
                nd += 1;
            }
            if a.is_finite() && a < 8.0 {
                across += a;
                na += 1;
            }
        }
    }
    (down / nd as f64, across / na as f64)
}

#[test]
fn estimator_recovers_the_white_noise_of_scenes() {
    // The benchmark's sensor: Gaussian noise σ (in range steps), then 8-bit rounding (step 1).
    for (sigma, seed) in [(0.6, 21), (1.0, 22), (2.0, 23), (3.0, 24)] {
        let e = estimate_scene(&Params { noise_sigma_v: sigma, ..Params::default() }, seed);
        assert_eq!(e.step, Some(1.0), "σ {sigma}: 8-bit range has step 1");
        let total = (sigma * sigma + 1.0 / 12.0_f64).sqrt();
        assert!((e.sigma / total - 1.0).abs() < 0.10, "σ {sigma}: σ with rounding {} vs {total}", e.sigma);
        assert!((e.sigma_noise() / sigma - 1.0).abs() < 0.15, "σ {sigma}: estimated {}", e.sigma_noise());
    }
}

#[test]
fn estimator_finds_the_staircase_step() {
    for (step, sigma, seed) in [(2.0, 1.0, 31), (3.0, 1.5, 32), (4.0, 0.25, 33)] {
        let p = Params {
            noise_sigma_v: sigma,
            staircase: Some(scenegen::Staircase { step_v: step }),
            ..Params::default()
        };
        let e = estimate_scene(&p, seed);
        assert_eq!(e.step, Some(step), "step {step}, σ {sigma}");
        if sigma >= step / 2.0 {
            let s = e.sigma_noise();
            assert!((s / sigma - 1.0).abs() < 0.15, "step {step}: σ {sigma} estimated {s}");
        }
    }
}

#[test]
fn families_share_their_scenes_and_differ_in_noise() {
    let scene = |f: Family, s: f64| {
        let (p, seed) = family_image(f, s, true, 3);
        p.validate().expect("family parameters are valid");
        generate(&p, seed)
    };
    let abw = scene(Family::Abw, 1.0);
    // Same layout, noise draws and dropouts: the ground truth is the same (Kinect holes aside).
    for f in [Family::Stripes, Family::Staircase] {
        let other = scene(f, 1.0);
        assert_eq!(other.labels, abw.labels, "{f:?}");
        assert_ne!(other.range, abw.range, "{f:?}");
    }
    // The family sets are not the benchmark's scenes.
    let (bp, bseed) = scenegen::benchmark_image(true, 3);
    assert_ne!(generate(&bp, bseed).labels, abw.labels);

    // Stripes run down the columns: second differences are smaller down them than across.
    let (down, across) = second_differences(&range_of(&scene(Family::Stripes, 1.0)));
    assert!(down < 0.85 * across, "stripes: down {down}, across {across}");
    let (down, across) = second_differences(&range_of(&abw));
    assert!((down / across - 1.0).abs() < 0.05, "white noise: down {down}, across {across}");

    // Staircase: the estimator sees the family's step, 3 × strength.
    assert_eq!(estimate(&range_of(&scene(Family::Staircase, 1.0))).step, Some(3.0));
    assert_eq!(estimate(&range_of(&scene(Family::Staircase, 2.0))).step, Some(6.0));
    // 1.33: steps of 3.99 stored in whole units, risers of 4 and, where the rounding drifts, 3.
    assert_eq!(estimate(&range_of(&scene(Family::Staircase, 1.33))).step, Some(4.0));

    // Kinect: noise grows with strength, and with depth (far half of the range vs near half).
    let k1 = scene(Family::Kinect, 1.0);
    let s = |sc: &Scene| estimate(&range_of(sc)).sigma;
    assert!(s(&scene(Family::Kinect, 0.5)) < s(&k1) && s(&k1) < s(&scene(Family::Kinect, 2.0)));
    let r = range_of(&k1);
    let mut v: Vec<f32> = r.as_slice().iter().copied().filter(|v| v.is_finite()).collect();
    v.sort_by(f32::total_cmp);
    let cut = v[v.len() / 2];
    let half = |far: bool| estimate(&r.map(|&v| if (v >= cut) == far { v } else { f32::NAN })).sigma;
    assert!(half(true) > 1.5 * half(false), "far σ {} vs near σ {}", half(true), half(false));
    // Holes: fewer valid pixels than the same scene without the Kinect model.
    let valid = |sc: &Scene| sc.range.as_slice().iter().filter(|&&v| v != 0).count();
    assert!(valid(&k1) < valid(&abw));
}

#[test]
fn strength_zero_removes_the_artefact_and_bad_parameters_are_refused() {
    let (p, _) = family_image(Family::Stripes, 0.0, false, 0);
    assert_eq!(p.stripes.map(|s| s.amplitude_v), Some(0.0));
    assert!(p.validate().is_ok());
    let bad =
        Params { stripes: Some(scenegen::Stripes { amplitude_v: 1.0, length_px: 0.0 }), ..Params::default() };
    assert!(bad.validate().unwrap_err().to_string().contains("stripes.length_px"));
    let bad = Params { staircase: Some(scenegen::Staircase { step_v: 0.5 }), ..Params::default() };
    assert!(bad.validate().is_err());
    let bad = Params {
        kinect: Some(scenegen::Kinect { far_mm: 1000.0, ..scenegen::Kinect::default() }),
        ..Params::default()
    };
    assert!(bad.validate().unwrap_err().to_string().contains("far_mm"));
    for f in Family::ALL {
        assert_eq!(Family::from_name(f.name()), Some(f));
    }
    assert_eq!(Family::from_name("nope"), None);
}

#[test]
fn disparity_is_planar_in_pixel_coordinates_and_noise_free() {
    // Each large GT region's stored values fit a plane in (x, y, value) to within the rounding, which range values
    // (affine in depth, not in its inverse) of the same scene do not: a slanted face of this scene bends by
    // 3.7 steps.
    let (params, seed) = family_image(Family::Disparity, 1.0, false, 2);
    let (disparity, range) =
        (generate(&params, seed), generate(&Params { disparity: false, ..params }, seed));
    assert_eq!(disparity.labels, range.labels, "the same scene and ground truth");
    // The 90th percentile of |value − plane fit| over a region's pixels.
    let p90 = |scene: &Scene, label: u32| {
        let px: Vec<[f64; 3]> = scene
            .labels
            .enumerate()
            .filter(|&(_, _, &l)| l == label)
            .map(|(x, y, _)| [f64::from(x), f64::from(y), f64::from(scene.range[(x, y)])])
            .collect();
        let n = px.len() as f64;
        let mean = |k: usize| px.iter().map(|p| p[k]).sum::<f64>() / n;
        let (mx, my, mv) = (mean(0), mean(1), mean(2));
        let s =
            |a: usize, b: usize, ma: f64, mb: f64| px.iter().map(|p| (p[a] - ma) * (p[b] - mb)).sum::<f64>();
        let (sxx, syy, sxy, sxv, syv) =
            (s(0, 0, mx, mx), s(1, 1, my, my), s(0, 1, mx, my), s(0, 2, mx, mv), s(1, 2, my, mv));
        let det = sxx * syy - sxy * sxy;
        let (a, b) = ((sxv * syy - syv * sxy) / det, (syv * sxx - sxv * sxy) / det);
        let mut r: Vec<f64> =
            px.iter().map(|p| (p[2] - mv - a * (p[0] - mx) - b * (p[1] - my)).abs()).collect();
        r.sort_by(f64::total_cmp);
        r[r.len() * 9 / 10]
    };
    let mut labels: Vec<u32> = disparity.labels.as_slice().to_vec();
    labels.sort_unstable();
    labels.dedup();
    let large: Vec<u32> = labels
        .into_iter()
        .filter(|&l| l >= 10 && disparity.labels.as_slice().iter().filter(|&&m| m == l).count() >= 5000)
        .collect();
    assert!(large.len() >= 3, "{large:?}");
    let (worst_disparity, worst_range) = large
        .iter()
        .map(|&l| (p90(&disparity, l), p90(&range, l)))
        .fold((0.0f64, 0.0f64), |(a, b), (c, d)| (a.max(c), b.max(d)));
    // The rounding alone puts the 90th percentile at 0.45; mixed pixels on jump edges add a little.
    assert!(worst_disparity <= 0.65, "disparity: {worst_disparity} from the plane");
    assert!(worst_range > 2.0 * worst_disparity, "range {worst_range}, disparity {worst_disparity}");
}

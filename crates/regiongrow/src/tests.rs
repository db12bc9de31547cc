//! Unit tests of `grow`, `borders` and `Params`.

use super::*;
use crate::testutil::{abw_like_scene, box_face, box_scene, canonical};
use approx::assert_relative_eq;

/// Pixels whose 5×5 neighbourhood lies entirely on face `f` of the box scene.
fn interior(f: u32) -> Vec<(u32, u32)> {
    let mut v = Vec::new();
    for y in 2..62 {
        for x in 2..62 {
            if (0..5).all(|dy| (0..5).all(|dx| box_face(x + dx - 2, y + dy - 2) == f)) {
                v.push((x, y));
            }
        }
    }
    v
}

/// The most frequent label over `px` and the fraction of `px` carrying it.
fn majority(labels: &LabelImage, px: &[(u32, u32)]) -> (u32, f64) {
    let mut counts = std::collections::BTreeMap::new();
    for &p in px {
        *counts.entry(labels[p]).or_insert(0u32) += 1;
    }
    let (l, c) = counts.into_iter().max_by_key(|&(l, c)| (c, std::cmp::Reverse(l))).unwrap();
    (l, f64::from(c) / px.len() as f64)
}

fn small_params() -> Params {
    Params { min_region_px: 20, ..Params::default() }
}

#[test]
fn default_mode_separates_crease_and_jump() {
    let s = box_scene();
    let (seg, info) = grow(&s.range, &s.features, &Camera::Grid, &small_params(), 1);
    let m: Vec<(u32, f64)> = (1..=3).map(|f| majority(&seg.labels, &interior(f))).collect();
    for (f, &(l, frac)) in m.iter().enumerate() {
        assert!(l != 0 && frac == 1.0, "face {}: label {l} on {frac} of its interior", f + 1);
    }
    assert!(m[0].0 != m[1].0 && m[1].0 != m[2].0 && m[0].0 != m[2].0, "faces share a label: {m:?}");
    assert_eq!(info.n_regions, 3, "{info:?}");
    assert_eq!(seg.regions.len(), 3);
    // With the fill step every valid pixel of each face ends in its face's region, except at most
    // the pixels right on the crease or the jump.
    let mut wrong = 0;
    for (x, y, &l) in seg.labels.enumerate() {
        let f = box_face(x, y);
        if f == 0 {
            assert_eq!(l, 0);
        } else if l != m[f as usize - 1].0 {
            wrong += 1;
        }
    }
    assert!(wrong <= 64, "{wrong} pixels off their face");
}

/// A 128×64 surface in `Camera::Grid` units whose depth bends slowly (as an encoding that is not
/// linear in depth bends a plane: up to about 5 units off its best plane) under a smooth ripple
/// of ±2.8 (period 24 px, so the local normals stay within about 25° of the mean and the
/// curvedness low): a region's RMS distance to its own plane reaches about 1.4 units, and
/// `max_residual = 3` alone is about 2σ of that scatter.
fn bent_surface() -> crate::testutil::Scene {
    let range = Grid::from_fn(128, 64, |x, y| {
        let t = std::f32::consts::TAU / 24.0;
        let ripple = 1.4 * ((t * x as f32).sin() + (t * y as f32).sin());
        let u = x as f32 - 64.0;
        100.0 + 0.1 * y as f32 + 0.002 * u * u + ripple
    });
    let features = crate::testutil::features(&range);
    crate::testutil::Scene { range, features }
}

/// The residual limit follows the region's own scatter: with `residual_rms_ratio = 3` the bent,
/// rippled surface grows into at most three regions covering nearly all of it; with
/// `max_residual` alone it shatters into many fragments. (The crease of the box scene still
/// separates its faces with the ratio on: `default_mode_separates_crease_and_jump` runs the
/// defaults.)
#[test]
fn residual_limit_follows_the_region_scatter() {
    let s = bent_surface();
    let run = |ratio: f32| {
        // Growth alone: the joint-fit merge, the merge after fill and a loose pairwise merge would
        // rejoin fragments.
        let params = Params {
            min_region_px: 20,
            residual_rms_ratio: ratio,
            merge_joint_rms_ratio: 0.0,
            merge_after_fill: false,
            merge_max_residual: 2.0,
            ..Params::default()
        };
        let (seg, info) = grow(&s.range, &s.features, &Camera::Grid, &params, 3);
        let mut counts = vec![0u32; info.n_regions as usize + 1];
        for &l in seg.labels.as_slice() {
            counts[l as usize] += 1;
        }
        counts.remove(0);
        counts.sort_unstable_by(|a, b| b.cmp(a));
        let two = counts.iter().take(2).sum::<u32>();
        (info.n_regions, f64::from(two) / f64::from(128 * 64))
    };
    let (n_on, two_on) = run(3.0);
    let (n_off, _) = run(0.0);
    assert!(n_on <= 3 && two_on > 0.95, "ratio 3: {n_on} regions, the two largest cover {two_on:.3}");
    assert!(n_off >= 2 * n_on + 2, "ratio 0: {n_off} regions (ratio 3: {n_on})");
}

#[test]
fn regions_carry_their_planes() {
    let s = box_scene();
    let (seg, _) = grow(&s.range, &s.features, &Camera::Grid, &small_params(), 1);
    let label_a = majority(&seg.labels, &interior(1)).0;
    let r = &seg.regions[label_a as usize - 1];
    assert_eq!(r.label, label_a);
    // Face A: z = 100 + 0.8 x + 0.2 y; Camera::Grid looks along +z, so the normal points to −z.
    let n = (0.8f32 * 0.8 + 0.2 * 0.2 + 1.0).sqrt();
    assert_relative_eq!(r.normal[0], 0.8 / n, epsilon = 0.02);
    assert_relative_eq!(r.normal[1], 0.2 / n, epsilon = 0.02);
    assert_relative_eq!(r.normal[2], -1.0 / n, epsilon = 0.02);
    // offset: n·p + d = 0 at p = (0, 0, 100).
    assert_relative_eq!(r.offset, 100.0 / n, epsilon = 1.0);
    assert!(r.rms_residual < 0.5, "{r:?}");
    assert!(r.mean_k.abs() < 1e-3);
    let total: u32 = seg.regions.iter().map(|r| r.size_px).sum();
    assert_eq!(total as usize, seg.labels.as_slice().iter().filter(|&&l| l != 0).count());
}

#[test]
fn paper_mode_leaks_across_the_crease() {
    // K ≈ 0 on the crease (one principal curvature is 0), so the paper's criterion cannot stop
    // there; at the straight sides of the jump K ≈ 0 as well. Only the jump's corners have K ≠ 0.
    let s = box_scene();
    let params = Params { min_region_px: 20, ..Params::paper() };
    let (seg, _) = grow(&s.range, &s.features, &Camera::Grid, &params, 1);
    let a = majority(&seg.labels, &interior(1)).0;
    let b = majority(&seg.labels, &interior(2)).0;
    let c = majority(&seg.labels, &interior(3)).0;
    assert!(a != 0 && a == b, "paper mode should merge the faces across the crease: {a} {b}");
    assert_eq!(c, a, "paper mode also leaks across the jump's straight sides on this scene");
}

#[test]
fn labels_are_zero_on_no_data() {
    let s = box_scene();
    for params in [small_params(), Params::paper()] {
        let (seg, _) = grow(&s.range, &s.features, &Camera::Grid, &params, 3);
        for (x, y, v) in s.range.enumerate() {
            if v.is_nan() {
                assert_eq!(seg.labels[(x, y)], 0);
                assert!(!seg.c1[(x, y)]);
            }
        }
    }
}

#[test]
fn regions_under_min_size_are_dropped() {
    let s = box_scene();
    // The box top has 24 × 20 = 480 pixels (fewer after the growth margin).
    for fill in [false, true] {
        let params = Params { min_region_px: 600, fill_unlabelled: fill, ..Params::default() };
        let (seg, info) = grow(&s.range, &s.features, &Camera::Grid, &params, 1);
        // Either grown and dropped, or never seeded (seeding stops once fewer than
        // `min_region_px` growable pixels are left).
        assert!(info.n_dropped >= 1 || info.n_unlabelled_valid_px as usize >= interior(3).len(), "{info:?}");
        assert!(interior(3).iter().all(|&p| seg.labels[p] == 0), "fill = {fill}");
        assert!(seg.regions.iter().all(|r| r.size_px >= 600));
        assert_eq!(info.n_regions, 2);
    }
}

#[test]
fn same_seed_same_output_in_1_and_2_thread_pools() {
    let s = abw_like_scene(96);
    let params = Params { min_region_px: 30, ..Params::default() };
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        pool.install(|| grow(&s.range, &s.features, &Camera::ABW0, &params, 42))
    };
    let (a, ia) = run(1);
    let (b, ib) = run(2);
    assert_eq!(a.labels, b.labels);
    assert_eq!(a.c1, b.c1);
    assert_eq!(ia, ib);
    assert_eq!(region_bits(&a), region_bits(&b));
    assert!(a.regions.len() >= 4, "{ia:?}");
}

#[test]
fn clean_scene_partition_does_not_depend_on_the_seed() {
    let s = box_scene();
    let (a, _) = grow(&s.range, &s.features, &Camera::Grid, &small_params(), 1);
    for seed in [2, 99, 12345] {
        let (b, _) = grow(&s.range, &s.features, &Camera::Grid, &small_params(), seed);
        assert_eq!(canonical(a.labels.as_slice()), canonical(b.labels.as_slice()), "seed {seed}");
    }
}

#[test]
fn too_few_seeds_relax_t_sigma() {
    let s = abw_like_scene(64);
    let params = Params { t_sigma: 1e-12, min_seeds: 3, min_region_px: 10, ..Params::default() };
    let (seg, info) = grow(&s.range, &s.features, &Camera::ABW0, &params, 5);
    assert!(info.n_relaxations >= 1, "{info:?}");
    assert!(info.n_seeds >= 3, "{info:?}");
    assert!(info.t_sigma_used > 1e-12);
    assert!(!seg.regions.is_empty());
    // Without the relaxation need, nothing is relaxed.
    let (_, info) = grow(&s.range, &s.features, &Camera::ABW0, &Params::default(), 5);
    assert_eq!((info.n_relaxations, info.t_sigma_used), (0, Params::default().t_sigma));
}

#[test]
fn max_seeds_caps_the_regions_grown() {
    let s = abw_like_scene(64);
    let params = Params { max_seeds: 2, min_seeds: 1, min_region_px: 1, ..Params::default() };
    let (_, info) = grow(&s.range, &s.features, &Camera::ABW0, &params, 5);
    assert_eq!((info.n_seeds, info.n_regions_grown), (2, 2));
}

#[test]
fn borders_both_sides_and_one_side() {
    let labels = Grid::from_rows(vec![vec![1, 1, 2, 2], vec![1, 1, 2, 2], vec![0, 1, 2, 0]]).unwrap();
    let two = borders(&labels, false);
    let got: Vec<u8> = two.as_slice().iter().map(|&b| u8::from(b)).collect();
    assert_eq!(got, vec![0, 1, 1, 0, 1, 1, 1, 1, 0, 1, 1, 0]);
    let one = borders(&labels, true);
    let got: Vec<u8> = one.as_slice().iter().map(|&b| u8::from(b)).collect();
    // Region/region: only the left pixel of each pair; region/0: the labelled pixel.
    assert_eq!(got, vec![0, 1, 0, 0, 1, 1, 0, 1, 0, 1, 1, 0]);
    let labels = Grid::from_rows(vec![vec![1, 1, 2, 2]]).unwrap();
    assert_eq!(borders(&labels, true).as_slice(), &[false, true, false, false]);
    assert_eq!(borders(&labels, false).as_slice(), &[false, true, true, false]);
}

#[test]
fn c1_is_the_border_of_the_labels() {
    let s = box_scene();
    for one_sided in [false, true] {
        let params = Params { c1_one_sided: one_sided, ..small_params() };
        let (seg, _) = grow(&s.range, &s.features, &Camera::Grid, &params, 1);
        assert_eq!(seg.c1, borders(&seg.labels, one_sided));
        assert!(seg.c1.as_slice().iter().any(|&b| b));
    }
}

#[test]
fn params_toml_round_trip_and_unknown_fields() {
    let p = Params::paper();
    let text = toml::to_string(&p).unwrap();
    assert_eq!(toml::from_str::<Params>(&text).unwrap(), p);
    let partial: Params = toml::from_str("mode = \"paper\"\nt_m = 0.5").unwrap();
    assert_eq!(
        (partial.mode, partial.t_m, partial.max_seeds),
        (Mode::Paper, 0.5, Params::default().max_seeds)
    );
    assert!(toml::from_str::<Params>("t_mm = 0.5").is_err());
    assert!(Params::default().validate().is_ok());
    assert!(Params::paper().validate().is_ok());
    let bad = [
        Params { connectivity: 6, ..Params::default() },
        Params { min_seeds: 10, max_seeds: 5, ..Params::default() },
        Params { t_sigma: -1.0, ..Params::default() },
        Params { max_residual: f32::NAN, ..Params::default() },
        Params { max_angle_deg: 200.0, ..Params::default() },
        Params { refit_every_px: 0, ..Params::default() },
    ];
    for b in bad {
        assert!(b.validate().is_err(), "{b:?}");
    }
}

#[test]
fn eight_connectivity_also_separates_faces() {
    let s = box_scene();
    let params = Params { connectivity: 8, ..small_params() };
    let (seg, info) = grow(&s.range, &s.features, &Camera::Grid, &params, 1);
    assert_eq!(info.n_regions, 3, "{info:?}");
    let m: Vec<u32> = (1..=3).map(|f| majority(&seg.labels, &interior(f)).0).collect();
    assert!(m[0] != m[1] && m[1] != m[2] && m[0] != m[2] && !m.contains(&0));
}

mod proptests {
    use super::*;
    use proptest::prelude::*;
    use rangeimage::testing::arbitrary_range_image;

    proptest! {
        #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]
        #[test]
        fn proptest_labels_zero_where_nan(img in arbitrary_range_image(1..40, 1..40), seed in 0u64..1000) {
            let f = crate::testutil::features(&img);
            for params in [Params { min_region_px: 1, ..Params::default() }, Params { min_region_px: 1, ..Params::paper() }] {
                let (seg, info) = grow(&img, &f, &Camera::ABW0, &params, seed);
                prop_assert_eq!(seg.regions.len() as u32, info.n_regions);
                for (x, y, v) in img.enumerate() {
                    let l = seg.labels[(x, y)];
                    if v.is_nan() {
                        prop_assert_eq!(l, 0);
                    }
                    prop_assert!(l as usize <= seg.regions.len());
                    prop_assert!(!seg.c1[(x, y)] || l != 0);
                }
                for (i, r) in seg.regions.iter().enumerate() {
                    prop_assert_eq!(r.label as usize, i + 1);
                    prop_assert!(r.size_px >= 1);
                }
            }
        }
    }
}

/// The seed-window test rejects noisy seeds: fewer regions are grown, and the result keeps its
/// regions; a zero stride is rejected.
#[test]
fn seed_window_rejects_noisy_seeds() {
    let s = crate::testutil::abw_like_scene(128);
    let loose = Params { seed_radius_px: 0, ..Params::default() };
    let (_, i0) = grow(&s.range, &s.features, &Camera::ABW0, &loose, 3);
    let (seg, i1) = grow(&s.range, &s.features, &Camera::ABW0, &Params::default(), 3);
    assert!(i1.n_seeds <= i0.n_seeds, "{i1:?} vs {i0:?}");
    assert!(!seg.regions.is_empty());
    assert!(Params { seed_stride_px: 0, ..Params::default() }.validate().is_err());
}

/// The pre-optimisation `borders`, pixel by pixel with explicit bounds: the reference of the
/// row-slice version.
fn borders_reference(labels: &LabelImage, one_sided: bool) -> Vec<bool> {
    let (w, h) = labels.dimensions();
    let (w, h) = (w as usize, h as usize);
    let l = labels.as_slice();
    (0..w * h)
        .map(|i| {
            let (x, y, a) = (i % w, i / w, l[i]);
            if a == 0 {
                return false;
            }
            let right = (x + 1 < w).then(|| l[i + 1]);
            let down = (y + 1 < h).then(|| l[i + w]);
            let left = (x > 0).then(|| l[i - 1]);
            let up = (y > 0).then(|| l[i - w]);
            if one_sided {
                [right, down].into_iter().flatten().any(|b| b != a)
                    || [left, up].into_iter().flatten().any(|b| b == 0)
            } else {
                [right, down, left, up].into_iter().flatten().any(|b| b != a)
            }
        })
        .collect()
}

#[test]
fn borders_match_the_reference_on_random_labels() {
    use rand::{RngExt, SeedableRng, rngs::Xoshiro256PlusPlus};
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(3);
    for case in 0..200 {
        let (w, h) = (rng.random_range(1..12u32), rng.random_range(1..12u32));
        // Few labels so that equal neighbours are common.
        let n_labels = rng.random_range(1..4u32);
        let labels = Grid::from_fn(w, h, |_, _| rng.random_range(0..=n_labels));
        for one_sided in [false, true] {
            assert_eq!(
                borders(&labels, one_sided).as_slice(),
                borders_reference(&labels, one_sided).as_slice(),
                "case {case}, one_sided {one_sided}: {labels:?}"
            );
        }
    }
}

/// The pinhole camera takes the general geometry path: it grows regions, keeps no-data at 0 and
/// is reproducible.
#[test]
fn pinhole_camera_grows_regions() {
    let s = box_scene();
    let cam = Camera::Pinhole { fx: 60.0, fy: 60.0, cx: 32.0, cy: 32.0, depth_scale: 1.0 };
    let params = Params { max_residual: 1.0, fill_max_residual: 1.0, ..small_params() };
    let (seg, info) = grow(&s.range, &s.features, &cam, &params, 1);
    assert!(info.n_regions >= 1, "{info:?}");
    assert_eq!(seg.regions.len() as u32, info.n_regions);
    for (x, y, v) in s.range.enumerate() {
        if v.is_nan() {
            assert_eq!(seg.labels[(x, y)], 0);
        }
    }
    let (again, _) = grow(&s.range, &s.features, &cam, &params, 1);
    assert_eq!(again.labels, seg.labels);
}

/// FNV-1a over everything `grow` returns: labels, C1, every region field and every `Info` field.
fn output_hash(seg: &Segmentation, info: &Info) -> u64 {
    let mut h = 0xcbf2_9ce4_8422_2325u64;
    let mut eat = |v: u32| {
        for b in v.to_le_bytes() {
            h = (h ^ u64::from(b)).wrapping_mul(0x100_0000_01b3);
        }
    };
    seg.labels.as_slice().iter().for_each(|&l| eat(l));
    seg.c1.as_slice().iter().for_each(|&e| eat(u32::from(e)));
    for r in &seg.regions {
        [r.label, r.size_px, r.mean_k.to_bits(), r.offset.to_bits(), r.rms_residual.to_bits()]
            .into_iter()
            .chain(r.normal.map(f32::to_bits))
            .for_each(&mut eat);
    }
    let Info {
        n_seeds,
        n_draws,
        n_relaxations,
        t_sigma_used,
        n_regions_grown,
        n_merged,
        n_merge_passes,
        n_dropped,
        n_filled_px,
        n_regions,
        n_unlabelled_valid_px,
    } = *info;
    [
        n_seeds,
        n_draws,
        n_relaxations,
        t_sigma_used.to_bits(),
        n_regions_grown,
        n_merged,
        n_merge_passes,
        n_dropped,
        n_filled_px,
        n_regions,
        n_unlabelled_valid_px,
    ]
    .into_iter()
    .for_each(&mut eat);
    h
}

/// Pins the exact output (labels, C1, regions, `Info`) of six setups covering both modes, both
/// connectivities, the ABW, pinhole and grid cameras, 8-bit-like quantised data, strided seeds,
/// relaxation and both C1 variants. Speed work must keep these hashes; a deliberate change of
/// the output updates them (and says so in its commit).
#[test]
fn outputs_are_pinned_on_six_setups() {
    let abw = abw_like_scene(256);
    // Quantised to integer range steps (staircases, as in 8-bit ABW images).
    let q = abw.range.map(|v| v.round());
    let quant = crate::testutil::Scene { features: crate::testutil::features(&q), range: q };
    let boxes = box_scene();
    let pin = Camera::Pinhole { fx: 60.0, fy: 60.0, cx: 32.0, cy: 32.0, depth_scale: 1.0 };
    let setups: [(&str, &crate::testutil::Scene, Camera, Params, u64); 6] = [
        ("default abw0", &abw, Camera::ABW0, Params::default(), 0),
        (
            "default 8-conn one-sided abw1",
            &abw,
            Camera::ABW1,
            Params { connectivity: 8, c1_one_sided: true, ..Params::default() },
            5,
        ),
        ("paper abw0", &abw, Camera::ABW0, Params::paper(), 0),
        (
            "default quantised strided relaxed",
            &quant,
            Camera::ABW0,
            Params { seed_stride_px: 3, min_seeds: 60, fill_unlabelled: false, ..Params::default() },
            11,
        ),
        ("default quantised", &quant, Camera::ABW0, Params::default(), 2),
        ("pinhole and grid", &boxes, pin, Params { max_residual: 1.0, ..small_params() }, 1),
    ];
    let got: Vec<(&str, u64)> = setups
        .iter()
        .map(|(name, s, cam, params, seed)| {
            let (seg, info) = grow(&s.range, &s.features, cam, params, *seed);
            let mut h = output_hash(&seg, &info);
            if *name == "pinhole and grid" {
                let (seg, info) = grow(&s.range, &s.features, &Camera::Grid, params, *seed);
                h ^= output_hash(&seg, &info).rotate_left(1);
            }
            (*name, h)
        })
        .collect();
    let want: [(&str, u64); 6] = [
        ("default abw0", 0x960fa6f6299c1d97),
        ("default 8-conn one-sided abw1", 0xaf01ecd6f47160eb),
        ("paper abw0", 0xe82fa7424b5b6cee),
        ("default quantised strided relaxed", 0x9da8007243e1cfad),
        ("default quantised", 0x8438ebb21d1cd345),
        ("pinhole and grid", 0x4412b0f3f07d6ec7),
    ];
    assert_eq!(got, want, "outputs changed:\n{got:#x?}");
    // Before `release_max_px` (its only change to these setups): 0 restores that output.
    let (name, s, cam, params, seed) = &setups[3];
    let (seg, info) =
        grow(&s.range, &s.features, cam, &Params { release_max_px: 0, ..params.clone() }, *seed);
    assert_eq!(output_hash(&seg, &info), 0xccf908998ca7613c, "{name} without the release");
}

#[test]
fn every_instruction_set_gives_the_same_bits() {
    // `grow` runs compiled for each instruction set of this CPU (isa::dispatch): the same output on each.
    let pinhole = Camera::Pinhole { fx: 80.0, fy: 80.0, cx: 47.5, cy: 47.5, depth_scale: 0.01 };
    let abw = abw_like_scene(96);
    let boxes = box_scene();
    let cases = [
        (&abw, Camera::ABW0, Params { min_region_px: 30, ..Params::default() }),
        (&abw, pinhole, Params { min_region_px: 30, ..Params::default() }),
        (&boxes, Camera::Grid, small_params()),
        (&abw, Camera::ABW0, Params { min_region_px: 30, ..Params::paper() }),
    ];
    for (case, (s, camera, params)) in cases.iter().enumerate() {
        let run = || grow(&s.range, &s.features, camera, params, 7);
        let (a, ia) = isa::with_isa(isa::Isa::Baseline, run).expect("baseline");
        assert!(!a.regions.is_empty(), "case {case}: {ia:?}");
        for other in isa::Isa::available() {
            let (b, ib) = isa::with_isa(other, run).expect("available");
            assert_eq!(a.labels, b.labels, "case {case}: {other:?}");
            assert_eq!(a.c1, b.c1, "case {case}: {other:?}");
            assert_eq!(region_bits(&a), region_bits(&b), "case {case}: {other:?}");
            assert_eq!(ia, ib, "case {case}: {other:?}");
        }
    }
}

/// Every field of every region of `seg`, floats as their bits (for bit-for-bit comparisons).
fn region_bits(seg: &Segmentation) -> Vec<u32> {
    seg.regions
        .iter()
        .flat_map(|r| {
            [r.label, r.size_px, r.mean_k.to_bits(), r.offset.to_bits(), r.rms_residual.to_bits()]
                .into_iter()
                .chain(r.normal.map(f32::to_bits))
        })
        .collect()
}

/// A plane slanted in range value (0.1 and 0.4 range units per pixel), rounded to multiples of `step` without
/// noise: with step 3, terraces about 7 px wide.
fn stepped_plane(step: f64) -> RangeImage {
    Grid::from_fn(120, 100, |x, y| {
        let v = 60.0 + 0.1 * f64::from(x) + 0.4 * f64::from(y);
        ((v / step).round() * step) as f32
    })
}

#[test]
fn depth_in_coarse_steps_raises_the_angle_and_residual_limits() {
    let p = Params::default();
    // 3 range steps on the ABW camera: 3.8 units of Z against 0.6 units between pixels at this depth.
    let q = p.for_steps(&stepped_plane(3.0), &Camera::ABW0);
    assert!(q.max_residual > 3.7 && q.max_residual < 3.9, "one step in 3D: {}", q.max_residual);
    assert!(
        q.max_angle_deg > 60.0 && q.max_angle_deg < 65.0,
        "tilt of 0.3 steps per pixel: {}",
        q.max_angle_deg
    );
    assert_eq!(
        Params { max_angle_deg: p.max_angle_deg, max_residual: p.max_residual, ..q },
        p,
        "nothing else"
    );
    // Steps of 3.8 stored in whole units (risers of 4 and 3): raised for the highest riser, 4 steps.
    let uneven = stepped_plane(3.8).map(|v: &f32| v.round());
    let r = p.for_steps(&uneven, &Camera::ABW0);
    assert!(r.max_residual > q.max_residual && r.max_residual < 1.4 * q.max_residual, "{}", r.max_residual);
    assert!(r.max_angle_deg > q.max_angle_deg, "{}", r.max_angle_deg);
    // 1-step rounding (real ABW): a tilt of about 32°, under the limit; continuous depth; the rule off.
    assert_eq!(p.for_steps(&stepped_plane(1.0), &Camera::ABW0), p);
    let continuous = Grid::from_fn(120, 100, |x, y| 60.0 + 0.35 * x as f32 + 0.01 * ((x * y) % 7) as f32);
    assert_eq!(p.for_steps(&continuous, &Camera::ABW0), p);
    let off = Params { step_tilt: 0.0, ..p.clone() };
    assert_eq!(off.for_steps(&stepped_plane(3.0), &Camera::ABW0), off);
}

#[test]
fn a_plane_in_coarse_steps_grows_as_one_region() {
    // Without the raised limits the terraces' 5 × 5 normals (flat on a terrace, steep across its edge) and the
    // 3.8-unit steps between terraces stop growth at every terrace edge.
    let range = stepped_plane(3.0);
    let feats = features::compute(&range, &features::Params::default());
    let largest = |p: &Params| {
        let (seg, _) = grow(&range, &feats, &Camera::ABW0, p, 1);
        let mut counts = std::collections::BTreeMap::new();
        for &l in seg.labels.as_slice().iter().filter(|&&l| l != 0) {
            *counts.entry(l).or_insert(0usize) += 1;
        }
        counts.values().copied().max().unwrap_or(0) as f64 / range.len() as f64
    };
    let on = largest(&small_params());
    let off = largest(&Params { step_tilt: 0.0, ..small_params() });
    assert!(on > 0.95, "with the step limits the largest region holds {on} of the plane");
    assert!(off < 0.5, "without, {off}");
}

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
    let out = rangeseg::segment(&range, &camera, &Config::default());
    assert!(out.fin.edges().as_slice().iter().any(|&b| b), "the scene has several final regions");
    // C holds exactly the region pixels with a 4-neighbour in another region, and the unlabelled
    // pixels between two regions.
    for (x, y, &l) in out.fin.labels.enumerate() {
        let nb: Vec<u32> = [(1i64, 0i64), (-1, 0), (0, 1), (0, -1)]
            .iter()
            .filter_map(|&(dx, dy)| out.fin.labels.get_signed(i64::from(x) + dx, i64::from(y) + dy).copied())
            .filter(|&m| m != 0)
            .collect();
        let want = if l != 0 { nb.iter().any(|&m| m != l) } else { nb.iter().any(|&m| m != nb[0]) };
        assert_eq!(out.fin.edges()[(x, y)], want, "pixel ({x}, {y}), label {l}, neighbours {nb:?}");
    }
    let mut relaxed = Config::default();
    relaxed.pipeline.final_edges = rangeseg::FinalEdges::Relaxed;
    let out = rangeseg::pipeline::finish(&range, &camera, &relaxed, &out.features, &out.regions, &out.canny);
    assert_eq!(out.edges(), &out.relaxed.edges, "relaxed: C is C1 ∪ the supported relaxed C2");
}

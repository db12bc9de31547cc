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

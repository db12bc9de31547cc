//! The `rangeseg` binary end to end: segment writes outputs, score reads them back, and the numbers match
//! what the evaluation computes in memory.

use rangeseg::Config;
use std::path::Path;
use std::process::Command;

fn rangeseg(args: &[&std::ffi::OsStr]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_rangeseg")).args(args).output().expect("rangeseg runs")
}

#[test]
fn score_of_written_outputs_equals_in_memory_scores() {
    let dir = tempfile::tempdir().unwrap();
    let scene = crate::small_scene(7);
    let range_path = dir.path().join("abw.train.0.range");
    let gt_path = dir.path().join("abw.train.0.gt-seg");
    let ang_path = dir.path().join("abw.train.0.gt-ang");
    let range = crate::range_of(&scene);
    rangeio::abw::write_range(&range_path, &range).unwrap();
    rangeio::abw::write_labels(&gt_path, &scene.labels).unwrap();
    let angles: Vec<_> = scene
        .angles
        .iter()
        .map(|&(a, b, angle_deg)| rangeio::abw::AdjacentAngle { a, b, angle_deg })
        .collect();
    rangeio::abw::write_angles(&ang_path, &angles).unwrap();

    let out_dir = dir.path().join("out");
    let o = rangeseg(&["segment".as_ref(), range_path.as_os_str(), "-o".as_ref(), out_dir.as_os_str()]);
    assert!(o.status.success(), "segment failed: {}", String::from_utf8_lossy(&o.stderr));
    for ext in ["ms-seg", "ms-nor", "edges.png", "c1.png", "c2.png", "regions.png", "json", "planes.json"] {
        assert!(out_dir.join(format!("abw.train.0.{ext}")).is_file(), "missing output .{ext}");
    }

    let seg = out_dir.join("abw.train.0.ms-seg");
    let edges = out_dir.join("abw.train.0.edges.png");
    let o = rangeseg(&[
        "score".as_ref(),
        "--gt".as_ref(),
        gt_path.as_os_str(),
        "--seg".as_ref(),
        seg.as_os_str(),
        "--edges".as_ref(),
        edges.as_os_str(),
        "--json".as_ref(),
    ]);
    assert!(o.status.success(), "score failed: {}", String::from_utf8_lossy(&o.stderr));
    let json: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();

    // The same numbers, in memory, as `cargo xtask eval` computes them.
    let gt = rangeio::abw::read_labels(&gt_path, true).unwrap();
    let frame = rangeio::read(&range_path, &Default::default()).unwrap();
    let out = rangeseg::segment(&frame.range, &frame.camera, &Config::default());
    let planes = rangeseg::planes(&frame.range, &out.fin.labels, &frame.camera);
    let want = serde_json::json!({ "camera": frame.camera, "planes": planes });
    let text = std::fs::read_to_string(out_dir.join("abw.train.0.planes.json")).unwrap();
    assert_eq!(text, serde_json::to_string_pretty(&want).unwrap());
    assert_eq!(planes.len(), out.fin.final_regions.len());
    let h = rangeseg::evaluate::hoover(&gt, &out.fin.labels, &out.fin.final_regions, &scene.angles);
    let e = rangeseg::evaluate::score_edges(out.fin.edges(), &out.regions.c1, &gt);
    let hj = &json["hoover"];
    assert_eq!(hj["gt_regions"], h.gt_regions);
    assert_eq!(hj["correct"], h.correct);
    assert_eq!(hj["over"], h.over);
    assert_eq!(hj["under"], h.under);
    assert_eq!(hj["missed"], h.missed);
    assert_eq!(hj["noise"], h.noise);
    let close = |j: &serde_json::Value, v: f64| (j.as_f64().unwrap() - v).abs() < 1e-4;
    if let Some(a) = h.angle_error_deg {
        assert!(close(&hj["angle_error_deg"], a), "angle {} vs {a}", hj["angle_error_deg"]);
    }
    let m = &json["boundary"]["matched"];
    assert!(close(&m["precision"], e.matched.precision) && close(&m["recall"], e.matched.recall));
    assert!(close(&m["f"], e.matched.f));
    assert!(close(&json["boundary"]["simple"]["f"], e.simple.f));
}

#[test]
fn segment_reports_a_bad_file_and_finishes_the_rest() {
    let dir = tempfile::tempdir().unwrap();
    let good = dir.path().join("abw.train.1.range");
    let scene = crate::small_scene(2);
    rangeio::abw::write_range(&good, &crate::range_of(&scene)).unwrap();
    let bad = dir.path().join("broken.range");
    std::fs::write(&bad, [0x59, 0xa6, 0x6a, 0x95, 0, 0]).unwrap();
    let out_dir = dir.path().join("out");
    let o = rangeseg(&[
        "segment".as_ref(),
        bad.as_os_str(),
        good.as_os_str(),
        "-o".as_ref(),
        out_dir.as_os_str(),
    ]);
    assert!(!o.status.success());
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(stderr.contains("broken.range"), "{stderr}");
    assert!(out_dir.join("abw.train.1.ms-seg").is_file());
    assert!(!Path::new(&out_dir.join("broken.ms-seg")).exists());
}

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
    for ext in [
        "ms-seg",
        "ms-nor",
        "labels.png",
        "edges.png",
        "c1.png",
        "c2.png",
        "regions.png",
        "json",
        "planes.json",
    ] {
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

fn stderr_of(o: &std::process::Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Writes a small benchmark scene as an ABW range file at `path`.
fn write_scene(path: &Path, index: u32) {
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    rangeio::abw::write_range(path, &crate::range_of(&crate::small_scene(index))).unwrap();
}

#[test]
fn inputs_with_one_stem_are_refused_before_any_work() {
    let dir = tempfile::tempdir().unwrap();
    let (a, b) = (dir.path().join("d1/x.range"), dir.path().join("d2/x.range"));
    write_scene(&a, 1);
    write_scene(&b, 2);
    let out = dir.path().join("o");
    let o = rangeseg(&["segment".as_ref(), a.as_os_str(), b.as_os_str(), "-o".as_ref(), out.as_os_str()]);
    assert!(!o.status.success());
    let e = stderr_of(&o);
    assert!(e.contains(&*a.to_string_lossy()) && e.contains(&*b.to_string_lossy()), "{e}");
    assert!(!out.exists(), "nothing written");
}

#[test]
fn segment_skips_its_own_outputs_when_run_twice_on_a_folder() {
    let dir = tempfile::tempdir().unwrap();
    write_scene(&dir.path().join("abw.train.1.range"), 1);
    for _ in 0..2 {
        let o =
            rangeseg(&["segment".as_ref(), dir.path().as_os_str(), "-o".as_ref(), dir.path().as_os_str()]);
        assert!(o.status.success(), "{}", stderr_of(&o));
    }
    let mut jsons: Vec<String> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".json"))
        .collect();
    jsons.sort();
    assert_eq!(jsons, ["abw.train.1.json", "abw.train.1.planes.json"]);
}

#[test]
fn output_paths_are_checked_before_the_pipeline() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("abw.train.1.range");
    write_scene(&input, 1);
    // `-o FILE`: not a directory.
    let file = dir.path().join("plain-file");
    std::fs::write(&file, b"x").unwrap();
    let o = rangeseg(&["segment".as_ref(), input.as_os_str(), "-o".as_ref(), file.as_os_str()]);
    assert!(!o.status.success());
    let e = stderr_of(&o);
    assert!(e.contains("plain-file: not a directory"), "{e}");
    // An output folder nobody can write into (even root) is refused before reading a bad input.
    if Path::new("/proc/1").is_dir() {
        let bad = dir.path().join("broken.range");
        std::fs::write(&bad, b"not a range file").unwrap();
        let o = rangeseg(&["segment".as_ref(), bad.as_os_str(), "-o".as_ref(), "/proc/1".as_ref()]);
        let e = stderr_of(&o);
        assert!(!o.status.success() && e.contains("/proc/1: cannot write into the output folder"), "{e}");
        assert!(!e.contains("broken.range"), "the output folder is checked first: {e}");
    }
    // `render` and `edges` create the folder of their output file, like `segment`.
    for cmd in ["render", "edges"] {
        let out = dir.path().join(format!("new/{cmd}/out.png"));
        let o = rangeseg(&[cmd.as_ref(), input.as_os_str(), "-o".as_ref(), out.as_os_str()]);
        assert!(o.status.success() && out.is_file(), "{cmd}: {}", stderr_of(&o));
    }
    // A configuration path that is a folder is reported once.
    let o = rangeseg(&[
        "segment".as_ref(),
        input.as_os_str(),
        "-o".as_ref(),
        dir.path().join("o").as_os_str(),
        "--config".as_ref(),
        dir.path().as_os_str(),
    ]);
    let e = stderr_of(&o);
    assert!(!o.status.success());
    assert_eq!(e.matches("directory").count(), 1, "{e}");
}

#[test]
fn pixel_cap_is_a_clear_error_and_raisable() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("abw.train.1.range");
    write_scene(&input, 1);
    let o = rangeseg(&["info".as_ref(), input.as_os_str(), "--max-pixels".as_ref(), "1000".as_ref()]);
    let e = stderr_of(&o);
    assert!(!o.status.success() && e.contains("abw.train.1.range") && e.contains("--max-pixels"), "{e}");
    let o = rangeseg(&["info".as_ref(), input.as_os_str(), "--max-pixels".as_ref(), "262144".as_ref()]);
    assert!(o.status.success(), "{}", stderr_of(&o));
}

#[test]
fn info_says_which_depth_is_a_staircase() {
    let dir = tempfile::tempdir().unwrap();
    let (noisy, stairs) = (dir.path().join("abw.train.1.range"), dir.path().join("abw.train.2.range"));
    write_scene(&noisy, 1);
    let (params, seed) = scenegen::family_image(scenegen::Family::Staircase, 1.33, false, 2);
    rangeio::abw::write_range(&stairs, &crate::range_of(&scenegen::generate(&params, seed))).unwrap();
    let o = rangeseg(&["info".as_ref(), noisy.as_os_str(), stairs.as_os_str()]);
    let out = String::from_utf8_lossy(&o.stdout).into_owned();
    assert!(o.status.success(), "{}", stderr_of(&o));
    let (a, b) = out.split_at(out.find("abw.train.2.range").expect("both files described"));
    assert!(a.contains("step 1.0000") && !a.contains("staircase"), "{out}");
    assert!(b.contains("step 4.0000; a staircase") && b.contains("dequantised"), "{out}");
}

#[test]
fn info_says_which_frame_is_a_staircase_of_its_inverse_depth() {
    // A room seen by a Kinect-like camera, its disparity hardly dithered (S = 0.5), and the same room exact.
    let dir = tempfile::tempdir().unwrap();
    let (stairs, exact) = (dir.path().join("stairs.png"), dir.path().join("exact.png"));
    for (path, strength) in [(&stairs, 0.5), (&exact, 0.0)] {
        let (params, seed) = scenegen::room_image(3, strength);
        rangeio::png::write_gray16_png(path, &scenegen::generate_room(&params, seed).depth).unwrap();
    }
    let o = rangeseg(&["info".as_ref(), exact.as_os_str(), stairs.as_os_str()]);
    let out = String::from_utf8_lossy(&o.stdout).into_owned();
    assert!(o.status.success(), "{}", stderr_of(&o));
    let (a, b) = out.split_at(out.find("stairs.png").expect("both files described"));
    assert!(!a.contains("staircase"), "{out}");
    assert!(b.contains("a staircase of its inverse depth") && b.contains("dequantised"), "{out}");
}

#[test]
fn info_hints_at_the_byte_order_of_16_bit_pgm() {
    // A tilted plane of 11-bit samples with a little noise (as NYU Depth v2's raw disparity), written in either
    // byte order.
    let dir = tempfile::tempdir().unwrap();
    let write = |name: &str, little: bool| {
        let path = dir.path().join(name);
        let mut bytes = b"P5\n64 48\n65535\n".to_vec();
        for y in 0..48u16 {
            for x in 0..64u16 {
                let v = 800 + 3 * x + 2 * y + (x * 7 + y * 13) % 5;
                bytes.extend(if little { v.to_le_bytes() } else { v.to_be_bytes() });
            }
        }
        std::fs::write(&path, bytes).unwrap();
        path
    };
    let (little, big) = (write("little.pgm", true), write("big.pgm", false));
    let info = |extra: &[&str], path: &std::path::Path| {
        let mut args = vec!["info"];
        args.extend_from_slice(extra);
        let mut args: Vec<&std::ffi::OsStr> = args.iter().map(std::ffi::OsStr::new).collect();
        args.push(path.as_os_str());
        let o = rangeseg(&args);
        assert!(o.status.success(), "{}", stderr_of(&o));
        String::from_utf8_lossy(&o.stdout).into_owned()
    };
    let out = info(&[], &little);
    assert!(
        out.contains("hint") && out.contains("times smoother") && out.contains("--pgm-little-endian reads"),
        "{out}"
    );
    for out in [info(&["--pgm-little-endian"], &little), info(&[], &big)] {
        assert!(!out.contains("hint"), "{out}");
    }
    let out = info(&["--pgm-little-endian"], &big);
    assert!(out.contains("hint") && out.contains("without --pgm-little-endian"), "{out}");
}

#[test]
fn regions_and_edges_write_what_segment_grows_and_detects() {
    // Two frames `segment` prepares before its stages run: a staircase, which it dequantises, and a Kinect-like
    // frame with `configs/fast.toml`, which it decimates. `regions` and `edges` must prepare them alike.
    let dir = tempfile::tempdir().unwrap();
    let stairs = dir.path().join("stairs.range");
    let (params, seed) = scenegen::family_image(scenegen::Family::Staircase, 1.33, false, 2);
    rangeio::abw::write_range(&stairs, &crate::range_of(&scenegen::generate(&params, seed))).unwrap();
    let hall = dir.path().join("hall.png");
    let (range, _, _) = crate::pipeline::hall_gt();
    let tum = range.map(|&z| if z.is_finite() { (f64::from(z) * 5000.0).round() as u16 } else { 0 });
    rangeio::png::write_gray16_png(&hall, &tum).unwrap();
    let fast = Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/fast.toml");
    let hall_args =
        ["--camera".as_ref(), "pinhole:525,525,319.5,239.5".as_ref(), "--config".as_ref(), fast.as_os_str()];
    for (input, stem, extra, prepared) in
        [(&stairs, "stairs", &[][..], "dequantised_step"), (&hall, "hall", &hall_args[..], "decimation")]
    {
        let (seg, reg, edges) =
            (dir.path().join("seg"), dir.path().join(stem), dir.path().join(format!("{stem}.png")));
        for (cmd, out) in [("segment", &seg), ("regions", &reg), ("edges", &edges)] {
            let mut args = vec![cmd.as_ref(), input.as_os_str(), "-o".as_ref(), out.as_os_str()];
            args.extend_from_slice(extra);
            let o = rangeseg(&args);
            assert!(o.status.success(), "{args:?}: {}", stderr_of(&o));
        }
        let json: serde_json::Value =
            serde_json::from_slice(&std::fs::read(seg.join(format!("{stem}.json"))).unwrap()).unwrap();
        let done = &json[prepared];
        assert!(done.as_f64().is_some_and(|v| v > 1.0), "{stem}: {prepared} {done}");
        let read = |p: &Path| rangeio::png::read_edge_png(p).unwrap();
        let differ = |a: &rangeimage::EdgeMap, b: &rangeimage::EdgeMap| {
            a.as_slice().iter().zip(b.as_slice()).filter(|(x, y)| x != y).count()
        };
        let c1 = read(&seg.join(format!("{stem}.c1.png")));
        assert!(c1.as_slice().iter().filter(|&&e| e).count() > 500, "{stem}: the frame has region borders");
        assert_eq!(
            differ(&read(&reg.join(format!("{stem}.c1.png"))), &c1),
            0,
            "{stem}: C1 pixels that differ"
        );
        let c2 = read(&seg.join(format!("{stem}.c2.png")));
        assert_eq!(differ(&read(&edges), &c2), 0, "{stem}: C2 pixels that differ");
    }
}

/// A 512² checkerboard of 30-px cells, each a plane of its own tilt: more regions than `.ms-seg` holds.
fn checkerboard() -> rangeimage::Grid<u16> {
    rangeimage::Grid::from_fn(512, 512, |x, y| {
        let (i, j) = (x / 30, y / 30);
        let (cx, cy) = (i as f64 * 30.0 + 14.5, j as f64 * 30.0 + 14.5);
        let a = [-2.0, 1.5, -1.0, 2.5][((i + 2 * j) % 4) as usize];
        let b = [1.0, -2.0, 2.0, -1.5][((3 * i + j) % 4) as usize];
        (3000.0 + 40.0 * f64::from((i + j) % 3) + a * (f64::from(x) - cx) + b * (f64::from(y) - cy)) as u16
    })
}

#[test]
fn regions_beyond_the_ms_seg_cap_are_reported_and_kept_in_the_labels_png() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("board.pgm");
    rangeio::pgm::write_pgm(&input, &checkerboard()).unwrap();
    let out = dir.path().join("o");
    let o = rangeseg(&["segment".as_ref(), input.as_os_str(), "-o".as_ref(), out.as_os_str()]);
    assert!(o.status.success(), "{}", stderr_of(&o));
    let json: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("board.json")).unwrap()).unwrap();
    let final_regions = json["regions_final"].as_u64().unwrap();
    assert!(final_regions > 246, "the scene must exceed the cap: {final_regions} regions");
    let dropped = json["regions_dropped_by_ms_seg_cap"].as_u64().unwrap();
    assert_eq!(dropped, final_regions - 246);
    assert!(json["px_dropped_by_ms_seg_cap"].as_u64().unwrap() > 0);
    let e = stderr_of(&o);
    assert!(e.contains("246") && e.contains("board.labels.png"), "a warning on stderr: {e}");
    // The 16-bit labels PNG keeps every region.
    let img = image::open(out.join("board.labels.png")).unwrap().into_luma16();
    let labels: std::collections::BTreeSet<u16> = img.pixels().map(|p| p.0[0]).filter(|&l| l != 0).collect();
    assert_eq!(labels.len() as u64, final_regions);
    // The pixels the cap dropped: labelled in the PNG, 0 in the `.ms-seg`.
    let ms = rangeio::abw::read_labels(&out.join("board.ms-seg"), false).unwrap();
    let lost = img.pixels().zip(ms.as_slice()).filter(|&(p, &m)| p.0[0] != 0 && m == 0).count() as u64;
    assert_eq!(json["px_dropped_by_ms_seg_cap"].as_u64(), Some(lost));
}

/// `NAME.json`, the file `segment` writes last for an image (not `NAME.planes.json`).
fn is_image_json(name: &str) -> bool {
    name.ends_with(".json") && !name.ends_with(".planes.json")
}

#[test]
fn interrupt_leaves_no_temporary_files_and_json_marks_complete_sets() {
    if !Path::new("/bin/kill").exists() && !Path::new("/usr/bin/kill").exists() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let inputs = dir.path().join("in");
    for k in 0..40 {
        write_scene(&inputs.join(format!("img{k:02}.range")), k % 10);
    }
    let out = dir.path().join("o");
    let mut child = Command::new(env!("CARGO_BIN_EXE_rangeseg"))
        .args([
            "segment".as_ref(),
            inputs.as_os_str(),
            "-o".as_ref(),
            out.as_os_str(),
            "-j".as_ref(),
            "2".as_ref(),
        ])
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // Interrupt once the first image is complete (or when the run has ended on its own).
    let json_count = || {
        std::fs::read_dir(&out).map_or(0, |d| {
            d.filter(|e| e.as_ref().is_ok_and(|e| is_image_json(&e.file_name().to_string_lossy()))).count()
        })
    };
    while json_count() == 0 && child.try_wait().unwrap().is_none() {
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    let ended_alone = child.try_wait().unwrap().is_some();
    Command::new("kill").args(["-INT", &child.id().to_string()]).status().unwrap();
    let o = child.wait_with_output().unwrap();
    let names: Vec<String> = std::fs::read_dir(&out)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert!(names.iter().all(|n| !n.contains(".tmp.")), "temporary files left: {names:?}");
    if !ended_alone {
        assert_eq!(o.status.code(), Some(130), "exit 128 + SIGINT: {}", stderr_of(&o));
    }
    for json in names.iter().filter(|n| is_image_json(n)) {
        let stem = json.trim_end_matches(".json");
        for ext in
            ["ms-seg", "ms-nor", "labels.png", "planes.json", "edges.png", "c1.png", "c2.png", "regions.png"]
        {
            assert!(names.contains(&format!("{stem}.{ext}")), "{stem} has a JSON but no .{ext}");
        }
    }
}

#[test]
fn nyu_grey_reads_the_inverted_rendering_with_the_kinect_camera() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("nyu.7.pgm");
    std::fs::write(&input, b"P5\n2 1\n255\n\x00\x64").unwrap();
    let o = rangeseg(&["info".as_ref(), input.as_os_str(), "--nyu-grey".as_ref()]);
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{}", stderr_of(&o));
    assert!(
        out.contains("370 − stored value") && out.contains("pinhole") && out.contains("270.0000"),
        "{out}"
    );
    let o =
        rangeseg(&["info".as_ref(), input.as_os_str(), "--nyu-grey".as_ref(), "--nyu-disparity".as_ref()]);
    assert!(!o.status.success(), "--nyu-grey excludes --nyu-disparity");
}

#[test]
fn a_closed_stdout_is_no_panic() {
    // `rangeseg config | head -c 0`: the pipe's reader is gone before anything is written.
    let (reader, writer) = std::io::pipe().unwrap();
    drop(reader);
    let o = Command::new(env!("CARGO_BIN_EXE_rangeseg")).arg("config").stdout(writer).output().unwrap();
    let e = stderr_of(&o);
    assert!(o.status.success() && !e.contains("panicked"), "{}: {e}", o.status);
}

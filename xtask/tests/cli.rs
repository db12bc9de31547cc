//! The `xtask` binary end to end: `gen-data`, then `eval` on the folder it wrote, and `eval`'s errors.
//!
//! `.ci/run` runs the evaluations with the binary this test target makes Cargo build (`target/debug/xtask`).

use std::path::Path;
use std::process::{Command, Output};

/// Runs the `xtask` binary of this build with `args`.
fn xtask(args: &[&Path]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_xtask")).args(args).output().expect("the xtask binary runs")
}

/// `output`'s stderr as text.
fn stderr(output: &Output) -> String {
    String::from_utf8_lossy(&output.stderr).into_owned()
}

#[test]
fn eval_scores_every_test_image_of_a_generated_benchmark() {
    let dir = tempfile::tempdir().expect("temporary folder");
    let (data, out) = (dir.path().join("data"), dir.path().join("eval"));
    let generated = xtask(&[Path::new("gen-data"), Path::new("--out"), &data]);
    assert!(generated.status.success(), "gen-data failed: {}", stderr(&generated));
    let eval = xtask(&[Path::new("eval"), Path::new("--data"), &data, Path::new("--out"), &out]);
    assert!(eval.status.success(), "eval failed: {}", stderr(&eval));

    let csv = std::fs::read_to_string(out.join("results.csv")).expect("results.csv");
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().expect("a header").split(',').collect();
    let column = |name: &str| header.iter().position(|&h| h == name).unwrap_or_else(|| panic!("no {name}"));
    let (image, gt, correct, over, missed) =
        (column("image"), column("gt_regions"), column("correct"), column("over"), column("missed"));
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    // A folder of ABW names gives its test split: the 30 test images, in order.
    let stems: Vec<&str> = rows.iter().map(|r| r[image]).collect();
    let expected: Vec<String> = (0..30).map(|i| format!("abw.test.{i}")).collect();
    assert_eq!(stems, expected);
    let count = |row: &[&str], k: usize| -> u32 { row[k].parse().expect("a count") };
    let (mut all_gt, mut all_correct) = (0, 0);
    for row in &rows {
        // Each GT region is at most one of correct, over-segmented and missed.
        assert!(count(row, correct) + count(row, over) + count(row, missed) <= count(row, gt), "{row:?}");
        all_gt += count(row, gt);
        all_correct += count(row, correct);
    }
    // The pipeline ran for real: the default finds about 95 % of these regions (docs/results.md).
    assert!(all_correct * 10 >= all_gt * 8, "{all_correct} of {all_gt} GT regions correct");

    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("results.json")).expect("results.json"))
            .expect("results.json is JSON");
    assert_eq!(json.as_array().map(Vec::len), Some(30));
    for report in ["report.md", "report.html"] {
        let text = std::fs::read_to_string(out.join(report)).expect(report);
        assert!(text.contains("abw.test.29"), "{report} lists every image");
    }
}

#[test]
fn eval_of_a_missing_folder_names_it_and_writes_nothing() {
    let dir = tempfile::tempdir().expect("temporary folder");
    let (missing, out) = (dir.path().join("no-such-folder"), dir.path().join("eval"));
    let eval = xtask(&[Path::new("eval"), Path::new("--data"), &missing, Path::new("--out"), &out]);
    assert!(!eval.status.success());
    assert!(stderr(&eval).contains(&missing.display().to_string()), "{}", stderr(&eval));
    assert!(!out.exists(), "no output folder after an error");
}

#[test]
fn eval_rejects_an_unknown_option_with_its_usage() {
    let eval = xtask(&[Path::new("eval"), Path::new("--bogus")]);
    assert!(!eval.status.success());
    let text = stderr(&eval);
    assert!(text.contains("unknown option --bogus") && text.contains("usage: cargo xtask eval"), "{text}");
}

//! `abort_writes` (its own test binary: it blocks every later write of the process).

use std::path::Path;

#[test]
fn abort_removes_temporary_files_in_flight_and_blocks_later_writes() {
    let dir = std::env::temp_dir().join(format!("rangeio-abort-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let done = dir.join("done.bin");
    rangeio::write_atomic(&done, b"complete").unwrap();

    // A writer that is still writing when the abort comes: a large file written in a thread.
    let big = dir.join("big.bin");
    let writer = {
        let big = big.clone();
        std::thread::spawn(move || rangeio::write_atomic(&big, &vec![7u8; 64 << 20]))
    };
    // Wait until its temporary file exists (or the write has finished).
    let tmp_exists = |d: &Path| {
        std::fs::read_dir(d).unwrap().any(|e| e.unwrap().file_name().to_string_lossy().contains(".tmp."))
    };
    while !tmp_exists(&dir) && !writer.is_finished() {
        std::thread::yield_now();
    }
    let removed = rangeio::abort_writes();
    let result = writer.join().unwrap();
    assert!(removed == 1 || result.is_ok(), "the write in flight was removed, or had completed");
    if removed == 1 {
        let e = result.unwrap_err().to_string();
        assert!(e.starts_with(&format!("{}: ", big.display())), "{e}");
        assert!(!big.exists());
    }

    // Later writes fail, naming the file, and create nothing.
    let later = dir.join("later.bin");
    let e = rangeio::write_atomic(&later, b"x").unwrap_err().to_string();
    assert!(e.starts_with(&format!("{}: ", later.display())) && e.contains("interrupted"), "{e}");
    let names: Vec<String> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert!(!names.iter().any(|n| n.contains(".tmp.")), "{names:?}");
    assert_eq!(std::fs::read(&done).unwrap(), b"complete", "completed outputs are kept");
    assert_eq!(rangeio::abort_writes(), 0);
    std::fs::remove_dir_all(&dir).unwrap();
}

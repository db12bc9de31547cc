//! `cargo xtask`: project automation (gen-data, tune, eval, tidy).

use xtask::{USAGE, gen_data};

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    match args.first().map(String::as_str) {
        Some("gen-data") => gen_data::run(&args[1..]),
        _ => anyhow::bail!("{USAGE}"),
    }
}

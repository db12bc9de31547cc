//! `cargo xtask`: project automation (gen-data, tune, eval, tidy).

fn main() -> anyhow::Result<()> {
    anyhow::bail!("usage: cargo xtask <gen-data|tune|eval|tidy>")
}

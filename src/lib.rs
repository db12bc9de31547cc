//! rangeseg: range image segmentation by cooperative relaxation (Belloum et al., 2024).
//!
//! The facade crate: it re-exports the pipeline stages and holds the configuration that ties them.

pub use {eval, features, rangeimage, rangeio, regiongrow, relax, vcanny};

#![doc = include_str!("../README.md")]

//! The facade crate: it re-exports the pipeline stages and holds the configuration that ties them.

pub mod config;
pub mod decimate;
pub mod dequantise;
pub mod evaluate;
pub mod output;
pub mod pipeline;
pub mod planes;
pub mod units;

pub use config::{C1Strength, Config, ConfigError, FinalEdges, PipelineParams, RawCannyParams};
pub use output::{OutputSet, write_outputs, write_selected_outputs};
pub use pipeline::{Output, segment};
pub use planes::{Plane, planes};
pub use {eval, features, finalseg, isa, rangeimage, rangeio, regiongrow, relax, vcanny};

//! Edge and region metrics: paper precision, boundary P/R/F, Hoover et al. region metrics.

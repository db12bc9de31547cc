//! Deterministic ABW-like synthetic range scenes with ground truth.

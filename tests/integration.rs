//! Integration tests of the rangeseg workspace.

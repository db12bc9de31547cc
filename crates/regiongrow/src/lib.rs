//! Multi-seed region growing with a curvature homogeneity criterion, and region borders C1.

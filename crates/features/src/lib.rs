//! Per-pixel local planes, derivatives and curvatures of a range image.

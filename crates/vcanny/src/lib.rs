//! Canny edge detection on vector fields (plane parameters) with the Di Zenzo tensor.

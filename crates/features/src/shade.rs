//! Lambertian shading of a range image for figures (the paper's Fig. 2a).

use rangeimage::{Grid, PlaneMap};

/// Shades the surface with normals from the local planes, light from the viewer's upper left; no data is black.
pub(crate) fn shade_planes(plane: &PlaneMap) -> Grid<u8> {
    // Image frame: x right, y down, z away from the viewer. The normal facing the viewer of z = a·x + b·y + c is
    // (a, b, −1)/‖·‖; the light comes from the upper left and from the viewer's side.
    let l = {
        let l = [-1.0f32, -1.0, -1.5];
        let n = (l[0] * l[0] + l[1] * l[1] + l[2] * l[2]).sqrt();
        [l[0] / n, l[1] / n, l[2] / n]
    };
    plane.map(|&[a, b, _]| {
        if !(a.is_finite() && b.is_finite()) {
            return 0;
        }
        let n = (a * a + b * b + 1.0).sqrt();
        let lambert = ((a * l[0] + b * l[1] - l[2]) / n).max(0.0);
        // Ambient term keeps surfaces facing away distinguishable from no data.
        (1.0 + 254.0 * (0.15 + 0.85 * lambert)).round().clamp(1.0, 255.0) as u8
    })
}

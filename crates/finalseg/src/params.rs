//! The `[segment]` parameters of the final segmentation.

use rangeimage::ParamError;

/// How [`segment`](crate::segment) forms its regions.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Mode {
    /// The specification taken literally: connected components of valid non-edge pixels, filled by best plane.
    Components,
    /// Components that also never cross a region-growing border, then adjacent regions merged
    /// where the relaxed edges do not support their border and their planes agree.
    Regions,
}

/// The `[segment]` parameters of [`segment`](crate::segment).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    /// Region formation (`regions` needs the region-growing labels; without them it falls back
    /// to `components`).
    pub mode: Mode,
    /// Connected components (of core pixels) smaller than this are dropped (their pixels are
    /// then filled from adjacent regions like edge pixels). The default equals region growing's
    /// `min_region_px`: a piece cut off by edges needs the support a grown region needs.
    pub min_region_px: u32,
    /// Core pixels, whose components seed the regions, are the valid pixels farther than this
    /// from every edge pixel (Euclidean); 0 = every non-edge pixel. A positive value closes gaps
    /// up to about twice as wide in the edge contours, which Canny edges and pruned borders have,
    /// but also drops the thin strips between parallel C1 and C2 lines and leaves every pixel of the
    /// margin to the plane-residual fill; in `regions` mode the region-growing borders already
    /// close the contours, and 0 scores better on the synthetic, real ABW and NYU images.
    pub gap_close_px: f64,
    /// `regions` mode: pixels that region growing left unlabelled (0) may be core pixels too,
    /// connected only among themselves (so faces region growing missed can still be found);
    /// `false` = they are only filled from adjacent regions.
    pub unlabelled_core: bool,
    /// `regions` mode: two adjacent regions may merge only if less than this fraction of their
    /// border pixels lie within 1 px (8-neighbourhood) of an edge pixel. In 0..=1.
    pub min_border_support: f64,
    /// `regions` mode: two adjacent pieces of one region-growing region merge when their planes
    /// agree, however strongly the edges support the border between them (edges inside a face
    /// must not split it; a split needs a change of plane). `false` = only weakly supported
    /// borders are merge candidates.
    pub merge_within_region: bool,
    /// `regions` mode, `merge_within_region`: two pieces of one region-growing region over a
    /// supported border merge only if the RMS distance of each one's core points to the other's
    /// plane is at most this multiple of its RMS distance to its own plane (they lie on one plane
    /// within noise; a small step between parallel faces is a real border). ≥ 1.
    pub within_max_rms_ratio: f64,
    /// `regions` mode, `merge_within_region`: such pieces also merge if the plane fitted to both explains each
    /// one's core points within this multiple of its own RMS and their planes lie within the larger RMS of each
    /// other halfway between the pieces' centroids (0 = off).
    pub within_joint_rms_ratio: f64,
    /// `regions` mode, `merge_within_region`: two pieces of one region-growing region that come within this many
    /// pixels (Chebyshev) of each other across valid unlabelled pixels are merge candidates too, as if adjacent
    /// (0 = off): a thin face seen edge-on that an edge crosses, whose pieces the fill leaves apart.
    pub within_close_px: u32,
    /// `regions` mode: largest angle between the two regions' 3D plane normals for a merge.
    pub merge_max_angle_deg: f64,
    /// `regions` mode: largest RMS distance of each region's core points to the other region's
    /// plane for a merge, in sensor units (ABW: about 1.3 units per range step).
    pub merge_max_residual: f64,
    /// Largest 3D distance of a filled pixel to the plane of the region it joins, in sensor units
    /// (0 = no limit, the specification taken literally). Farther pixels stay 0, so a small face that region growing
    /// dropped is not swallowed by its neighbour (which would make that neighbour an
    /// under-segmentation of both).
    pub fill_max_residual: f64,
    /// With `fill_max_residual` > 0, the limit of a region is the larger of `fill_max_residual` and this
    /// multiple of the RMS distance of its core points to its plane (0 = `fill_max_residual` alone): a surface
    /// a plane fits only roughly (8-bit staircases, depth encodings that bend planes) keeps its pixels.
    pub fill_rms_ratio: f64,
    /// Passes of border refinement after the merge: a pixel on a region border that its own plane
    /// does not explain (farther than one noise scale) moves to the adjacent region whose plane
    /// fits it better (a Potts energy: squared distance in noise units plus a cost per disagreeing
    /// neighbour; within the fill limit). A border moves at most one pixel per pass; 0 = off
    /// (borders stay where growth and edges put them, the specification taken literally).
    pub refine_passes: u32,
    /// `refine_passes` > 0: a plane whose normal makes a cosine under this with a border pixel's line of sight has
    /// the pixel's distance to it and its RMS scaled up by `refine_steep_cos / cosine` (at most 5 times) in the
    /// refinement's energy, toward their length along the line of sight, where range noise lies; otherwise the
    /// pixels beside a face seen almost edge-on fit its plane within the noise whatever their depth (0 = off).
    pub refine_steep_cos: f64,
    /// `regions` mode: two adjacent regions whose planes meet along their border (a bend of one
    /// surface, not a step: the mean distance of the border pixels to the other region's plane is
    /// below `bend_max_gap` times the regions' scatter) merge, whatever the edges, if their normals differ by at most this
    /// and one plane fits both within `merge_max_residual` (RMS). A wall that the depth encoding
    /// bends (8-bit inverse depth) is split by region growing into pieces that fail the plane
    /// tests above; 0 = off.
    pub bend_max_angle_deg: f64,
    /// `regions` mode, `bend_max_angle_deg` > 0: a bend merge needs the mean distance of the border
    /// pixels of two regions to each other's plane below this multiple of the larger of the two
    /// regions' RMS distances to their own planes (their scatter: noise, quantisation, bending).
    pub bend_max_gap: f64,
    /// `regions` mode, `bend_max_angle_deg` > 0: a bend whose normals differ by more than
    /// `bend_max_angle_deg` still merges if the joint plane explains each of the two regions within
    /// this multiple of the larger of their own RMS residuals (the regions' own normals are unreliable:
    /// thin terraces of a quantised slope); 0 = off.
    pub bend_fit_ratio: f64,
    /// `regions` mode, `bend_max_angle_deg` > 0, depth rounded to steps: when one of two adjacent regions is a single
    /// terrace (its depths spread by less than half the rounding error of one step, `|Δq| / √12`, with `|Δq|` the
    /// step's 3D length at the image centre), their border may lie this many steps `|Δq|` farther (mean gap) from the
    /// other's plane than `bend_max_gap` allows: a terrace meets the next piece of its slope on a riser (0 = off).
    pub terrace_gap_steps: f64,
    /// Passes placing the pixels beside a crease (0 = off): where two adjacent regions meet at a crease (their
    /// normals more than `crease_min_angle_deg` apart, each region behind the other's plane or each in front), a
    /// border pixel within the noise of both planes goes to the region whose plane its line of sight sees (at a
    /// convex crease the plane it meets last, at a concave one the plane it meets first), one pixel per pass.
    pub crease_passes: u32,
    /// Smallest angle between two regions' normals for `crease_passes` to place their common border.
    pub crease_min_angle_deg: f64,
    /// Largest angle between two adjacent regions' normals for a band of one on the other's plane (a connected part
    /// nearer that plane than its own, which the two planes' fits over the whole band assign to it) to move whole,
    /// after the border refinement (0 = off): growth leaked past a shallow crease.
    pub band_max_angle_deg: f64,
    /// A region's pixels farther than this many noise scales (its RMS about its plane, at least 0.25 units) from its
    /// plane, in 4-connected groups of at least `outlier_min_px`, are left unlabelled: a small face seen edge-on that
    /// no region of its own holds, an object on a wall, the mixed pixels of a jump (0 = off).
    pub outlier_scales: f64,
    /// Smallest group of outlier pixels that `outlier_scales` leaves unlabelled (smaller groups are noise and stay).
    pub outlier_min_px: u32,
    /// Two adjacent regions whose normals are at most `curved_max_angle_deg` apart merge, last, when the least-squares
    /// quadric of their union fits it within this multiple of their plane RMS residuals pooled over their pixels (at
    /// least 0.25 units) and within `merge_max_residual`: one surface that a depth encoding bends, cut along folds
    /// that are not there (0 = off).
    pub curved_merge_ratio: f64,
    /// Largest angle between two regions' normals for `curved_merge_ratio`.
    pub curved_max_angle_deg: f64,
    /// Last, a 4-connected group of valid unlabelled pixels, from this many pixels up to under `min_region_px`, that
    /// lies on one plane of its own between at least two regions becomes a region (0 = off): a face too small or too
    /// thin for a region to grow in (docs/method.md, the final segmentation's step 9).
    pub small_face_min_px: u32,
    /// `small_face_min_px` > 0: a pixel lies on the group's plane within this many noise scales (the largest RMS of the
    /// regions beside the group, at least 0.25 units); three quarters of the group must, and the plane's RMS must be
    /// within one noise scale.
    pub small_face_scales: f64,
    /// `small_face_min_px` > 0: smallest RMS distance of the face's points to each neighbour's plane, in noise scales
    /// (a terrace of a quantised slope lies within a few noise scales of the slope's plane).
    pub small_face_min_gap: f64,
    /// `small_face_min_px` > 0: largest angle between the face's normal and the line of sight (a plane seen more
    /// nearly edge-on is the ramp of mixed pixels at a jump; region growing's `max_slant_deg` by default).
    pub small_face_max_slant_deg: f64,
    /// `small_face_min_px` > 0: a face then takes, ring by ring out to this many pixels from it, the pixels of the
    /// regions beside it that its plane explains within `small_face_scales` noise scales and better than their own
    /// region's plane by `small_face_grow_margin` noise scales: the part of the face that a neighbour's fill took, within
    /// its fill limit, before the face existed (0 = off).
    pub small_face_grow_px: u32,
    /// `small_face_grow_px` > 0: how much nearer a pixel must lie to the face's plane than to its own region's, in noise
    /// scales.
    pub small_face_grow_margin: f64,
}

impl Default for Params {
    fn default() -> Self {
        Self {
            mode: Mode::Regions,
            min_region_px: 200,
            gap_close_px: 0.0,
            unlabelled_core: true,
            min_border_support: 0.3,
            merge_within_region: true,
            within_max_rms_ratio: 1.5,
            within_joint_rms_ratio: 1.1,
            within_close_px: 8,
            merge_max_angle_deg: 10.0,
            merge_max_residual: 3.0,
            fill_max_residual: 4.0,
            fill_rms_ratio: 2.0,
            refine_passes: 10,
            refine_steep_cos: 0.3,
            bend_max_angle_deg: 30.0,
            bend_max_gap: 1.5,
            bend_fit_ratio: 2.0,
            terrace_gap_steps: 1.0,
            crease_passes: 3,
            crease_min_angle_deg: 20.0,
            band_max_angle_deg: 45.0,
            outlier_scales: 2.25,
            outlier_min_px: 10,
            curved_merge_ratio: 1.1,
            curved_max_angle_deg: 15.0,
            small_face_min_px: 40,
            small_face_scales: 2.5,
            small_face_min_gap: 4.0,
            small_face_max_slant_deg: 80.0,
            small_face_grow_px: 8,
            small_face_grow_margin: 0.25,
        }
    }
}

impl Params {
    /// The most regions a frame of `px` pixels can end with: one per `min_region_px` pixels, or per
    /// `small_face_min_px` pixels where small faces are made (the per-region vectors reserve this many once).
    pub fn most_regions(&self, px: usize) -> usize {
        let smallest = match self.small_face_min_px {
            0 => self.min_region_px,
            f => f.min(self.min_region_px),
        };
        px / smallest.max(1) as usize + 1
    }

    /// Checks the values; the error names the offending field.
    pub fn validate(&self) -> Result<(), ParamError> {
        if self.min_region_px == 0 {
            return Err(ParamError::new("segment.min_region_px", "must be ≥ 1"));
        }
        ParamError::in_range("segment.gap_close_px", self.gap_close_px, 0.0, 64.0)?;
        ParamError::in_range("segment.min_border_support", self.min_border_support, 0.0, 1.0)?;
        ParamError::at_least("segment.within_max_rms_ratio", self.within_max_rms_ratio, 1.0)?;
        ParamError::at_least("segment.within_joint_rms_ratio", self.within_joint_rms_ratio, 0.0)?;
        ParamError::in_range("segment.within_close_px", self.within_close_px, 0, 64)?;
        ParamError::in_range("segment.merge_max_angle_deg", self.merge_max_angle_deg, 0.0, 90.0)?;
        ParamError::at_least("segment.fill_max_residual", self.fill_max_residual, 0.0)?;
        ParamError::at_least("segment.fill_rms_ratio", self.fill_rms_ratio, 0.0)?;
        ParamError::at_least("segment.merge_max_residual", self.merge_max_residual, 0.0)?;
        ParamError::in_range("segment.bend_max_angle_deg", self.bend_max_angle_deg, 0.0, 90.0)?;
        ParamError::at_least("segment.bend_max_gap", self.bend_max_gap, 0.0)?;
        ParamError::at_least("segment.bend_fit_ratio", self.bend_fit_ratio, 0.0)?;
        ParamError::at_least("segment.terrace_gap_steps", self.terrace_gap_steps, 0.0)?;
        ParamError::in_range("segment.refine_steep_cos", self.refine_steep_cos, 0.0, 1.0)?;
        ParamError::in_range("segment.crease_min_angle_deg", self.crease_min_angle_deg, 0.0, 90.0)?;
        ParamError::in_range("segment.band_max_angle_deg", self.band_max_angle_deg, 0.0, 90.0)?;
        ParamError::at_least("segment.outlier_scales", self.outlier_scales, 0.0)?;
        if self.outlier_min_px == 0 {
            return Err(ParamError::new("segment.outlier_min_px", "must be ≥ 1"));
        }
        ParamError::at_least("segment.curved_merge_ratio", self.curved_merge_ratio, 0.0)?;
        ParamError::in_range("segment.curved_max_angle_deg", self.curved_max_angle_deg, 0.0, 90.0)?;
        ParamError::at_least("segment.small_face_scales", self.small_face_scales, 0.0)?;
        ParamError::at_least("segment.small_face_min_gap", self.small_face_min_gap, 0.0)?;
        ParamError::in_range("segment.small_face_max_slant_deg", self.small_face_max_slant_deg, 0.0, 90.0)?;
        ParamError::in_range("segment.small_face_grow_px", self.small_face_grow_px, 0, 64)?;
        ParamError::at_least("segment.small_face_grow_margin", self.small_face_grow_margin, 0.0)?;
        Ok(())
    }
}

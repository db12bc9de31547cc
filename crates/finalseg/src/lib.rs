//! The final segmentation (docs/method.md §3.4 step 4): regions from the relaxed edge map,
//! optionally guided by the region-growing labels and merged where the relaxed edges do not
//! support a border. One entry point, [`segment`]; its steps live in one module each
//! (`components`, `fill`, `merge`, `refine`, `band`, `crease`, `outliers`, `curved`, `faces`; the region planes in `plane`).

mod band;
mod components;
mod crease;
mod curved;
mod edges;
mod faces;
mod fill;
mod merge;
mod outliers;
mod params;
mod plane;
mod refine;

pub use edges::{PLANE_MARGIN, edge_labels_into};
pub use params::{Mode, Params};

use plane::{Plane, fit_plane};
use planefit::Moments;
use rangeimage::union_find::find;
use rangeimage::{Camera, EdgeMap, Grid, LabelImage, RangeImage, Region};

/// Labels the image from the final edge map `edges` (C = C1 ∪ C2).
///
/// 1. Core pixels: valid pixels farther than `gap_close_px` from every edge pixel (with 0, all
///    non-edge valid pixels); in `regions` mode with `unlabelled_core = false` also labelled
///    (≠ 0) in `regions`.
/// 2. 4-connected components of core pixels; in `regions` mode two neighbours connect only if
///    their region-growing labels are equal, so no component crosses a region-growing border
///    (but edges inside a region may split it). Components under `min_region_px` are dropped.
/// 3. Every remaining valid unlabelled pixel (edge pixels, the margin around them, dropped
///    components, pixels region growing left unlabelled) is given to the 8-adjacent region
///    whose plane fits its 3D point best, ring by ring outward from the regions (each ring
///    decided from the previous rings only, ties to the smaller label, so the result does not
///    depend on visiting order). A pixel farther than `fill_max_residual` (if > 0) from that
///    best plane when its ring comes stays 0 and passes the fill on no further. Valid pixels not
///    connected to any region stay 0; NaN pixels always stay 0.
/// 4. `regions` mode only: adjacent regions whose border is supported by C on less than
///    `min_border_support` of its pixels (a border pixel is supported if it is within 1 px,
///    8-neighbourhood, of an edge pixel) and whose planes agree (normal angle ≤
///    `merge_max_angle_deg`, RMS distance of each one's core points to the other's plane ≤
///    `merge_max_residual`) are merged: union-find over the adjacent pairs in sorted order,
///    planes refitted on merge, passes repeated until none merges (support is per original
///    pair; the plane test uses the current merged groups). With `merge_within_region`, two
///    adjacent pieces of one region-growing region (label ≠ 0) are candidates whatever the
///    support, if their planes agree as above and, for a supported border, each piece's RMS
///    distance to the other's plane is at most `within_max_rms_ratio` times its own RMS: edges
///    inside a face split it only where the geometry changes. With `within_joint_rms_ratio` > 0 such pieces
///    also merge if the plane fitted to both explains each one's core points within that ratio times its own
///    RMS and the two planes, halfway between the pieces' centroids, lie within the larger RMS of each other
///    (a thin piece's own plane strays when extrapolated; parallel faces at two depths stay apart). With
///    `within_close_px` > 0, two pieces of one region-growing region that come within that many pixels of each
///    other across valid unlabelled pixels are such candidates too (a thin face seen edge-on that an edge
///    crosses, whose pieces the fill leaves apart).
///    With `bend_max_angle_deg` > 0, two adjacent regions whose border pixels lie, on average,
///    closer to each other's plane than `bend_max_gap` times the larger of their RMS residuals
///    (the planes meet at the border: a bend, not a step) merge whatever the support, if their
///    normals differ by at most `bend_max_angle_deg` and one plane fits both within
///    `merge_max_residual` (RMS): one wall that the depth encoding bends. Normals farther apart still
///    merge if that joint plane fits each region within `bend_fit_ratio` times the larger of their
///    RMS residuals: a thin piece (a terrace of a quantised slope) whose own normal means nothing.
/// 5. Border refinement (`refine_passes` > 0): a border pixel farther than one noise scale
///    from its own region's plane moves to the adjacent region whose plane fits it better (a
///    Potts energy, so noise does not fray the border; within the fill limit), up to
///    `refine_passes` passes of one pixel each, every pass decided from the previous one: a
///    border that growth or an edge left off the crease moves to where the planes meet.
///    Then (step 5b, `band_max_angle_deg` > 0), by the planes refitted on the refined regions, a 4-connected part
///    of a region (at least 50 pixels, at most half the other region) whose pixels lie nearer an adjacent
///    region's plane than their own and within two noise scales of it, where the two normals are at most
///    `band_max_angle_deg` apart, moves to that region if the two planes' fits over the whole band favour it
///    (mean gain of at least one squared noise scale; the giving region's fit no worse without it, the
///    taking region's RMS grows by at most 5 %): a band that growth leaked past a shallow crease, which the
///    Potts cost of step 5 keeps pixel by pixel; then a refinement round against the planes refitted on them.
/// 6. Crease pixels (`crease_passes` > 0): where two adjacent regions meet at a crease (normals more
///    than `crease_min_angle_deg` apart; each region behind the other's plane, or each in front), a
///    border pixel within two noise scales of the other region's plane goes to the region whose plane
///    its line of sight sees (at a convex crease the plane it meets last, at a concave one the first),
///    by the planes refitted on the refined regions, up to `crease_passes` passes of one pixel each:
///    the distances cannot place pixels that lie within the noise of both planes, the planes can.
/// 7. Outliers (`outlier_scales` > 0): by the planes refitted on the regions as steps 5–6 left them, a
///    region's pixels farther than `outlier_scales` noise scales from its plane (its RMS, at least 0.25),
///    in 4-connected groups of at least `outlier_min_px`, become unlabelled: a small face seen edge-on
///    that no region of its own holds, an object on a wall, the mixed pixels of a jump.
/// 8. Curved merges (`regions` mode, `curved_merge_ratio` > 0): two adjacent regions whose normals are at most
///    `curved_max_angle_deg` apart merge when the least-squares quadric of their union (height over the union's
///    plane, quadratic in the two in-plane coordinates) fits it within `curved_merge_ratio` times the two regions'
///    plane RMS pooled over their pixels (at least 0.25), and within `merge_max_residual`: one surface that a depth
///    encoding bends, cut along folds that are not there. Edge support does not matter here: the edges split a
///    surface only where its geometry changes.
/// 9. Small faces (`small_face_min_px` > 0): a 4-connected group of valid unlabelled pixels, from `small_face_min_px`
///    up to under `min_region_px`, becomes a region if it borders at least two regions, half of its pixels have all
///    four neighbours in it, three quarters lie within `small_face_scales` noise scales of its plane (the largest RMS
///    of the regions beside it, at least 0.25) with that plane's RMS within one, its points lie farther than
///    `small_face_min_gap` noise scales (RMS) from every neighbour's plane, and its plane is seen at most
///    `small_face_max_slant_deg` from the line of sight: a face too small or too thin for a region to grow in. Each
///    face then takes, out to `small_face_grow_px` rings from its group, the pixels of the regions beside it that its
///    plane explains within `small_face_scales` noise scales and better than their own plane by
///    `small_face_grow_margin` noise scales: what the fill gave its neighbours of it before it existed.
///
/// `regions = None` makes `regions` mode behave as `components`.
///
/// Labels are consecutive from 1 in raster order of first appearance. Each [`Region`] carries
/// its final size, and the plane (unit normal toward the sensor, offset, RMS residual) fitted in
/// 3D through `camera.point` on its core pixels only (edge pixels include mixed pixels at jumps,
/// which would bias the fit). `mean_k` is `NaN`: curvature is not an input here.
///
/// # Panics
#[must_use]
pub fn segment(
    range: &RangeImage,
    camera: &Camera,
    edges: &EdgeMap,
    regions: Option<&LabelImage>,
    params: &Params,
) -> (LabelImage, Vec<Region>) {
    let (mut labels, mut out) = (LabelImage::default(), Vec::new());
    segment_into(range, camera, edges, regions, params, &mut Scratch::default(), (&mut labels, &mut out));
    (labels, out)
}

/// The working memory of [`segment_into`], kept from one frame to the next (none of it carries a result).
#[derive(Debug, Default)]
pub struct Scratch {
    /// Step 1: the core mask and the row distances of its distance test.
    core: Grid<bool>,
    row_dist: Vec<u16>,
    /// Step 1: the union-find forest of the components, and the size of each component.
    components: components::Buffers,
    sizes: Vec<u32>,
    /// Steps 2–4: the new label of each component (0 = dropped), and per kept component its guide label,
    /// moments and plane.
    kept: Vec<u32>,
    guide: Vec<u32>,
    moments: Vec<Moments>,
    planes: Vec<Plane>,
    fill: fill::Buffers,
    merge: merge::Buffers,
    /// Step 5: the refinement's buffers and the planes refitted on the refined regions.
    refine: refine::Buffers,
    refitted: Vec<Plane>,
    /// Step 6: the crease step's buffers.
    crease: crease::Buffers,
    /// Step 7: the outlier step's buffers.
    outliers: outliers::Buffers,
    /// Step 5b: the band step's buffers.
    band: band::Buffers,
    /// Step 9: the small faces' buffers.
    faces: faces::Buffers,
    /// Step 8: the curved merge's buffers.
    curved: curved::Buffers,
    /// Every pixel's 3D point, computed once a frame for steps 2–8.
    points: Vec<[f64; 3]>,
    /// Steps 4–9: the merge forest, the root of each label, the final label of each root and the roots in
    /// order of first pixel.
    parent: Vec<u32>,
    root: Vec<u32>,
    map: Vec<u32>,
    order: Vec<u32>,
}

/// [`segment`] into `labels` and `regions` (whose memory is reused), with the working memory of `scratch`: the
/// same result, bit for bit, and no image-sized allocation once `scratch` has seen a frame of this size.
///
/// # Panics
/// As [`segment`].
pub fn segment_into(
    range: &RangeImage,
    camera: &Camera,
    edges: &EdgeMap,
    regions: Option<&LabelImage>,
    params: &Params,
    scratch: &mut Scratch,
    (labels, out): (&mut LabelImage, &mut Vec<Region>),
) {
    let _s = tracing::info_span!("final_segmentation", w = range.width(), h = range.height()).entered();
    assert!(range.same_size(edges), "finalseg::segment: range and edges differ in size");
    if let Some(l) = regions {
        assert!(range.same_size(l), "finalseg::segment: range and regions differ in size");
    }
    let guide = match params.mode {
        Mode::Regions => regions.map(|l| l.as_slice()),
        Mode::Components => None,
    };
    let (w, h) = (range.width() as usize, range.height() as usize);
    let Scratch {
        core,
        row_dist,
        components: cbufs,
        sizes,
        kept,
        guide: comp_guide,
        moments,
        planes,
        fill: fbufs,
        merge: mbufs,
        refine: rbufs,
        refitted,
        crease: crbufs,
        outliers: obufs,
        band: bbufs,
        faces: fabufs,
        curved: cvbufs,
        points,
        parent,
        root,
        map,
        order,
    } = scratch;
    let scene = Scene::new(range.as_slice(), (w, h), camera, points);

    // 1. 4-connected components of core pixels (two neighbours connect only if their guide
    //    labels agree), numbered in raster order of their first pixel, into the memory of the output labels.
    core_pixels(range, edges, guide, params, (row_dist, core));
    let mut comp = std::mem::take(labels).into_vec();
    // The pixels keep provisional labels (component `cbufs.id[l]`) until step 2 maps them.
    components::provisional_into(core.as_slice(), guide, (w, h), &mut comp, sizes, cbufs);

    // 2. Drop small components; fit a plane to every kept one (moments summed in raster order).
    let mut pieces = Pieces {
        comp,
        guide: std::mem::take(comp_guide),
        moments: std::mem::take(moments),
        planes: std::mem::take(planes),
    };
    // Room in the per-region vectors for every region the frame can end with (steps 2, 8 and 9).
    let room = params.most_regions(w * h);
    pieces.fit(&scene, (sizes, &mut cbufs.id), kept, guide, (params.min_region_px, room));

    // 3. Fill unlabelled valid pixels ring by ring.
    let limit = fill::Limit { max_residual: params.fill_max_residual, rms_ratio: params.fill_rms_ratio };
    fill::fill(&scene, &mut pieces.comp, &pieces.planes, limit, fbufs);

    // 4. Merge adjacent regions over unsupported borders with agreeing planes.
    parent.clear();
    parent.extend(0..=pieces.planes.len() as u32);
    if guide.is_some() {
        // The 3D length of the depth's step, for the bends beside a terrace (if a component may be one).
        let step_3d = (params.bend_max_angle_deg > 0.0 && params.terrace_gap_steps > 0.0)
            .then(|| merge::terrace_step(range, camera, &pieces.moments))
            .flatten();
        tracing::debug!(?step_3d, "depth step");
        merge::merge_unsupported(&scene, edges, &mut pieces, parent, (params, step_3d), mbufs);
    }

    // 5–6. Border pixels to the adjacent plane that fits them best, bands of a neighbour's plane given back whole;
    //      crease pixels to the face their line of sight sees.
    place_borders(&scene, &mut pieces, parent, (params, limit), (root, refitted), (rbufs, crbufs, bbufs));

    // 7. Pixels their region's plane does not explain, in groups, left unlabelled (by the planes refitted on the
    //    regions as they now are).
    if params.outlier_scales > 0.0 {
        refine::refit_from(&scene, &pieces.comp, &pieces.planes, refitted, &mut *rbufs);
        let limits = (params.outlier_scales, params.outlier_min_px as usize);
        let n = outliers::release(&scene, &mut pieces.comp, refitted, limits, obufs);
        tracing::debug!(released = n, "outliers");
    }

    // 8. Adjacent regions that one gently curved surface explains, merged (pixels carry their groups' roots).
    if params.curved_merge_ratio > 0.0 && guide.is_some() {
        carry_roots(parent, root, &mut pieces.comp);
        let limits = (params.curved_merge_ratio, params.curved_max_angle_deg, params.merge_max_residual);
        // The moments of every label over all of its pixels: step 7's refit less the pixels it released, or a refit.
        let released: &[(u32, u32)] = if params.outlier_scales > 0.0 {
            obufs.released()
        } else {
            refine::refit_from(&scene, &pieces.comp, &pieces.planes, refitted, &mut *rbufs);
            &[]
        };
        let fits = (&mut pieces.moments[..], &mut pieces.planes[..]);
        let all = (rbufs.moments(), released);
        let n = curved::merge_curved(&scene, &pieces.comp, parent, fits, all, limits, (cvbufs, room));
        tracing::debug!(merges = n, "curved merges");
    }

    // 9. Small faces among the unlabelled pixels.
    if params.small_face_min_px > 0 {
        let limits = faces::Limits {
            min_px: params.small_face_min_px as usize,
            max_px: params.min_region_px as usize,
            scales: params.small_face_scales,
            min_gap: params.small_face_min_gap,
            max_slant_deg: params.small_face_max_slant_deg,
            grow_px: params.small_face_grow_px as usize,
            grow_margin: params.small_face_grow_margin,
        };
        let grow = (&mut *parent, &mut pieces.moments, &mut pieces.planes, &mut pieces.guide);
        let n = faces::recover(&scene, &mut pieces.comp, grow, limits, fabufs);
        tracing::debug!(faces = n, "small faces");
    }

    // 10. Consecutive labels in raster order; region statistics.
    pieces.relabel((parent, root, map, order), (w, h), (labels, out));
    (*comp_guide, *moments, *planes) = (pieces.guide, pieces.moments, pieces.planes);
}

/// Gives each pixel of `comp` its merged group's root in `parent`, through a table of the roots in `root` (no pixel
/// rewritten if nothing merged).
fn carry_roots(parent: &mut [u32], root: &mut Vec<u32>, comp: &mut [u32]) {
    root.clear();
    root.extend((0..parent.len() as u32).map(|c| find(parent, c)));
    if root.iter().enumerate().any(|(c, &r)| r != c as u32) {
        for l in comp {
            *l = root[*l as usize];
        }
    }
}

/// Steps 5, 5b and 6 of [`segment_into`] on the merged groups of `parent`: border refinement, bands and crease
/// pixels, each when it is on (the pixels carry their groups' roots afterwards whenever step 5, 5b, 6 or 7 is on);
/// `root` and `refitted` are working memory, `rbufs`, `crbufs` and `bbufs` the steps' buffers.
fn place_borders(
    scene: &Scene<'_>,
    pieces: &mut Pieces,
    parent: &mut [u32],
    (params, limit): (&Params, fill::Limit),
    (root, refitted): (&mut Vec<u32>, &mut Vec<Plane>),
    (rbufs, crbufs, bbufs): (&mut refine::Buffers, &mut crease::Buffers, &mut band::Buffers),
) {
    let (w, h) = (scene.w, scene.h);
    // 5. Border pixels to the adjacent plane that fits them best.
    // Steps 5–7 work on merged groups, so their pixels carry the groups' roots.
    let later = params.crease_passes > 0 || params.band_max_angle_deg > 0.0 || params.outlier_scales > 0.0;
    if params.refine_passes > 0 || later {
        carry_roots(parent, &mut *root, &mut pieces.comp);
    }
    // The planes refitted on the refined regions, once there are any (`rbufs` holds their moments).
    let mut refit_done = false;
    if params.refine_passes > 0 {
        // A second round against planes refitted on the refined regions: a plane that the
        // misplaced pixels had tilted now lets the rest of them go. (The reported planes stay
        // those of the core pixels.)
        let (passes, first) = (params.refine_passes, (&pieces.planes[..], refine::Start::Scan));
        if refine::refine(scene, &mut pieces.comp, first, (limit, params.refine_steep_cos), passes, rbufs) > 0
        {
            refine::refit_from(scene, &pieces.comp, &pieces.planes, refitted, &mut *rbufs);
            refit_done = true;
            let second = (&refitted[..], refine::Start::Update);
            refine::refine(scene, &mut pieces.comp, second, (limit, params.refine_steep_cos), passes, rbufs);
        }
    }

    // 5b. Bands of a neighbour's plane that a region holds, given back whole.
    if params.band_max_angle_deg > 0.0 {
        if !refit_done {
            refine::refit_from(scene, &pieces.comp, &pieces.planes, refitted, &mut *rbufs);
            refit_done = true;
        }
        // The refinement's border list is that of the current labels, once updated around its last moves.
        let given = params.refine_passes > 0;
        if given {
            rbufs.border_after(&pieces.comp, (w, h), bbufs.border_mut());
        }
        let fits = (&refitted[..], rbufs.moments());
        let band_moved =
            band::give_back(scene, &mut pieces.comp, fits, params.band_max_angle_deg, given, bbufs) > 0;
        if band_moved && params.refine_passes > 0 {
            // A refinement round against the planes refitted on the moved bands: the pixels of a band where the
            // leaking region's tilted plane crossed it are outliers of that region's plane now.
            refine::refit_from(scene, &pieces.comp, &pieces.planes, refitted, &mut *rbufs);
            let again = (&refitted[..], refine::Start::Scan);
            refine::refine(
                scene,
                &mut pieces.comp,
                again,
                (limit, params.refine_steep_cos),
                params.refine_passes,
                rbufs,
            );
            // The crease step takes these planes, refitted before this round as step 5's are before its second
            // round (a refit after the round gave the same counts and cost 0.7 ms per ABW frame).
        } else if band_moved {
            // Without a refinement round, the crease step refits on the moved bands.
            refit_done = false;
        }
    }

    // 6. Crease pixels to the face their line of sight sees, by the planes of the refined regions.
    if params.crease_passes > 0 {
        if !refit_done {
            refine::refit_from(scene, &pieces.comp, &pieces.planes, refitted, &mut *rbufs);
        }
        // The refinement's border list is that of the current labels, once updated around its last moves (a band
        // that moved was followed by a refinement round, which scanned the labels again).
        let given = params.refine_passes > 0;
        if given {
            rbufs.border_after(&pieces.comp, (w, h), crbufs.border_mut());
        }
        let fits = (&refitted[..], rbufs.moments());
        let crease_params = (params.crease_min_angle_deg, params.crease_passes);
        crease::creases(scene, &mut pieces.comp, fits, crease_params, given, crbufs);
    }
}

/// The read-only inputs every step reads: the range values, the image size and the camera.
#[derive(Clone, Copy)]
struct Scene<'a> {
    range: &'a [f32],
    w: usize,
    h: usize,
    camera: &'a Camera,
    /// Every pixel's 3D point ([`Camera::point`]'s bits where the value is finite, meaningless elsewhere).
    points: &'a [[f64; 3]],
}

impl<'a> Scene<'a> {
    /// The scene of `range` (`w` × `h`) seen by `camera`, with every pixel's 3D point computed once into `points`.
    fn new(
        range: &'a [f32],
        (w, h): (usize, usize),
        camera: &'a Camera,
        points: &'a mut Vec<[f64; 3]>,
    ) -> Self {
        points.clear();
        points.resize(w * h, [0.0; 3]);
        // Compiled for the best instruction set of this CPU, so the points are computed several at a time (the same
        // bits on every one).
        isa::dispatch(
            #[inline(always)]
            || {
                for (y, (vals, out)) in
                    range.chunks_exact(w.max(1)).zip(points.chunks_exact_mut(w.max(1))).enumerate()
                {
                    camera.row_points(y as u32, vals, out);
                }
            },
        );
        Scene { range, w, h, camera, points }
    }

    /// The 3D point of pixel (x, y); `None` where the range value is not valid.
    #[inline]
    fn point(&self, x: usize, y: usize) -> Option<[f64; 3]> {
        let i = y * self.w + x;
        self.range[i].is_finite().then(|| self.points[i])
    }

    /// The range values of row `y` and their 3D points: [`Scene::point`]'s bits where the value is finite,
    /// meaningless elsewhere.
    #[inline(always)]
    fn row(&self, y: usize) -> (&[f32], &[[f64; 3]]) {
        let r = y * self.w..(y + 1) * self.w;
        (&self.range[r.clone()], &self.points[r])
    }
}

/// Into `core`, the core pixels: valid, not an edge pixel and not within `gap_close_px` of one (and, in
/// `regions` mode with `unlabelled_core = false`, labelled in `guide`); `row_dist` is the distance test's memory.
fn core_pixels(
    range: &RangeImage,
    edges: &EdgeMap,
    guide: Option<&[u32]>,
    params: &Params,
    (row_dist, core): (&mut Vec<u16>, &mut Grid<bool>),
) {
    if params.gap_close_px > 0.0 {
        rangeimage::distance::within_into(edges, params.gap_close_px, row_dist, core);
    } else {
        core.copy_from(edges);
    }
    for (c, &v) in core.as_mut_slice().iter_mut().zip(range.as_slice()) {
        *c = !*c & v.is_finite();
    }
    if let (Some(g), false) = (guide, params.unlabelled_core) {
        for (c, &l) in core.as_mut_slice().iter_mut().zip(g) {
            *c &= l != 0;
        }
    }
}

/// The regions while they form (steps 2–5): a region per pixel (0 = none; label `l` indexes the per-region
/// vectors at `l − 1`), and per region its region-growing label (0 without a guide), the moments of its core
/// points and its plane.
struct Pieces {
    comp: Vec<u32>,
    guide: Vec<u32>,
    moments: Vec<Moments>,
    planes: Vec<Plane>,
}

impl Pieces {
    /// Step 2: drops the components of `comp` (of sizes `sizes`; `comp` holds provisional labels, `ids[l]` the
    /// component of label `l`, rewritten here into its new label) under `min_region_px` pixels, numbers the kept
    /// ones consecutively in their order (`kept[c − 1]`, the new label of component `c`, 0 if dropped), and fits
    /// a plane to each. The numbering keeps the order of the labels, so every later step (ties to the smaller
    /// label, pairs in sorted order, union-find roots) decides as it would on the component numbers; the per-region
    /// vectors reserve `room` entries (the most regions a frame can end with, small faces included).
    fn fit(
        &mut self,
        scene: &Scene<'_>,
        (sizes, ids): (&[u32], &mut [u32]),
        kept: &mut Vec<u32>,
        guide: Option<&[u32]>,
        (min_region_px, room): (u32, usize),
    ) {
        let (w, h) = (scene.w, scene.h);
        kept.clear();
        kept.reserve(w * h);
        let mut n_kept = 0u32;
        kept.extend(sizes.iter().map(|&n| {
            if u64::from(n) >= u64::from(min_region_px) {
                n_kept += 1;
                n_kept
            } else {
                0
            }
        }));
        // The new label of each provisional label (label 0 stays 0).
        for c in ids.iter_mut().skip(1) {
            *c = kept[*c as usize - 1];
        }
        // Room for every region a frame of this size can end with, so later frames reuse the memory.
        let n = n_kept as usize;
        // The region-growing label of each region (all its pixels share one; 0 without a guide).
        self.guide.clear();
        self.guide.reserve(room);
        self.guide.resize(n, 0);
        self.moments.clear();
        self.moments.reserve(room);
        self.moments.resize(n, Moments::default());
        let (comp, guides, moments, ids) = (&mut self.comp, &mut self.guide, &mut self.moments, &*ids);
        // Compiled for the best instruction set of this CPU (the same bits on every one).
        isa::dispatch(
            #[inline(always)]
            || {
                // Runs of one component are summed in a local copy of its moments (the same additions in
                // the same order, but in registers).
                let mut cur = 0u32;
                let mut acc = Moments::default();
                let mut run = 0u32;
                for y in 0..h {
                    let labels = &mut comp[y * w..(y + 1) * w];
                    if labels.iter().all(|&c| c == 0) {
                        continue;
                    }
                    let (vals, row) = scene.row(y);
                    for (x, c) in labels.iter_mut().enumerate() {
                        if *c == 0 {
                            continue;
                        }
                        *c = ids[*c as usize];
                        if *c == 0 {
                            continue;
                        }
                        // All pixels of a component share its guide label: read it where a run of one starts.
                        if *c != run {
                            run = *c;
                            if let Some(g) = guide {
                                guides[*c as usize - 1] = g[y * w + x];
                            }
                        }
                        if vals[x].is_finite() {
                            if *c != cur {
                                if cur != 0 {
                                    moments[cur as usize - 1] = acc;
                                }
                                cur = *c;
                                acc = moments[cur as usize - 1];
                            }
                            acc.add(row[x]);
                        }
                    }
                }
                if cur != 0 {
                    moments[cur as usize - 1] = acc;
                }
            },
        );
        self.planes.clear();
        self.planes.reserve(room);
        self.planes.extend(self.moments.iter().map(|m| fit_plane(m, scene.camera)));
    }

    /// Step 5: into `labels` (the memory of `self.comp`) and `regions`, the merged groups of `parent` numbered
    /// consecutively in raster order of their first pixel, and their regions; `root`, `map` and `order` are
    /// working memory.
    fn relabel(
        &mut self,
        (parent, root, map, order): (&mut [u32], &mut Vec<u32>, &mut Vec<u32>, &mut Vec<u32>),
        (w, h): (usize, usize),
        (labels, regions): (&mut LabelImage, &mut Vec<Region>),
    ) {
        let planes = &self.planes;
        let n = planes.len();
        root.clear();
        root.reserve(n + 1);
        root.extend((0..=n as u32).map(|c| find(parent, c)));
        map.clear();
        map.reserve(n + 1);
        map.resize(n + 1, 0);
        order.clear();
        order.reserve(n);
        let mut comp = std::mem::take(&mut self.comp);
        // The final sizes, counted into `parent` (no longer needed; one entry per final label, at most n + 1).
        let sizes = parent;
        sizes.fill(0);
        // Runs of one label: the label looked up once per run, and counted once per run.
        let (mut from, mut to, mut run) = (0u32, 0u32, 0u32);
        for l in &mut comp {
            if *l != from {
                if to != 0 {
                    sizes[to as usize - 1] += run;
                }
                (from, run) = (*l, 0);
                to = if *l == 0 {
                    0
                } else {
                    let c = root[*l as usize] as usize;
                    if map[c] == 0 {
                        order.push(c as u32);
                        map[c] = order.len() as u32;
                    }
                    map[c]
                };
            }
            *l = to;
            run += 1;
        }
        if to != 0 {
            sizes[to as usize - 1] += run;
        }
        regions.clear();
        regions.extend(order.iter().zip(sizes.iter()).enumerate().map(|(k, (&c, &size_px))| {
            let plane = planes[c as usize - 1];
            Region {
                label: k as u32 + 1,
                size_px,
                mean_k: f32::NAN,
                normal: plane.normal.map(|v| v as f32),
                offset: plane.offset as f32,
                rms_residual: plane.rms as f32,
            }
        }));
        *labels = Grid::from_vec(w as u32, h as u32, comp).expect("size matches");
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    /// 40×30: left plane v = 100 + 0.5x (x ≤ 19), right plane v = 200 − 2x (x ≥ 20), a two-pixel
    /// edge line at x = 19, 20, and a NaN block in the top-left corner.
    fn two_planes() -> (RangeImage, EdgeMap) {
        let range = Grid::from_fn(40, 30, |x, y| {
            if x < 3 && y < 4 {
                f32::NAN
            } else if x <= 19 {
                100.0 + 0.5 * x as f32
            } else {
                200.0 - 2.0 * x as f32
            }
        });
        let edges = Grid::from_fn(40, 30, |x, _| x == 19 || x == 20);
        (range, edges)
    }

    #[test]
    fn the_region_reserve_counts_small_faces() {
        // Faces of 40 px or more join the regions of 200 px or more: a 512² frame can end with 6,554 regions, not
        // 1,311; without faces, or with faces no smaller than the regions, one per 200 px.
        let px = 512 * 512;
        assert_eq!(Params::default().most_regions(px), px / 40 + 1);
        assert_eq!(Params { small_face_min_px: 0, ..Params::default() }.most_regions(px), px / 200 + 1);
        assert_eq!(Params { small_face_min_px: 500, ..Params::default() }.most_regions(px), px / 200 + 1);
    }

    /// A 4×4 patch 20 units in front of a flat 40×30 plane, all of it edge pixels: without a fill
    /// limit (and without the outlier step) the plane's region swallows it, with `fill_max_residual = 3` it
    /// stays 0; so it does without a fill limit when the outlier step releases it.
    #[test]
    fn fill_limit_leaves_off_plane_pixels_unlabelled() {
        let patch = |x: u32, y: u32| (5..9).contains(&x) && (5..9).contains(&y);
        let range = Grid::from_fn(40, 30, |x, y| if patch(x, y) { 80.0 } else { 100.0 });
        let edges = Grid::from_fn(40, 30, patch);
        let params = Params { min_region_px: 10, gap_close_px: 0.0, ..Params::default() };
        for (limit, outliers, want) in [(0.0, 0.0, 1u32), (3.0, 0.0, 0), (0.0, 2.5, 0)] {
            let p = Params { fill_max_residual: limit, outlier_scales: outliers, ..params.clone() };
            let (labels, regions) = segment(&range, &Camera::Grid, &edges, None, &p);
            assert_eq!(regions.len(), 1);
            assert_eq!(labels[(6, 6)], want, "limit {limit}, outliers {outliers}");
            assert_eq!(labels[(20, 20)], 1);
        }
    }

    /// The default fill limit (4 units) with the default outlier step (2.25 noise scales, groups of 10 px): single
    /// glitch pixels 3.5 units off a flat plane, edge pixels all of them, are filled and stay in its region; a 4×4
    /// patch 3.5 units off is filled too but released again as a group. With the limit of 3 the glitches stay 0.
    #[test]
    fn default_fill_keeps_glitches_and_the_outlier_step_releases_groups() {
        let glitches = [(12u32, 10u32), (25, 7), (31, 22), (18, 24)];
        let glitch = |x: u32, y: u32| glitches.contains(&(x, y));
        let patch = |x: u32, y: u32| (5..9).contains(&x) && (15..19).contains(&y);
        let range = Grid::from_fn(40, 30, |x, y| if glitch(x, y) || patch(x, y) { 103.5 } else { 100.0 });
        let edges = Grid::from_fn(40, 30, |x, y| glitch(x, y) || patch(x, y));
        let defaults = Params { gap_close_px: 0.0, ..Params::default() };
        assert_eq!(
            (defaults.fill_max_residual, defaults.outlier_scales, defaults.outlier_min_px),
            (4.0, 2.25, 10)
        );
        for (limit, want_glitch) in [(4.0, 1u32), (3.0, 0)] {
            let p = Params { fill_max_residual: limit, ..defaults.clone() };
            let (labels, regions) = segment(&range, &Camera::Grid, &edges, None, &p);
            assert_eq!(regions.len(), 1, "limit {limit}");
            for (x, y) in glitches {
                assert_eq!(labels[(x, y)], want_glitch, "glitch ({x}, {y}), limit {limit}");
            }
            assert_eq!(labels[(6, 16)], 0, "patch, limit {limit}");
            assert_eq!(labels[(20, 15)], 1, "plane, limit {limit}");
        }
    }

    /// `fill_rms_ratio`: a rough plane (a ±2-unit checker ripple, RMS 2) keeps a pixel 4 units off it that the
    /// absolute limit of 3 alone would leave unlabelled; a pixel 20 units off stays 0 either way.
    #[test]
    fn fill_limit_follows_the_region_scatter() {
        let hole = |x: u32, y: u32| (5..7).contains(&x) && (5..7).contains(&y);
        let far = |x: u32, y: u32| (30..32).contains(&x) && (20..22).contains(&y);
        let range = Grid::from_fn(40, 30, |x, y| {
            let ripple = if (x + y) % 2 == 0 { 2.0 } else { -2.0 };
            if hole(x, y) {
                104.0
            } else if far(x, y) {
                120.0
            } else {
                100.0 + ripple
            }
        });
        let edges = Grid::from_fn(40, 30, |x, y| hole(x, y) || far(x, y));
        let base = Params { min_region_px: 10, fill_max_residual: 3.0, ..Params::default() };
        for (ratio, want) in [(0.0, 0u32), (3.0, 1)] {
            let p = Params { fill_rms_ratio: ratio, ..base.clone() };
            let (labels, _) = segment(&range, &Camera::Grid, &edges, None, &p);
            assert_eq!(labels[(5, 5)], want, "ratio {ratio}");
            assert_eq!(labels[(30, 20)], 0, "ratio {ratio}");
        }
    }

    /// A crease at x = 30 between v = 100 + 0.5x and a steep v = 115 + 8(x − 30), with the edge
    /// line 3 px off it (x = 33): the left region's core holds two columns of the right plane.
    /// Refinement moves them back to the plane they lie on; without it they stay.
    #[test]
    fn refinement_moves_a_displaced_border_to_the_crease() {
        let range = Grid::from_fn(60, 30, |x, _| {
            if x <= 30 { 100.0 + 0.5 * x as f32 } else { 115.0 + 8.0 * (x as f32 - 30.0) }
        });
        let edges = Grid::from_fn(60, 30, |x, _| x == 33);
        let base = Params { min_region_px: 10, ..Params::default() };
        let column = |p: &Params, x: u32| {
            let (labels, _) = segment(&range, &Camera::Grid, &edges, None, p);
            (0..30).map(|y| labels[(x, y)]).collect::<Vec<_>>()
        };
        let off = border_steps_off(&base);
        assert!(column(&off, 32).iter().all(|&l| l == 1), "without refinement x = 32 stays left");
        for x in 31..=32 {
            assert!(column(&base, x).iter().all(|&l| l == 2), "x = {x} moves to the right plane");
        }
        for x in [0, 29, 30] {
            assert!(column(&base, x).iter().all(|&l| l == 1), "x = {x} stays on the left plane");
        }
    }

    /// `base` with every step after the merge off (refinement, bands, creases, outliers): the borders stay where
    /// growth and edges put them.
    fn border_steps_off(base: &Params) -> Params {
        Params {
            refine_passes: 0,
            crease_passes: 0,
            band_max_angle_deg: 0.0,
            outlier_scales: 0.0,
            ..base.clone()
        }
    }

    /// A shallow crease at x = 30 (slopes 0.5 and 1.5 per pixel, 30° apart in Grid units, with a ±0.3 ripple) and
    /// the edge line 6 px past it (x = 36): the left region holds five columns of the right plane, which tilt its
    /// plane and inflate its RMS enough that they lie within 2.5 of its noise scales. Refinement still gives
    /// them back to the plane they lie on, and the moved border is straight.
    #[test]
    fn refinement_returns_a_band_leaked_past_a_shallow_crease() {
        let ripple = |x: u32, y: u32| if (x * 3 + y * 5) % 4 < 2 { 0.3 } else { -0.3 };
        let range = Grid::from_fn(72, 40, |x, y| {
            let v = if x <= 30 { 100.0 + 0.5 * x as f32 } else { 115.0 + 1.5 * (x as f32 - 30.0) };
            v + ripple(x, y)
        });
        let edges = Grid::from_fn(72, 40, |x, _| x == 36);
        let base = Params { min_region_px: 10, ..Params::default() };
        let column = |p: &Params, x: u32| {
            let (labels, _) = segment(&range, &Camera::Grid, &edges, None, p);
            (0..40).map(|y| labels[(x, y)]).collect::<Vec<_>>()
        };
        let off = border_steps_off(&base);
        assert!(column(&off, 33).iter().all(|&l| l == 1), "without refinement the leaked band stays left");
        for x in 32..=35 {
            assert!(column(&base, x).iter().all(|&l| l == 2), "x = {x} moves to the right plane");
        }
        for x in [0, 20, 29] {
            assert!(column(&base, x).iter().all(|&l| l == 1), "x = {x} stays on the left plane");
        }
    }

    /// A noisy plane split by an edge line: refinement leaves the border alone (no pixel is an
    /// outlier of its own plane), so noise does not fray it.
    #[test]
    fn refinement_leaves_a_border_inside_one_noisy_plane() {
        let noise = |x: u32, y: u32| (((x * 7919 + y * 104_729) % 13) as f32 - 6.0) * 0.15;
        let range = Grid::from_fn(40, 30, |x, y| 100.0 + 0.5 * x as f32 + noise(x, y));
        let edges = Grid::from_fn(40, 30, |x, _| x == 20);
        let p = Params { min_region_px: 10, ..Params::default() };
        let (with, _) = segment(&range, &Camera::Grid, &edges, None, &p);
        let (without, _) = segment(&range, &Camera::Grid, &edges, None, &Params { refine_passes: 0, ..p });
        assert_eq!(with, without);
    }

    #[test]
    fn two_planes_split_at_the_edge_line() {
        for gap_close_px in [0.0, 2.0] {
            two_planes_split(gap_close_px);
        }
    }

    #[test]
    fn gap_closing_separates_regions_across_a_broken_contour() {
        let (range, mut edges) = two_planes();
        for y in 10..12 {
            edges[(19, y)] = false;
            edges[(20, y)] = false;
        }
        let open = Params { gap_close_px: 0.0, ..Params::default() };
        let (_, regions) = segment(&range, &Camera::Grid, &edges, None, &open);
        assert_eq!(regions.len(), 1, "without gap closing the two faces leak into one component");
        let closing = Params { gap_close_px: 2.0, ..Params::default() };
        let (labels, regions) = segment(&range, &Camera::Grid, &edges, None, &closing);
        assert_eq!(regions.len(), 2);
        for y in 0..30 {
            assert_eq!(labels[(10, y)], 1);
            assert_eq!(labels[(30, y)], 2);
            assert_eq!(labels[(19, y)], 1, "gap pixel (19, {y}) fits the left plane");
            assert_eq!(labels[(20, y)], 2, "gap pixel (20, {y}) fits the right plane");
        }
    }

    fn two_planes_split(gap_close_px: f64) {
        let (range, edges) = two_planes();
        let params = Params { gap_close_px, ..Params::default() };
        let (labels, regions) = segment(&range, &Camera::Grid, &edges, None, &params);
        assert_eq!(regions.len(), 2);
        for (x, y, &l) in labels.enumerate() {
            let want = if range[(x, y)].is_nan() {
                0
            } else if x <= 19 {
                1
            } else {
                2
            };
            assert_eq!(l, want, "pixel ({x}, {y})");
        }
        assert_eq!(regions[0].label, 1);
        assert_eq!(regions[0].size_px, 20 * 30 - 12);
        assert_eq!(regions[1].size_px, 20 * 30);
        for r in &regions {
            let n = r.normal;
            assert_relative_eq!((n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt(), 1.0, epsilon = 1e-5);
            // Camera::Grid looks along −z: normals point toward the sensor.
            assert!(n[2] < 0.0, "{r:?}");
            assert!(r.rms_residual < 1e-3, "{r:?}");
            assert!(r.mean_k.is_nan());
        }
        // Left plane: v − 0.5x − 100 = 0 → normal ∝ (−0.5, 0, 1), flipped toward −z.
        let n = regions[0].normal;
        assert_relative_eq!(n[0] / n[2], -0.5, epsilon = 1e-4);
    }

    #[test]
    fn thick_edges_fill_by_best_plane_and_small_components_are_dropped() {
        // Edge band x = 16..=23 (8 px), an isolated 2×2 non-edge hole in it at (18..20, 10..12).
        let range =
            Grid::from_fn(
                40,
                30,
                |x, _| if x <= 19 { 100.0 + 0.5 * x as f32 } else { 200.0 - 2.0 * x as f32 },
            );
        let edges = Grid::from_fn(40, 30, |x, y| {
            (16..=23).contains(&x) && !((18..20).contains(&x) && (10..12).contains(&y))
        });
        let (labels, regions) = segment(
            &range,
            &Camera::Grid,
            &edges,
            None,
            &Params { min_region_px: 10, gap_close_px: 0.0, ..Params::default() },
        );
        assert_eq!(regions.len(), 2);
        for (x, y, &l) in labels.enumerate() {
            assert_eq!(l, if x <= 19 { 1 } else { 2 }, "pixel ({x}, {y})");
        }
        assert_eq!(regions.iter().map(|r| r.size_px).sum::<u32>(), 40 * 30);
    }

    #[test]
    fn isolated_and_invalid_pixels_stay_unlabelled() {
        // Everything is edge: no region at all.
        let range = Grid::new(10, 10, 50.0f32);
        let (labels, regions) =
            segment(&range, &Camera::ABW0, &Grid::new(10, 10, true), None, &Params::default());
        assert!(regions.is_empty());
        assert!(labels.as_slice().iter().all(|&l| l == 0));
        // An all-NaN image.
        let nan = Grid::new(6, 5, f32::NAN);
        let (labels, regions) =
            segment(&nan, &Camera::ABW0, &Grid::new(6, 5, false), None, &Params::default());
        assert!(regions.is_empty() && labels.as_slice().iter().all(|&l| l == 0));
    }

    #[test]
    fn labels_are_consecutive_in_raster_order() {
        // Three vertical stripes separated by edge columns; the middle one starts lower.
        let range = Grid::from_fn(30, 20, |x, _| 80.0 + x as f32);
        let edges = Grid::from_fn(30, 20, |x, y| x == 9 || x == 19 || ((10..19).contains(&x) && y < 5));
        let (labels, regions) = segment(
            &range,
            &Camera::ABW0,
            &edges,
            None,
            &Params { min_region_px: 5, gap_close_px: 0.0, ..Params::default() },
        );
        assert_eq!(regions.iter().map(|r| r.label).collect::<Vec<_>>(), vec![1, 2, 3]);
        let mut first = Vec::new();
        for &l in labels.as_slice() {
            if l != 0 && !first.contains(&l) {
                first.push(l);
            }
        }
        assert_eq!(first, vec![1, 2, 3]);
        assert_eq!(regions.iter().map(|r| r.size_px).sum::<u32>(), 30 * 20);
        assert_ne!(labels[(0, 0)], labels[(25, 10)]);
        assert_ne!(labels[(12, 10)], labels[(25, 10)]);
        // ABW normals point toward the scanner (+z).
        assert!(regions.iter().all(|r| r.normal[2] > 0.0));
    }

    /// Region-growing labels: 1 for x < 20, 2 for x ≥ 20 (0 on NaN pixels).
    fn rg_split(range: &RangeImage) -> LabelImage {
        Grid::from_fn(range.width(), range.height(), |x, y| {
            if range[(x, y)].is_nan() {
                0
            } else if x < 20 {
                1
            } else {
                2
            }
        })
    }

    fn regions_mode() -> Params {
        Params { mode: Mode::Regions, ..Params::default() }
    }

    /// [`regions_mode`] without the curved merge (step 8), which joins coplanar pieces whatever edges lie between
    /// them: the tests of step 4's edge support use it.
    fn step4_support() -> Params {
        Params { curved_merge_ratio: 0.0, ..regions_mode() }
    }

    #[test]
    fn regions_mode_splits_a_region_along_an_edge_line_inside_it() {
        // Region growing merged both planes into one region; C separates them.
        let (range, edges) = two_planes();
        let rg = range.map(|v| u32::from(v.is_finite()));
        let (labels, regions) = segment(&range, &Camera::Grid, &edges, Some(&rg), &regions_mode());
        assert_eq!(regions.len(), 2);
        assert_eq!(labels[(5, 20)], 1);
        assert_eq!(labels[(35, 20)], 2);
        assert_eq!(labels[(0, 0)], 0, "NaN stays unlabelled");
    }

    #[test]
    fn regions_mode_never_leaks_across_a_region_growing_border_of_different_planes() {
        // No edges at all: Components mode gives one region, Regions mode keeps the two
        // region-growing regions (the border is unsupported, but the planes differ).
        let (range, _) = two_planes();
        let none = Grid::new(40, 30, false);
        let rg = rg_split(&range);
        let comps = Params { mode: Mode::Components, ..Params::default() };
        assert_eq!(segment(&range, &Camera::Grid, &none, Some(&rg), &comps).1.len(), 1);
        // Without region-growing labels, Regions mode falls back to Components.
        assert_eq!(segment(&range, &Camera::Grid, &none, None, &regions_mode()).1.len(), 1);
        let (labels, regions) = segment(&range, &Camera::Grid, &none, Some(&rg), &regions_mode());
        assert_eq!(regions.len(), 2);
        for (x, y, &l) in labels.enumerate() {
            let want = if range[(x, y)].is_nan() { 0 } else { rg[(x, y)] };
            assert_eq!(l, want, "pixel ({x}, {y})");
        }
    }

    #[test]
    fn regions_mode_merges_coplanar_regions_over_an_unsupported_border_only() {
        // One plane, split in two by region growing.
        let range = Grid::from_fn(40, 30, |x, y| 100.0 + 0.5 * x as f32 + 0.25 * y as f32);
        let rg = rg_split(&range);
        let none = Grid::new(40, 30, false);
        let (labels, regions) = segment(&range, &Camera::Grid, &none, Some(&rg), &step4_support());
        assert_eq!(regions.len(), 1, "unsupported border, same plane: merged");
        assert_eq!(regions[0].size_px, 40 * 30);
        assert!(labels.as_slice().iter().all(|&l| l == 1));
        assert!(regions[0].rms_residual < 1e-3);
        // The same border with edge support stays.
        let edges = Grid::from_fn(40, 30, |x, _| x == 19 || x == 20);
        let (labels, regions) = segment(&range, &Camera::Grid, &edges, Some(&rg), &step4_support());
        assert_eq!(regions.len(), 2, "supported border: kept");
        assert_ne!(labels[(5, 5)], labels[(35, 5)]);
        // An edge along a tenth of the border (support ≈ 0.15 < min_border_support = 0.3): merged.
        let partial = Grid::from_fn(40, 30, |x, y| (x == 19 || x == 20) && y < 3);
        let (_, regions) = segment(&range, &Camera::Grid, &partial, Some(&rg), &step4_support());
        assert_eq!(regions.len(), 1);
        // A tilt of 1.0 vs 0.5 per pixel (about 18° apart in Grid units) is not merged.
        let tilted =
            Grid::from_fn(
                40,
                30,
                |x, _| if x < 20 { 100.0 + 0.5 * x as f32 } else { 110.0 + (x as f32 - 20.0) },
            );
        let (_, regions) = segment(&tilted, &Camera::Grid, &none, Some(&rg), &step4_support());
        assert_eq!(regions.len(), 2);
    }

    #[test]
    fn regions_mode_rejoins_pieces_of_one_region_split_by_interior_edges_on_one_plane_only() {
        // Region growing found one region; an edge line inside it splits it in two.
        let edges = Grid::from_fn(40, 30, |x, _| x == 19 || x == 20);
        let one = |range: &RangeImage| range.map(|v| u32::from(v.is_finite()));
        let count = |range: &RangeImage, sp: &Params| {
            segment(range, &Camera::Grid, &edges, Some(&one(range)), sp).1.len()
        };
        let plane = |x: u32, y: u32| 100.0 + 0.5 * x as f32 + 0.25 * y as f32;
        let image = |f: &dyn Fn(u32, u32) -> f32| Grid::from_fn(40, 30, f);
        let plane_img = image(&plane);
        assert_eq!(count(&plane_img, &step4_support()), 1, "one plane: the pieces rejoin");
        let split = Params { merge_within_region: false, ..step4_support() };
        assert_eq!(count(&plane_img, &split), 2, "without merge_within_region the edges split it");
        // Parallel planes one unit apart (within merge_max_residual = 3, far above their RMS of
        // 0): a real step, kept.
        let step = image(&|x, y| plane(x, y) + if x < 20 { 0.0 } else { 1.0 });
        assert_eq!(count(&step, &step4_support()), 2, "a step between parallel pieces stays");
        // Two pieces of one noisy plane rejoin, a step of twice the noise does not.
        let noise = |x: u32, y: u32| ((x * 7 + y * 13) % 5) as f32 * 0.25 - 0.5;
        let noisy = image(&|x, y| plane(x, y) + noise(x, y));
        assert_eq!(count(&noisy, &step4_support()), 1);
        let noisy_step = image(&|x, y| plane(x, y) + noise(x, y) + if x < 20 { 0.0 } else { 0.7 });
        assert_eq!(count(&noisy_step, &step4_support()), 2);
    }

    #[test]
    fn curved_merge_joins_coplanar_pieces_across_edges_but_not_a_step() {
        // Two region-growing regions of one plane with an edge line on their border: step 4 keeps the supported
        // border, step 8 joins the pieces (one surface explains both). A step of about three times the noise stays:
        // the quadric misfits it over the whole union. (Steps under about twice the noise, or under about one unit
        // on noise-free planes, whose noise scale is the floor of 0.25, merge: a noise-relative test cannot see them.)
        let edges = Grid::from_fn(40, 30, |x, _| x == 19 || x == 20);
        let noise = |x: u32, y: u32| ((x * 7 + y * 13) % 5) as f32 * 0.25 - 0.5;
        let count = |step: f32, noisy: bool, sp: &Params| {
            let range = Grid::from_fn(40, 30, |x, y| {
                let n = if noisy { noise(x, y) } else { 0.0 };
                100.0 + 0.5 * x as f32 + 0.25 * y as f32 + n + if x < 20 { 0.0 } else { step }
            });
            segment(&range, &Camera::Grid, &edges, Some(&rg_split(&range)), sp).1.len()
        };
        assert_eq!(count(0.0, false, &step4_support()), 2, "step 4 keeps a supported border");
        assert_eq!(count(0.0, false, &regions_mode()), 1, "step 8 joins the pieces of one surface");
        assert_eq!(count(0.0, true, &regions_mode()), 1, "and of one noisy surface");
        assert_eq!(count(1.0, true, &regions_mode()), 2, "a step of three times the noise stays");
        assert_eq!(count(2.0, false, &regions_mode()), 2, "a step of two units on noise-free planes stays");
    }

    #[test]
    fn regions_mode_merges_across_a_bend_but_not_across_a_step() {
        // Two region-growing regions with an edge line on their border: a noisy surface whose slope
        // changes from 0.5 to 0.6 per pixel at x = 20 (a bend of 4.4°, continuous), and the same
        // surface with a step of about three times its noise.
        let edges = Grid::from_fn(40, 30, |x, _| x == 19 || x == 20);
        let noise = |x: u32, y: u32| ((x * 7 + y * 13) % 5) as f32 * 0.25 - 0.5;
        let bent = |x: u32| if x < 20 { 100.0 + 0.5 * x as f32 } else { 110.0 + 0.6 * (x as f32 - 20.0) };
        let count = |step: f32, sp: &Params| {
            let range = Grid::from_fn(40, 30, |x, y| bent(x) + noise(x, y) + if x < 20 { 0.0 } else { step });
            segment(&range, &Camera::Grid, &edges, Some(&rg_split(&range)), sp).1.len()
        };
        let off = Params { bend_max_angle_deg: 0.0, ..step4_support() };
        assert_eq!(count(0.0, &off), 2, "without bend (and curved) merges the supported border stays");
        assert_eq!(count(0.0, &regions_mode()), 1, "a bend: merged");
        assert_eq!(count(1.0, &regions_mode()), 2, "a step: kept");
        let narrow = Params { bend_max_angle_deg: 3.0, bend_fit_ratio: 0.0, ..step4_support() };
        assert_eq!(count(0.0, &narrow), 2, "a bend sharper than bend_max_angle_deg: kept");
        let fits = Params { bend_fit_ratio: 2.0, ..narrow };
        assert_eq!(count(0.0, &fits), 1, "sharper, but one plane fits both within twice their RMS: merged");
    }

    #[test]
    fn regions_mode_merges_a_thin_strip_whose_own_normal_is_unreliable() {
        // One noisy plane (slope 0.5 per pixel, noise RMS about 1) that region growing cut into a 1-px strip at
        // x = 18 and the rest on either side, with edge lines beside the strip. The strip's own plane is x = 18
        // (63° off: its points span no width), but the plane through the strip and a neighbour fits the
        // strip as well as the neighbour's own plane fits it.
        let noise = |x: u32, y: u32| ((x * 7 + y * 13) % 5) as f32 * 0.75 - 1.5;
        let range = Grid::from_fn(40, 30, |x, y| 100.0 + 0.5 * x as f32 + noise(x, y));
        let edges = Grid::from_fn(40, 30, |x, _| x == 17 || x == 19);
        let rg = Grid::from_fn(40, 30, |x, _| match x {
            0..18 => 1u32,
            18 => 2,
            _ => 3,
        });
        let count = |p: &Params| segment(&range, &Camera::Grid, &edges, Some(&rg), p).1.len();
        let p = Params { min_region_px: 10, ..regions_mode() };
        let angle_only = Params { bend_fit_ratio: 0.0, ..p.clone() };
        assert_eq!(count(&angle_only), 3, "the strip's normal fails the angle test");
        assert_eq!(count(&p), 1, "the joint plane fits the strip: merged");
        // Right of the strip a second plane, 37° steeper (a crease at x = 18.5): the strip joins the left
        // plane only.
        let creased = Grid::from_fn(40, 30, |x, y| {
            let v = if x <= 18 { 100.0 + 0.5 * x as f32 } else { 109.25 + 2.0 * (x as f32 - 18.5) };
            v + noise(x, y)
        });
        let (labels, regions) = segment(&creased, &Camera::Grid, &edges, Some(&rg), &p);
        assert_eq!(regions.len(), 2, "a crease is not a strip");
        assert_eq!(labels[(18, 10)], labels[(5, 10)]);
        assert_ne!(labels[(30, 10)], labels[(5, 10)]);
    }

    #[test]
    fn segment_params_default_validates_and_round_trips() {
        let p = Params::default();
        assert_eq!(p.validate(), Ok(()));
        assert_eq!(p.mode, Mode::Regions);
        let json = serde_json::to_string(&p).unwrap();
        assert!(json.contains(r#""mode":"regions""#), "{json}");
        let back: Params = serde_json::from_str(&json).unwrap();
        assert_eq!(back, p);
        let c: Params = serde_json::from_str(r#"{"mode": "components"}"#).unwrap();
        assert_eq!(c.mode, Mode::Components);
        assert!(Params { min_border_support: 1.5, ..p.clone() }.validate().is_err());
        assert!(Params { within_max_rms_ratio: 0.5, ..p.clone() }.validate().is_err());
        assert!(Params { merge_max_angle_deg: -1.0, ..p.clone() }.validate().is_err());
        assert!(Params { merge_max_residual: f64::NAN, ..p.clone() }.validate().is_err());
        assert!(Params { bend_max_angle_deg: 91.0, ..p.clone() }.validate().is_err());
        assert!(Params { bend_max_gap: -1.0, ..p.clone() }.validate().is_err());
        assert!(Params { bend_fit_ratio: -1.0, ..p }.validate().is_err());
    }

    /// A random scene: tilted planes in vertical bands with noise and NaN holes, random edge pixels plus
    /// the band borders, region-growing labels in blocks (0 in places).
    fn random_scene(w: u32, h: u32, seed: u64) -> (RangeImage, EdgeMap, LabelImage) {
        use rand::{RngExt, SeedableRng};
        let mut rng = rand::rngs::Xoshiro256PlusPlus::seed_from_u64(seed);
        let bands = rng.random_range(2..6u32);
        let slopes: Vec<(f32, f32)> =
            (0..bands).map(|_| (rng.random_range(-2.0..2.0), rng.random_range(-1.0..1.0))).collect();
        let band = |x: u32| (x * bands / w) as usize;
        let range = Grid::from_fn(w, h, |x, y| {
            let (a, b) = slopes[band(x)];
            if (x * 7 + y * 3) % 53 == 0 { f32::NAN } else { 120.0 + a * x as f32 + b * y as f32 }
        });
        let range = range.map(|&v| v + rng.random_range(-0.3..0.3));
        let edges = Grid::from_fn(w, h, |x, _| x > 0 && band(x) != band(x - 1));
        let edges = edges.map(|&e| e || rng.random_bool(0.08));
        let guide =
            Grid::from_fn(w, h, |x, y| if (x / 9 + y / 13) % 5 == 0 { 0 } else { 1 + x / 17 + y / 11 });
        (range, edges, guide)
    }

    /// One scratch through frames of varying sizes, modes and parameters gives what fresh memory gives.
    #[test]
    fn reused_scratch_gives_the_same_result() {
        let mut scratch = Scratch::default();
        let (mut labels, mut regions) = (LabelImage::default(), Vec::new());
        let params = [
            Params { min_region_px: 20, mode: Mode::Components, ..Params::default() },
            Params { min_region_px: 5, gap_close_px: 1.5, ..regions_mode() },
            Params { min_region_px: 30, fill_max_residual: 1.0, ..regions_mode() },
        ];
        for (k, (w, h)) in [(60u32, 40u32), (60, 40), (90, 30), (20, 70), (60, 40)].into_iter().enumerate() {
            for (j, p) in params.iter().enumerate() {
                let (range, edges, guide) = random_scene(w, h, (k * 3 + j) as u64);
                let want = segment(&range, &Camera::Grid, &edges, Some(&guide), p);
                assert!(!want.1.is_empty(), "frame {k}, params {j}: no region");
                let out = (&mut labels, &mut regions);
                segment_into(&range, &Camera::Grid, &edges, Some(&guide), p, &mut scratch, out);
                assert_eq!(labels, want.0, "frame {k}, params {j}");
                assert_eq!(format!("{regions:?}"), format!("{:?}", want.1), "frame {k}, params {j}");
            }
        }
    }
    #[test]
    fn every_instruction_set_gives_the_same_segmentation() {
        let cams = [
            Camera::Grid,
            Camera::ABW0,
            Camera::Pinhole { fx: 52.0, fy: 51.0, cx: 29.5, cy: 19.5, depth_scale: 0.001 },
        ];
        for (k, cam) in cams.iter().enumerate() {
            for (j, p) in
                [Params { min_region_px: 5, gap_close_px: 1.5, ..regions_mode() }, Params::default()]
                    .iter()
                    .enumerate()
            {
                let (range, edges, guide) = random_scene(60, 40, (10 + 2 * k + j) as u64);
                let run = || segment(&range, cam, &edges, Some(&guide), p);
                let want = isa::with_isa(isa::Isa::Baseline, run).expect("baseline");
                for other in isa::Isa::available() {
                    let got = isa::with_isa(other, run).expect("available");
                    assert_eq!(got.0, want.0, "camera {k}, params {j}, {other:?}");
                    assert_eq!(
                        format!("{:?}", got.1),
                        format!("{:?}", want.1),
                        "camera {k}, params {j}, {other:?}"
                    );
                }
            }
        }
    }
}

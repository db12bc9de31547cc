//! Writing one image's pipeline results to disk in the ABW formats and as PNGs.

use crate::pipeline::Output;
use crate::planes::Plane;
use rangeimage::{Camera, LabelImage, Region};
use rangeio::Frame;
use std::path::Path;

/// Writes `labels` as an ABW `.ms-seg` (renumbered from 10 as the format needs), the regions' normals as a
/// `.ms-nor` under the same labels, and every label unchanged as a 16-bit gray PNG beside the `.ms-seg`
/// (`NAME.labels.png`, 0 = none), which keeps the regions the `.ms-seg`'s 246-region cap drops;
/// returns what the `.ms-seg` holds.
///
/// Regions lost to the cap are reported with `tracing::warn!` (see [`ms_seg_cap_loss`]).
pub fn write_segmentation(
    seg_path: &Path,
    nor_path: &Path,
    labels: &LabelImage,
    regions: &[Region],
) -> Result<MsSegWritten, rangeio::WriteError> {
    let labels_path = labels_png_path(seg_path);
    rangeio::png::write_label16_png(&labels_path, labels)?;
    let mapping = rangeio::abw::write_labels(seg_path, labels)?;
    let normals: Vec<(u32, [f32; 3])> = mapping
        .iter()
        .filter(|&&(_, new)| new != 0)
        .filter_map(|&(old, new)| regions.iter().find(|r| r.label == old).map(|r| (u32::from(new), r.normal)))
        .collect();
    rangeio::abw::write_normals(nor_path, &normals)?;
    // `write_labels` keeps every region unless it had to choose the largest `MAX_REGIONS`.
    let (lost, lost_px) =
        if mapping.len() < rangeio::abw::MAX_REGIONS { (0, 0) } else { ms_seg_cap_loss(labels, &mapping) };
    if lost > 0 {
        tracing::warn!(
            "{}: the .ms-seg format holds at most 246 regions: {lost} of {} regions ({lost_px} px) are 0 in it; \
             {} has them all",
            seg_path.display(),
            lost + mapping.len(),
            labels_path.display()
        );
    }
    Ok(MsSegWritten { mapping, lost_regions: lost, lost_px })
}

/// What [`write_segmentation`] wrote to the `.ms-seg`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MsSegWritten {
    /// The `(label, written label)` pairs of the `.ms-seg`.
    pub mapping: Vec<(u32, u8)>,
    /// Regions the 246-region cap left out of it ([`ms_seg_cap_loss`]).
    pub lost_regions: usize,
    /// Their pixels, 0 in it.
    pub lost_px: u64,
}

/// `NAME.labels.png` beside `NAME.ms-seg`.
pub fn labels_png_path(seg_path: &Path) -> std::path::PathBuf {
    let stem = seg_path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    seg_path.with_file_name(format!("{stem}.labels.png"))
}

/// Regions (and their pixels) of `labels` that the `.ms-seg` written with `mapping` sets to 0.
pub fn ms_seg_cap_loss(labels: &LabelImage, mapping: &[(u32, u8)]) -> (usize, u64) {
    let max = labels.as_slice().iter().copied().max().unwrap_or(0) as usize;
    let mut px = 0;
    if max <= labels.len() {
        // Labels 1..n of a segmentation: per-label tables (no hashing), updated once a run of one label.
        let mut kept = vec![false; max + 1];
        for &(l, _) in mapping {
            if let Some(k) = kept.get_mut(l as usize) {
                *k = true;
            }
        }
        let mut lost = vec![false; max + 1];
        rangeio::abw::for_each_run(labels.as_slice(), |l, _, len| {
            if l != 0 && !kept[l as usize] {
                lost[l as usize] = true;
                px += len as u64;
            }
        });
        return (lost.iter().filter(|&&x| x).count(), px);
    }
    let kept: std::collections::HashSet<u32> = mapping.iter().map(|&(l, _)| l).collect();
    let mut lost = std::collections::HashSet::new();
    rangeio::abw::for_each_run(labels.as_slice(), |l, _, len| {
        if l != 0 && !kept.contains(&l) {
            lost.insert(l);
            px += len as u64;
        }
    });
    (lost.len(), px)
}

/// Which files [`write_selected_outputs`] writes (the CLI's `--outputs`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct OutputSet {
    /// `STEM.ms-seg`, `STEM.ms-nor` and `STEM.labels.png` (`ms-seg`).
    pub ms_seg: bool,
    /// `STEM.edges.png`, the final edge map (`edges`).
    pub edges: bool,
    /// `STEM.c1.png` (`c1`).
    pub c1: bool,
    /// `STEM.c2.png` (`c2`).
    pub c2: bool,
    /// `STEM.regions.png`, the labels in colour (`regions`).
    pub regions: bool,
    /// `STEM.planes.json` (`planes`).
    pub planes: bool,
}

impl OutputSet {
    /// Every output.
    pub const ALL: Self = Self { ms_seg: true, edges: true, c1: true, c2: true, regions: true, planes: true };
    /// The names [`OutputSet::parse`] accepts.
    pub const NAMES: &[&str] = &["ms-seg", "edges", "c1", "c2", "regions", "planes"];

    /// The set named by a comma-separated list of [`OutputSet::NAMES`] (or `all`).
    pub fn parse(list: &str) -> Result<Self, String> {
        let mut s = Self { ms_seg: false, edges: false, c1: false, c2: false, regions: false, planes: false };
        for name in list.split(',').map(str::trim).filter(|n| !n.is_empty()) {
            match name {
                "all" => s = Self::ALL,
                "ms-seg" => s.ms_seg = true,
                "edges" => s.edges = true,
                "c1" => s.c1 = true,
                "c2" => s.c2 = true,
                "regions" => s.regions = true,
                "planes" => s.planes = true,
                other => {
                    return Err(format!("unknown output {other:?} (one of all, {})", Self::NAMES.join(", ")));
                }
            }
        }
        Ok(s)
    }
}

/// Writes `STEM.ms-seg`, `STEM.ms-nor`, `STEM.labels.png`, `STEM.edges.png`, `STEM.c1.png`, `STEM.c2.png`,
/// `STEM.regions.png` and `STEM.planes.json` ([`write_planes_json`]) into `dir`, each atomically, and returns a JSON
/// summary (counts, energies) for `STEM.json`.
pub fn write_outputs(
    dir: &Path,
    stem: &str,
    frame: &Frame,
    out: &Output,
) -> Result<serde_json::Value, rangeio::WriteError> {
    write_selected_outputs(dir, stem, frame, out, OutputSet::ALL)
}

/// [`write_outputs`] for the files of `which` only; without `ms-seg` the summary's `.ms-seg` counts
/// (`regions_written`, `regions_dropped_by_ms_seg_cap`, `px_dropped_by_ms_seg_cap`) are null.
pub fn write_selected_outputs(
    dir: &Path,
    stem: &str,
    frame: &Frame,
    out: &Output,
    which: OutputSet,
) -> Result<serde_json::Value, rangeio::WriteError> {
    let _s = tracing::info_span!("write_outputs", stem).entered();
    let path = |ext: &str| dir.join(format!("{stem}.{ext}"));
    let ms_seg = if which.ms_seg {
        Some(write_segmentation(&path("ms-seg"), &path("ms-nor"), &out.fin.labels, &out.fin.final_regions)?)
    } else {
        None
    };
    if which.edges {
        rangeio::png::write_edge_png(&path("edges.png"), out.fin.edges())?;
    }
    if which.c1 {
        rangeio::png::write_edge_png(&path("c1.png"), &out.regions.c1)?;
    }
    if which.c2 {
        rangeio::png::write_edge_png(&path("c2.png"), &out.canny.edges)?;
    }
    if which.regions {
        rangeio::png::write_label_png(&path("regions.png"), &out.fin.labels)?;
    }
    if which.planes {
        let planes = crate::planes::planes(&frame.range, &out.fin.labels, &frame.camera);
        write_planes_json(&path("planes.json"), &frame.camera, &planes)?;
    }

    let cap = ms_seg.as_ref().map(|m| (m.mapping.len(), (m.lost_regions, m.lost_px)));
    let count = |e: &rangeimage::EdgeMap| e.as_slice().iter().filter(|&&b| b).count();
    let info = &out.fin.relax_info;
    Ok(serde_json::json!({
        "format": frame.format.to_string(),
        "width": frame.range.width(),
        "height": frame.range.height(),
        "dequantised_step": out.dequantised,
        "decimation": out.decimation,
        "regions_grown": out.regions.regions.len(),
        "regions_final": out.fin.final_regions.len(),
        "regions_written": cap.map(|c| c.0),
        "regions_dropped_by_ms_seg_cap": cap.map(|c| c.1.0),
        "px_dropped_by_ms_seg_cap": cap.map(|c| c.1.1),
        "c1_px_initial": count(&out.regions.c1),
        "c2_px_initial": count(&out.canny.edges),
        "c1_px": count(&out.fin.relaxed.c1),
        "c2_px": count(&out.fin.relaxed.c2),
        "edge_px": count(out.fin.edges()),
        "relax": {
            "removed_c1": info.removed_c1,
            "removed_c2": info.removed_c2,
            "unsupported_c2": info.unsupported_c2,
            "energy_before": info.energy_before,
            "energy_after": info.energy_after,
            "sweeps": info.sweeps,
            "acceptance_rate": info.acceptance_rate,
        },
    }))
}

/// Writes the final regions' planes ([`crate::planes()`]) as JSON, atomically: `{"camera": …, "planes": [{"label",
/// "normal", "d", "centroid", "pixels", "rms", "bbox"}, …]}` with `normal · X = d` in the camera's frame; a
/// region with fewer than 3 points has `null` normal and d.
pub fn write_planes_json(path: &Path, camera: &Camera, planes: &[Plane]) -> Result<(), rangeio::WriteError> {
    let json = serde_json::json!({ "camera": camera, "planes": planes });
    let text = serde_json::to_string_pretty(&json).expect("json values serialise");
    rangeio::write_atomic(path, text.as_bytes())
}

//! Writing one image's pipeline results to disk in the ABW formats and as PNGs.

use crate::pipeline::Output;
use crate::planes::Plane;
use rangeimage::{Camera, LabelImage, Region};
use rangeio::Frame;
use std::path::Path;

/// Writes `labels` as an ABW `.ms-seg` (renumbered from 10 as the format needs), the regions' normals as a
/// `.ms-nor` under the same labels, and every label unchanged as a 16-bit gray PNG beside the `.ms-seg`
/// (`NAME.labels.png`, 0 = none), which keeps the regions the `.ms-seg`'s 246-region cap drops;
/// returns the `(label, written label)` pairs of the `.ms-seg`.
///
/// Regions lost to the cap are reported with `tracing::warn!` (see [`ms_seg_cap_loss`]).
pub fn write_segmentation(
    seg_path: &Path,
    nor_path: &Path,
    labels: &LabelImage,
    regions: &[Region],
) -> Result<Vec<(u32, u8)>, rangeio::WriteError> {
    let labels_path = labels_png_path(seg_path);
    rangeio::png::write_label16_png(&labels_path, labels)?;
    let mapping = rangeio::abw::write_labels(seg_path, labels)?;
    let normals: Vec<(u32, [f32; 3])> = mapping
        .iter()
        .filter(|&&(_, new)| new != 0)
        .filter_map(|&(old, new)| regions.iter().find(|r| r.label == old).map(|r| (u32::from(new), r.normal)))
        .collect();
    rangeio::abw::write_normals(nor_path, &normals)?;
    let (lost, lost_px) = ms_seg_cap_loss(labels, &mapping);
    if lost > 0 {
        tracing::warn!(
            "{}: the .ms-seg format holds at most 246 regions: {lost} of {} regions ({lost_px} px) are 0 in it; \
             {} has them all",
            seg_path.display(),
            lost + mapping.len(),
            labels_path.display()
        );
    }
    Ok(mapping)
}

/// `NAME.labels.png` beside `NAME.ms-seg`.
pub fn labels_png_path(seg_path: &Path) -> std::path::PathBuf {
    let stem = seg_path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    seg_path.with_file_name(format!("{stem}.labels.png"))
}

/// Regions (and their pixels) of `labels` that the `.ms-seg` written with `mapping` sets to 0.
pub fn ms_seg_cap_loss(labels: &LabelImage, mapping: &[(u32, u8)]) -> (usize, u64) {
    let kept: std::collections::HashSet<u32> = mapping.iter().map(|&(l, _)| l).collect();
    let mut lost = std::collections::HashSet::new();
    let mut px = 0;
    for &l in labels.as_slice() {
        if l != 0 && !kept.contains(&l) {
            lost.insert(l);
            px += 1;
        }
    }
    (lost.len(), px)
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
    let _s = tracing::info_span!("write_outputs", stem).entered();
    let path = |ext: &str| dir.join(format!("{stem}.{ext}"));
    let mapping =
        write_segmentation(&path("ms-seg"), &path("ms-nor"), &out.fin.labels, &out.fin.final_regions)?;
    rangeio::png::write_edge_png(&path("edges.png"), out.fin.edges())?;
    rangeio::png::write_edge_png(&path("c1.png"), &out.regions.c1)?;
    rangeio::png::write_edge_png(&path("c2.png"), &out.canny.edges)?;
    rangeio::png::write_label_png(&path("regions.png"), &out.fin.labels)?;
    let planes = crate::planes::planes(&frame.range, &out.fin.labels, &frame.camera);
    write_planes_json(&path("planes.json"), &frame.camera, &planes)?;

    let (lost, lost_px) = ms_seg_cap_loss(&out.fin.labels, &mapping);
    let count = |e: &rangeimage::EdgeMap| e.as_slice().iter().filter(|&&b| b).count();
    let info = &out.fin.relax_info;
    Ok(serde_json::json!({
        "format": frame.format.to_string(),
        "width": frame.range.width(),
        "height": frame.range.height(),
        "regions_grown": out.regions.regions.len(),
        "regions_final": out.fin.final_regions.len(),
        "regions_written": mapping.len(),
        "regions_dropped_by_ms_seg_cap": lost,
        "px_dropped_by_ms_seg_cap": lost_px,
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

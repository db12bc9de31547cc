//! Writing one image's pipeline results to disk in the ABW formats and as PNGs.

use crate::pipeline::Output;
use crate::planes::Plane;
use rangeimage::{Camera, LabelImage, Region};
use rangeio::Frame;
use std::path::Path;

/// Writes `labels` as an ABW `.ms-seg` (renumbered from 10 as the format needs) and the regions' normals as a
/// `.ms-nor` under the same labels; returns the `(label, written label)` pairs.
pub fn write_segmentation(
    seg_path: &Path,
    nor_path: &Path,
    labels: &LabelImage,
    regions: &[Region],
) -> Result<Vec<(u32, u8)>, rangeio::WriteError> {
    let mapping = rangeio::abw::write_labels(seg_path, labels)?;
    let normals: Vec<(u32, [f32; 3])> = mapping
        .iter()
        .filter(|&&(_, new)| new != 0)
        .filter_map(|&(old, new)| regions.iter().find(|r| r.label == old).map(|r| (u32::from(new), r.normal)))
        .collect();
    rangeio::abw::write_normals(nor_path, &normals)?;
    Ok(mapping)
}

/// Writes `STEM.ms-seg`, `STEM.ms-nor`, `STEM.edges.png`, `STEM.c1.png`, `STEM.c2.png`, `STEM.regions.png` and
/// `STEM.planes.json` ([`write_planes_json`]) into `dir`, each atomically, and returns a JSON summary (counts, energies) for `STEM.json`.
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

    let count = |e: &rangeimage::EdgeMap| e.as_slice().iter().filter(|&&b| b).count();
    let info = &out.fin.relax_info;
    Ok(serde_json::json!({
        "format": frame.format.to_string(),
        "width": frame.range.width(),
        "height": frame.range.height(),
        "regions_grown": out.regions.regions.len(),
        "regions_final": out.fin.final_regions.len(),
        "regions_written": mapping.len(),
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

//! Organized PCD point clouds (PCL's format): `ascii`, `binary` and `binary_compressed` (LZF).
//!
//! The range image of a cloud is its `z` field in metres (NaN where x, y or z is not finite, or
//! z ≤ 0). Points are in the camera frame (x right, y down, z forward), one per pixel, row-major.

use crate::{Format, ReadError, check_dims, default_pinhole, lzf};
use rangeimage::{Camera, Grid, RangeImage};
use std::path::Path;

/// The x, y and z grids of an organized cloud.
#[derive(Debug, Clone, PartialEq)]
pub struct Cloud {
    /// x in metres; NaN for invalid points.
    pub x: Grid<f32>,
    /// y in metres; NaN for invalid points.
    pub y: Grid<f32>,
    /// z in metres (the range image); NaN for invalid points.
    pub z: RangeImage,
    /// Which `DATA` encoding the file used.
    pub format: Format,
    /// Bits of the stored z field (32 or 64).
    pub z_bits: u8,
}

/// True if `bytes` start like a PCD header.
pub fn looks_like_pcd(bytes: &[u8]) -> bool {
    [&b"# .PCD"[..], b"VERSION", b"FIELDS"].iter().any(|m| bytes.starts_with(m))
}

#[derive(Debug)]
struct Field {
    name: String,
    size: usize,
    kind: u8,
    count: usize,
    offset: usize,
}

const MAX_HEADER_LINES: usize = 64;
const MAX_RECORD_BYTES: usize = 1 << 16;

/// Reads an organized PCD file (see [`pcd_from_bytes`]).
pub fn read_pcd(path: &Path) -> Result<Cloud, ReadError> {
    pcd_from_bytes(&crate::read_file(path)?, path)
}

/// Decodes an organized PCD from memory; `path` names the file in errors.
///
/// Needs fields `x`, `y`, `z` of type `F` (4 or 8 bytes, count 1) and `HEIGHT` > 1.
pub fn pcd_from_bytes(bytes: &[u8], path: &Path) -> Result<Cloud, ReadError> {
    pcd_from_bytes_limited(bytes, path, crate::DEFAULT_MAX_PIXELS)
}

/// [`pcd_from_bytes`] refusing headers of more than `max_pixels` points.
pub(crate) fn pcd_from_bytes_limited(bytes: &[u8], path: &Path, max_pixels: u64) -> Result<Cloud, ReadError> {
    let header = parse_header(bytes, path)?;
    let p = || path.to_path_buf();
    if header.height == 1 {
        return Err(ReadError::Unsupported {
            path: p(),
            what: "unorganized point cloud (HEIGHT 1): a range image needs an organized cloud".into(),
        });
    }
    let (w, h) = check_dims(path, header.width, header.height, max_pixels)?;
    let n = w * h;
    if let Some(pts) = header.points
        && pts != n as u64
    {
        return Err(ReadError::Invalid {
            path: p(),
            what: format!("pcd header: POINTS {pts} but WIDTH·HEIGHT = {n}"),
        });
    }
    let fields = field_layout(&header, path)?;
    let record: usize = fields.iter().map(|f| f.size * f.count).sum();
    let xyz = xyz_fields(&fields, &header.names, path)?;
    let data = &bytes[header.data_start..];
    let [xs, ys, zs] = match header.format {
        Format::PcdAscii => decode_ascii(bytes, header.data_start, &fields, xyz, n, path)?,
        Format::PcdBinary => {
            let need = n as u64 * record as u64;
            if (data.len() as u64) < need {
                return Err(ReadError::Truncated {
                    path: p(),
                    what: "pcd binary point data",
                    expected: header.data_start as u64 + need,
                    found: bytes.len() as u64,
                });
            }
            xyz.map(|f| (0..n).map(|i| read_float(data, i * record + f.offset, f.size)).collect())
        }
        _ => decode_compressed(bytes, header.data_start, record, xyz, n, path)?,
    };
    let valid: Vec<bool> =
        (0..n).map(|i| xs[i].is_finite() && ys[i].is_finite() && zs[i].is_finite() && zs[i] > 0.0).collect();
    let grid = |v: &[f64]| {
        let data = v.iter().zip(&valid).map(|(&a, &ok)| if ok { a as f32 } else { f32::NAN }).collect();
        Grid::from_vec(w as u32, h as u32, data).expect("n = w·h")
    };
    Ok(Cloud {
        x: grid(&xs),
        y: grid(&ys),
        z: grid(&zs),
        format: header.format,
        z_bits: 8 * xyz[2].size as u8,
    })
}

/// The header lines of a PCD file, up to and including `DATA`.
struct Header {
    names: Vec<String>,
    sizes: Vec<u64>,
    types: Vec<String>,
    counts: Vec<u64>,
    width: u64,
    height: u64,
    points: Option<u64>,
    format: Format,
    /// Offset of the first byte after the `DATA` line.
    data_start: usize,
}

/// Reads the header (at most [`MAX_HEADER_LINES`] lines): every required line present, one entry
/// per field in `SIZE`, `TYPE` and `COUNT` (`COUNT` defaults to 1 each).
fn parse_header(bytes: &[u8], path: &Path) -> Result<Header, ReadError> {
    let p = || path.to_path_buf();
    let perr = |line: usize, problem: String| ReadError::Parse { path: p(), line, problem };
    let mut pos = 0;
    let mut names: Option<Vec<String>> = None;
    let (mut sizes, mut types, mut counts) = (None, None, None);
    let (mut width, mut height, mut points): (Option<u64>, Option<u64>, Option<u64>) = (None, None, None);
    let mut data_kind = None;
    for line_no in 1..=MAX_HEADER_LINES {
        if pos >= bytes.len() {
            break;
        }
        let end = bytes[pos..].iter().position(|&b| b == b'\n').map_or(bytes.len(), |i| pos + i);
        let line = std::str::from_utf8(&bytes[pos..end])
            .map_err(|_| perr(line_no, "header line is not text".into()))?
            .trim();
        pos = (end + 1).min(bytes.len());
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let mut toks = line.split_ascii_whitespace();
        let key = toks.next().unwrap_or_default().to_ascii_uppercase();
        let rest: Vec<&str> = toks.collect();
        let num = |t: &str| {
            t.parse::<u64>().map_err(|_| perr(line_no, format!("{key}: `{t}` is not a whole number")))
        };
        let single = |rest: &[&str]| -> Result<u64, ReadError> {
            match rest {
                [t] => num(t),
                _ => Err(perr(line_no, format!("{key} needs one value"))),
            }
        };
        match key.as_str() {
            "VERSION" | "VIEWPOINT" => {}
            "FIELDS" => names = Some(rest.iter().map(|s| s.to_string()).collect()),
            "SIZE" => sizes = Some(rest.iter().map(|t| num(t)).collect::<Result<Vec<_>, _>>()?),
            "COUNT" => counts = Some(rest.iter().map(|t| num(t)).collect::<Result<Vec<_>, _>>()?),
            "TYPE" => types = Some(rest.iter().map(|t| t.to_ascii_uppercase()).collect::<Vec<_>>()),
            "WIDTH" => width = Some(single(&rest)?),
            "HEIGHT" => height = Some(single(&rest)?),
            "POINTS" => points = Some(single(&rest)?),
            "DATA" => {
                data_kind = Some(match rest.as_slice() {
                    ["ascii"] => Format::PcdAscii,
                    ["binary"] => Format::PcdBinary,
                    ["binary_compressed"] => Format::PcdBinaryCompressed,
                    _ => return Err(perr(line_no, format!("unknown DATA `{}`", rest.join(" ")))),
                });
                break;
            }
            _ => {
                let shown: String = key.chars().take(32).collect();
                return Err(perr(line_no, format!("unknown header keyword `{shown}`")));
            }
        }
    }
    let Some(format) = data_kind else {
        return Err(ReadError::Invalid { path: p(), what: "pcd header: no DATA line".into() });
    };
    let missing = |what: &str| ReadError::Invalid { path: p(), what: format!("pcd header: no {what} line") };
    let names = names.ok_or_else(|| missing("FIELDS"))?;
    let sizes = sizes.ok_or_else(|| missing("SIZE"))?;
    let types = types.ok_or_else(|| missing("TYPE"))?;
    let counts = counts.unwrap_or_else(|| vec![1; names.len()]);
    let (width, height) = (width.ok_or_else(|| missing("WIDTH"))?, height.ok_or_else(|| missing("HEIGHT"))?);
    if sizes.len() != names.len() || types.len() != names.len() || counts.len() != names.len() {
        return Err(ReadError::Invalid {
            path: p(),
            what: format!(
                "pcd header: FIELDS has {} entries but SIZE {}, TYPE {}, COUNT {}",
                names.len(),
                sizes.len(),
                types.len(),
                counts.len()
            ),
        });
    }
    Ok(Header { names, sizes, types, counts, width, height, points, format, data_start: pos })
}

/// The byte layout of one point record: every field a supported type, the record at most
/// [`MAX_RECORD_BYTES`] long, no name but `_` twice.
fn field_layout(header: &Header, path: &Path) -> Result<Vec<Field>, ReadError> {
    let p = || path.to_path_buf();
    let (names, sizes, types, counts) = (&header.names, &header.sizes, &header.types, &header.counts);
    let mut fields = Vec::with_capacity(names.len());
    let mut offset = 0usize;
    for i in 0..names.len() {
        let (size, count) = (sizes[i], counts[i]);
        let kind = types[i].as_bytes().first().copied().unwrap_or(b'?');
        if types[i].len() != 1
            || !matches!(kind, b'I' | b'U' | b'F')
            || !matches!(size, 1 | 2 | 4 | 8)
            || count == 0
        {
            return Err(ReadError::Unsupported {
                path: p(),
                what: format!("pcd field layout `{}`: SIZE {size} TYPE {} COUNT {count}", names[i], types[i]),
            });
        }
        let bytes_here = (size * count) as usize;
        if count > MAX_RECORD_BYTES as u64 || offset + bytes_here > MAX_RECORD_BYTES {
            return Err(ReadError::Unsupported {
                path: p(),
                what: "pcd point record longer than 65536 bytes".into(),
            });
        }
        fields.push(Field {
            name: names[i].clone(),
            size: size as usize,
            kind,
            count: count as usize,
            offset,
        });
        offset += bytes_here;
    }
    // PCL pads records with fields named `_`; any other name must be unique, or which `z` is the
    // range would be a guess.
    for (i, name) in names.iter().enumerate() {
        if name != "_" && names[..i].contains(name) {
            return Err(ReadError::Invalid {
                path: p(),
                what: format!("pcd header: field `{name}` appears more than once in FIELDS"),
            });
        }
    }
    Ok(fields)
}

/// The `x`, `y` and `z` fields, each one `F4` or `F8` value.
fn xyz_fields<'a>(fields: &'a [Field], names: &[String], path: &Path) -> Result<[&'a Field; 3], ReadError> {
    let find = |name: &str| -> Result<&Field, ReadError> {
        let f = fields.iter().find(|f| f.name == name).ok_or_else(|| ReadError::Unsupported {
            path: path.to_path_buf(),
            what: format!("pcd field layout: no `{name}` field (fields: {})", names.join(" ")),
        })?;
        if f.kind != b'F' || !matches!(f.size, 4 | 8) || f.count != 1 {
            return Err(ReadError::Unsupported {
                path: path.to_path_buf(),
                what: format!(
                    "pcd field layout: `{name}` must be one F4 or F8 value, is {}{} ×{}",
                    f.kind as char, f.size, f.count
                ),
            });
        }
        Ok(f)
    };
    Ok([find("x")?, find("y")?, find("z")?])
}

/// x, y and z of the `n` points of `DATA ascii` (one point per non-blank line from `data_start`).
fn decode_ascii(
    bytes: &[u8],
    data_start: usize,
    fields: &[Field],
    xyz: [&Field; 3],
    n: usize,
    path: &Path,
) -> Result<[Vec<f64>; 3], ReadError> {
    let p = || path.to_path_buf();
    let perr = |line: usize, problem: String| ReadError::Parse { path: p(), line, problem };
    let text = std::str::from_utf8(&bytes[data_start..])
        .map_err(|_| ReadError::Invalid { path: p(), what: "pcd ascii data: not text".into() })?;
    let tokens_per_point: usize = fields.iter().map(|f| f.count).sum();
    // Token index of each of x, y, z within a point's line.
    let tok_index: Vec<usize> =
        xyz.iter().map(|f| fields.iter().take_while(|g| g.name != f.name).map(|g| g.count).sum()).collect();
    let mut out = [vec![0f64; 0], vec![], vec![]];
    for o in &mut out {
        o.reserve(n.min(text.len() / 2 + 1));
    }
    let header_lines = bytes[..data_start].iter().filter(|&&b| b == b'\n').count();
    let mut lines = text.lines().enumerate().filter(|(_, l)| !l.trim().is_empty());
    for _ in 0..n {
        let Some((i, line)) = lines.next() else {
            return Err(ReadError::Invalid {
                path: p(),
                what: format!("pcd ascii data: expected {n} points, found {}", out[0].len()),
            });
        };
        let toks: Vec<&str> = line.split_ascii_whitespace().collect();
        if toks.len() != tokens_per_point {
            return Err(perr(
                header_lines + i + 1,
                format!("expected {tokens_per_point} values, found {}", toks.len()),
            ));
        }
        for k in 0..3 {
            let t = toks[tok_index[k]];
            let v: f64 = t.parse().map_err(|_| {
                perr(header_lines + i + 1, format!("`{}` is not a number", &t[..t.len().min(32)]))
            })?;
            out[k].push(v);
        }
    }
    Ok(out)
}

/// x, y and z of the `n` points of `DATA binary_compressed` (two little-endian u32 sizes, then the
/// LZF payload of the fields stored one after the other).
fn decode_compressed(
    bytes: &[u8],
    data_start: usize,
    record: usize,
    xyz: [&Field; 3],
    n: usize,
    path: &Path,
) -> Result<[Vec<f64>; 3], ReadError> {
    let p = || path.to_path_buf();
    let (pos, data) = (data_start, &bytes[data_start..]);
    if data.len() < 8 {
        return Err(ReadError::Truncated {
            path: p(),
            what: "pcd binary_compressed sizes",
            expected: pos as u64 + 8,
            found: bytes.len() as u64,
        });
    }
    let compressed = u32::from_le_bytes([data[0], data[1], data[2], data[3]]) as usize;
    let uncompressed = u32::from_le_bytes([data[4], data[5], data[6], data[7]]) as usize;
    let payload = &data[8..];
    if payload.len() < compressed {
        return Err(ReadError::Truncated {
            path: p(),
            what: "pcd lzf payload",
            expected: (pos + 8 + compressed) as u64,
            found: bytes.len() as u64,
        });
    }
    let need = n as u64 * record as u64;
    if uncompressed as u64 != need {
        return Err(ReadError::Invalid {
            path: p(),
            what: format!(
                "pcd binary_compressed: uncompressed size {uncompressed}, but {n} points × {record} bytes = {need}"
            ),
        });
    }
    // LZF expands at most 132 bytes out per 2 bytes in; refuse impossible sizes before allocating.
    if uncompressed as u64 > 66 * compressed as u64 + 64 {
        return Err(ReadError::Lzf {
            path: p(),
            problem: format!("{compressed} compressed bytes cannot hold {uncompressed} bytes"),
        });
    }
    let raw = lzf::decompress(&payload[..compressed], uncompressed)
        .map_err(|problem| ReadError::Lzf { path: p(), problem })?;
    Ok(xyz.map(|f| {
        let base = n * f.offset;
        (0..n).map(|i| read_float(&raw, base + i * f.size, f.size)).collect()
    }))
}

fn read_float(buf: &[u8], at: usize, size: usize) -> f64 {
    if size == 4 {
        f64::from(f32::from_le_bytes(buf[at..at + 4].try_into().expect("4 bytes")))
    } else {
        f64::from_le_bytes(buf[at..at + 8].try_into().expect("8 bytes"))
    }
}

/// Fits `t = a·s + b` by least squares; `None` without spread in `s`.
fn fit_line(pairs: impl Iterator<Item = (f64, f64)> + Clone) -> Option<(f64, f64)> {
    let (mut n, mut ms, mut mt) = (0.0, 0.0, 0.0);
    for (s, t) in pairs.clone() {
        n += 1.0;
        ms += s;
        mt += t;
    }
    if n < 2.0 {
        return None;
    }
    (ms, mt) = (ms / n, mt / n);
    let (mut sst, mut sss) = (0.0, 0.0);
    for (s, t) in pairs {
        sst += (s - ms) * (t - mt);
        sss += (s - ms) * (s - ms);
    }
    (sss > 0.0).then(|| (sst / sss, mt - sst / sss * ms))
}

/// A pinhole camera fitted to the cloud: `x/z = (u − cx)/fx`, `y/z = (v − cy)/fy` by least squares.
///
/// Falls back to [`default_pinhole`] when the points do not determine a camera with positive focal
/// lengths. The depth scale is 1 (the range image is already in metres).
pub fn estimate_camera(cloud: &Cloud) -> Camera {
    let w = cloud.z.width();
    let pts = || {
        cloud.z.as_slice().iter().enumerate().filter(|(_, z)| !z.is_nan()).map(move |(i, &z)| {
            let (u, v) = ((i as u32 % w) as f64, (i as u32 / w) as f64);
            (
                u,
                v,
                f64::from(cloud.x.as_slice()[i]) / f64::from(z),
                f64::from(cloud.y.as_slice()[i]) / f64::from(z),
            )
        })
    };
    let fx = fit_line(pts().map(|(u, _, a, _)| (u, a)));
    let fy = fit_line(pts().map(|(_, v, _, b)| (v, b)));
    match (fx, fy) {
        (Some((ax, bx)), Some((ay, by)))
            if ax > 0.0 && ay > 0.0 && (1.0 / ax).is_finite() && (1.0 / ay).is_finite() =>
        {
            Camera::Pinhole { fx: 1.0 / ax, fy: 1.0 / ay, cx: -bx / ax, cy: -by / ay, depth_scale: 1.0 }
        }
        _ => default_pinhole(cloud.z.width(), cloud.z.height()),
    }
}

/// Encodes a cloud of `x y z` F4 fields in the given `DATA` format (for tests and tools).
pub fn pcd_to_bytes(x: &Grid<f32>, y: &Grid<f32>, z: &Grid<f32>, format: Format) -> Vec<u8> {
    let (w, h) = z.dimensions();
    let n = z.len();
    let data = match format {
        Format::PcdAscii => "ascii",
        Format::PcdBinary => "binary",
        _ => "binary_compressed",
    };
    let mut out = format!(
        "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\n\
         WIDTH {w}\nHEIGHT {h}\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\nDATA {data}\n"
    )
    .into_bytes();
    let g = [x.as_slice(), y.as_slice(), z.as_slice()];
    match format {
        Format::PcdAscii => {
            for i in 0..n {
                out.extend_from_slice(format!("{} {} {}\n", g[0][i], g[1][i], g[2][i]).as_bytes());
            }
        }
        Format::PcdBinary => {
            for i in 0..n {
                for c in g {
                    out.extend_from_slice(&c[i].to_le_bytes());
                }
            }
        }
        _ => {
            let raw: Vec<u8> = g.iter().flat_map(|c| c.iter().flat_map(|v| v.to_le_bytes())).collect();
            let comp = lzf::compress_literal(&raw);
            out.extend_from_slice(&(comp.len() as u32).to_le_bytes());
            out.extend_from_slice(&(raw.len() as u32).to_le_bytes());
            out.extend_from_slice(&comp);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn plane_cloud() -> (Grid<f32>, Grid<f32>, Grid<f32>) {
        let (fx, fy, cx, cy) = (500.0f32, 510.0f32, 3.5f32, 2.0f32);
        let z = Grid::from_fn(8, 5, |x, y| {
            if (x, y) == (2, 3) { f32::NAN } else { 1.0 + 0.05 * x as f32 + 0.02 * y as f32 }
        });
        let xs = Grid::from_fn(8, 5, |x, y| (x as f32 - cx) * z[(x, y)] / fx);
        let ys = Grid::from_fn(8, 5, |x, y| (y as f32 - cy) * z[(x, y)] / fy);
        (xs, ys, z)
    }

    #[test]
    fn every_data_format_round_trips_and_fits_the_camera() {
        let (x, y, z) = plane_cloud();
        for format in [Format::PcdAscii, Format::PcdBinary, Format::PcdBinaryCompressed] {
            let c = pcd_from_bytes(&pcd_to_bytes(&x, &y, &z, format), Path::new("t.pcd")).unwrap();
            assert_eq!(c.format, format);
            assert!(c.z[(2, 3)].is_nan() && c.x[(2, 3)].is_nan());
            for (a, b) in c.z.as_slice().iter().zip(z.as_slice()).filter(|(a, _)| !a.is_nan()) {
                approx::assert_relative_eq!(*a, *b, max_relative = 1e-6);
            }
            let Camera::Pinhole { fx, fy, cx, cy, depth_scale } = estimate_camera(&c) else {
                panic!("not pinhole")
            };
            approx::assert_relative_eq!(fx, 500.0, max_relative = 1e-3);
            approx::assert_relative_eq!(fy, 510.0, max_relative = 1e-3);
            approx::assert_relative_eq!(cx, 3.5, epsilon = 1e-3);
            approx::assert_relative_eq!(cy, 2.0, epsilon = 1e-3);
            assert_eq!(depth_scale, 1.0);
        }
    }

    #[test]
    fn bad_layouts_are_errors() {
        let (x, y, z) = plane_cloud();
        let good = String::from_utf8(pcd_to_bytes(&x, &y, &z, Format::PcdAscii)).unwrap();
        let cases = [
            (good.replace("HEIGHT 5", "HEIGHT 1").replace("WIDTH 8", "WIDTH 40"), "unorganized point cloud"),
            (good.replace("TYPE F F F", "TYPE F F U"), "`z` must be one F4 or F8 value"),
            (good.replace("FIELDS x y z", "FIELDS x y q"), "no `z` field"),
            (good.replace("POINTS 40", "POINTS 41"), "POINTS 41 but"),
            (good.replace("DATA ascii", "DATA weird"), "unknown DATA"),
            (good.replace("WIDTH 8", "WIDTH 0"), "unsupported image size 0x5"),
            (good.replace("FIELDS x y z", "FIELDS x z z"), "field `z` appears more than once"),
            (format!("{}\n{good}", "é".repeat(40)), "unknown header keyword `ééé"),
        ];
        for (text, msg) in cases {
            let e = pcd_from_bytes(text.as_bytes(), Path::new("bad.pcd")).unwrap_err().to_string();
            assert!(e.starts_with("bad.pcd: ") && e.contains(msg), "{e}");
        }
        let bin = pcd_to_bytes(&x, &y, &z, Format::PcdBinary);
        let e = pcd_from_bytes(&bin[..bin.len() - 3], Path::new("b.pcd")).unwrap_err().to_string();
        assert!(e.contains("truncated pcd binary point data"), "{e}");
        let mut comp = pcd_to_bytes(&x, &y, &z, Format::PcdBinaryCompressed);
        let last = comp.len() - 33; // control byte of the last 32-byte literal run
        comp[last] = 0xff; // now a back-reference far before the start of the output
        let e = pcd_from_bytes(&comp, Path::new("c.pcd")).unwrap_err().to_string();
        assert!(e.starts_with("c.pcd: corrupt lzf data"), "{e}");
    }
}

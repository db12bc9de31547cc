//! PGM (netpbm gray) depth images: binary P5 and plain P2, 8 or 16 bits per sample.

use crate::{ReadError, WriteError, check_dims, write_atomic};
use rangeimage::Grid;
use std::path::Path;

/// A decoded PGM: samples widened to `u16` and the stored bit depth.
#[derive(Debug, Clone, PartialEq)]
pub struct Pgm {
    /// The samples as stored (not rescaled by maxval).
    pub samples: Grid<u16>,
    /// The header's maxval.
    pub maxval: u16,
    /// 8 (maxval ≤ 255) or 16.
    pub bits: u8,
}

/// Reads header tokens (skipping `#` comments) and returns the offset after the single whitespace
/// byte that ends the last token.
fn header_tokens(bytes: &[u8], n: usize) -> Option<(Vec<u64>, usize)> {
    let mut i = 2;
    let mut out = Vec::with_capacity(n);
    while out.len() < n {
        while i < bytes.len() && (bytes[i].is_ascii_whitespace() || bytes[i] == b'#') {
            if bytes[i] == b'#' {
                while i < bytes.len() && bytes[i] != b'\n' && bytes[i] != b'\r' {
                    i += 1;
                }
            } else {
                i += 1;
            }
        }
        let start = i;
        while i < bytes.len() && bytes[i].is_ascii_digit() {
            i += 1;
        }
        if start == i || i - start > 12 {
            return None;
        }
        out.push(std::str::from_utf8(&bytes[start..i]).ok()?.parse().ok()?);
    }
    if i >= bytes.len() || !bytes[i].is_ascii_whitespace() {
        return None;
    }
    Some((out, i + 1))
}

/// Decodes a PGM from memory; `path` names the file in errors.
///
/// 16-bit P5 samples are big-endian per the netpbm standard, little-endian with `little_endian`
/// (as the NYU Depth v2 toolbox writes them). Samples above maxval are an error.
pub fn pgm_from_bytes(bytes: &[u8], path: &Path, little_endian: bool) -> Result<Pgm, ReadError> {
    pgm_from_bytes_limited(bytes, path, little_endian, crate::DEFAULT_MAX_PIXELS)
}

/// [`pgm_from_bytes`] refusing headers of more than `max_pixels` pixels.
pub(crate) fn pgm_from_bytes_limited(
    bytes: &[u8],
    path: &Path,
    little_endian: bool,
    max_pixels: u64,
) -> Result<Pgm, ReadError> {
    let p = || path.to_path_buf();
    let plain = match bytes.get(..2) {
        Some(b"P5") => false,
        Some(b"P2") => true,
        _ => {
            return Err(ReadError::BadMagic {
                path: p(),
                expected: "pgm (P5 or P2)",
                found: String::from_utf8_lossy(&bytes[..bytes.len().min(2)]).into_owned(),
            });
        }
    };
    let Some((t, data_start)) = header_tokens(bytes, 3) else {
        return Err(ReadError::Invalid {
            path: p(),
            what: "pgm header: expected width, height and maxval".into(),
        });
    };
    let (w, h) = check_dims(path, t[0], t[1], max_pixels)?;
    let maxval = t[2];
    if maxval == 0 || maxval > 65535 {
        return Err(ReadError::Invalid {
            path: p(),
            what: format!("pgm maxval {maxval} (must be 1..=65535)"),
        });
    }
    let bytes_per = if maxval > 255 { 2 } else { 1 };
    let n = w * h;
    let data = &bytes[data_start..];
    let samples: Vec<u16> = if plain {
        plain_samples(data, n, maxval, path)?
    } else {
        let need = (n * bytes_per) as u64;
        if (data.len() as u64) < need {
            return Err(ReadError::Truncated {
                path: p(),
                what: "pgm pixel data",
                expected: data_start as u64 + need,
                found: bytes.len() as u64,
            });
        }
        if bytes_per == 1 {
            data[..n].iter().map(|&b| u16::from(b)).collect()
        } else {
            data[..2 * n]
                .chunks_exact(2)
                .map(|c| {
                    if little_endian {
                        u16::from_le_bytes([c[0], c[1]])
                    } else {
                        u16::from_be_bytes([c[0], c[1]])
                    }
                })
                .collect()
        }
    };
    if let Some(i) = samples.iter().position(|&s| u64::from(s) > maxval) {
        return Err(ReadError::Invalid {
            path: p(),
            what: format!(
                "pgm sample {} at pixel (x {}, y {}) exceeds maxval {maxval}{}",
                samples[i],
                i % w,
                i / w,
                if bytes_per == 2 && !little_endian {
                    " (little-endian 16-bit data? try the little-endian option)"
                } else {
                    ""
                }
            ),
        });
    }
    Ok(Pgm {
        samples: Grid::from_vec(w as u32, h as u32, samples).expect("length matches"),
        maxval: maxval as u16,
        bits: 8 * bytes_per as u8,
    })
}

/// The first `n` samples of a plain (P2) PGM's `data`, each at most `maxval`.
fn plain_samples(data: &[u8], n: usize, maxval: u64, path: &Path) -> Result<Vec<u16>, ReadError> {
    let p = || path.to_path_buf();
    let text = std::str::from_utf8(data)
        .map_err(|_| ReadError::Invalid { path: p(), what: "plain pgm data: not ascii".into() })?;
    let mut v = Vec::with_capacity(n.min(text.len() / 2 + 1));
    for tok in text.split_ascii_whitespace().take(n) {
        let s: u64 = tok.parse().map_err(|_| ReadError::Invalid {
            path: p(),
            what: format!("plain pgm sample `{}`", &tok[..tok.len().min(20)]),
        })?;
        if s > maxval {
            return Err(ReadError::Invalid {
                path: p(),
                what: format!("plain pgm sample {s} at index {} exceeds maxval {maxval}", v.len()),
            });
        }
        v.push(s as u16);
    }
    if v.len() < n {
        return Err(ReadError::Truncated {
            path: p(),
            what: "plain pgm samples",
            expected: n as u64,
            found: v.len() as u64,
        });
    }
    Ok(v)
}

/// Reads a PGM file (see [`pgm_from_bytes`]).
pub fn read_pgm(path: &Path, little_endian: bool) -> Result<Pgm, ReadError> {
    pgm_from_bytes(&crate::read_file(path)?, path, little_endian)
}

/// Encodes samples as a binary P5 PGM: 8-bit if every sample is ≤ 255, else 16-bit big-endian.
pub fn pgm_to_bytes(samples: &Grid<u16>) -> Vec<u8> {
    let maxval = samples.as_slice().iter().copied().max().unwrap_or(0).max(1);
    let maxval = if maxval <= 255 { 255 } else { 65535 };
    let mut out = format!("P5\n{} {}\n{maxval}\n", samples.width(), samples.height()).into_bytes();
    for &s in samples.as_slice() {
        if maxval == 255 {
            out.push(s as u8);
        } else {
            out.extend_from_slice(&s.to_be_bytes());
        }
    }
    out
}

/// Writes samples as a binary PGM (see [`pgm_to_bytes`]).
pub fn write_pgm(path: &Path, samples: &Grid<u16>) -> Result<(), WriteError> {
    if samples.is_empty() {
        return Err(WriteError::Invalid { path: path.to_path_buf(), what: "an empty image".into() });
    }
    write_atomic(path, &pgm_to_bytes(samples))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_both_byte_orders_and_comments() {
        let be = b"P5\n# a comment\n2 1\n65535\n\x01\x02\x03\x04";
        let g = pgm_from_bytes(be, Path::new("a.pgm"), false).unwrap();
        assert_eq!(g.samples.as_slice(), &[0x0102, 0x0304]);
        assert_eq!(g.bits, 16);
        let le = pgm_from_bytes(be, Path::new("a.pgm"), true).unwrap();
        assert_eq!(le.samples.as_slice(), &[0x0201, 0x0403]);
    }

    #[test]
    fn plain_pgm_reads() {
        let g = pgm_from_bytes(b"P2 3 1 255\n0 7 255\n", Path::new("p.pgm"), false).unwrap();
        assert_eq!(g.samples.as_slice(), &[0, 7, 255]);
        assert_eq!(g.bits, 8);
    }

    #[test]
    fn round_trip_8_and_16_bit() {
        for max in [200u16, 4000] {
            let img = Grid::from_fn(5, 3, |x, y| ((x * 3 + y * 17) * u32::from(max) / 100) as u16);
            let back = pgm_from_bytes(&pgm_to_bytes(&img), Path::new("r.pgm"), false).unwrap();
            assert_eq!(back.samples, img);
        }
    }

    #[test]
    fn bad_headers_are_errors() {
        let path = Path::new("bad.pgm");
        let cases: [(&[u8], &str); 5] = [
            (b"P6\n1 1\n255\n\0", "bad.pgm: not a pgm"),
            (b"P5\n0 4\n255\n", "bad.pgm: unsupported image size 0x4"),
            (b"P5\n99999 99999\n255\n", "bad.pgm: unsupported image size 99999x99999"),
            (b"P5\n4 4\n255\n\0\0", "bad.pgm: truncated pgm pixel data: expected 27 bytes, found 13"),
            (b"P5\n1 1\n0\n\0", "bad.pgm: invalid pgm maxval 0"),
        ];
        for (bytes, msg) in cases {
            let e = pgm_from_bytes(bytes, path, false).unwrap_err().to_string();
            assert!(e.starts_with(msg), "{e}");
        }
    }
}

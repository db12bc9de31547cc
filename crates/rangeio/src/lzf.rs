//! LZF decompression (the `binary_compressed` PCD payload), written from the liblzf format.
//!
//! A stream is a sequence of chunks. A control byte `c < 32` starts a literal run of `c + 1` bytes.
//! Otherwise `len = c >> 5` (7 means "add the next byte") and the back-reference offset is
//! `((c & 31) << 8) + next byte + 1`; `len + 2` bytes are copied from that far back in the output
//! (overlapping copies repeat bytes).

/// Decompresses `input` into exactly `expected_len` bytes.
///
/// Returns a description of the problem (truncated chunk, reference before the start, output
/// overrun or a short result) instead of panicking on corrupt data.
pub fn decompress(input: &[u8], expected_len: usize) -> Result<Vec<u8>, String> {
    let mut out = Vec::with_capacity(expected_len);
    let mut ip = 0;
    while ip < input.len() {
        let ctrl = usize::from(input[ip]);
        ip += 1;
        if ctrl < 32 {
            let len = ctrl + 1;
            if ip + len > input.len() {
                return Err(format!(
                    "literal run of {len} bytes at input offset {} runs past the end",
                    ip - 1
                ));
            }
            if out.len() + len > expected_len {
                return Err(format!("output overrun: more than the announced {expected_len} bytes"));
            }
            out.extend_from_slice(&input[ip..ip + len]);
            ip += len;
        } else {
            let mut len = ctrl >> 5;
            if len == 7 {
                let Some(&extra) = input.get(ip) else {
                    return Err("back-reference length byte missing at end of input".into());
                };
                len += usize::from(extra);
                ip += 1;
            }
            let Some(&low) = input.get(ip) else {
                return Err("back-reference offset byte missing at end of input".into());
            };
            ip += 1;
            len += 2;
            let back = ((ctrl & 0x1f) << 8) + usize::from(low) + 1;
            if back > out.len() {
                return Err(format!("back-reference {back} bytes behind output offset {}", out.len()));
            }
            if out.len() + len > expected_len {
                return Err(format!("output overrun: more than the announced {expected_len} bytes"));
            }
            let start = out.len() - back;
            for k in 0..len {
                let b = out[start + k];
                out.push(b);
            }
        }
    }
    if out.len() != expected_len {
        return Err(format!("decompressed to {} bytes, expected {expected_len}", out.len()));
    }
    Ok(out)
}

/// Compresses `input` with literal runs only (valid LZF, no size reduction); for tests and writers.
pub fn compress_literal(input: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(input.len() + input.len() / 32 + 1);
    for chunk in input.chunks(32) {
        out.push((chunk.len() - 1) as u8);
        out.extend_from_slice(chunk);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn literal_round_trip() {
        let data: Vec<u8> = (0..1000u32).map(|i| (i * 7 % 251) as u8).collect();
        assert_eq!(decompress(&compress_literal(&data), data.len()).unwrap(), data);
    }

    #[test]
    fn back_reference_repeats_bytes() {
        // "ab" literal, then copy 2+2=4 bytes from 2 back (ctrl = 2<<5 | 0, offset byte 1) → "ababab".
        let stream = [1, b'a', b'b', 2 << 5, 1];
        assert_eq!(decompress(&stream, 6).unwrap(), b"ababab");
        // Long form: len 7 + extra 3 = 10, +2 = 12 copies of "a".
        let stream = [0, b'a', 7 << 5, 3, 0];
        assert_eq!(decompress(&stream, 13).unwrap(), vec![b'a'; 13]);
    }

    #[test]
    fn corrupt_streams_are_errors() {
        assert!(decompress(&[5, 1, 2], 6).unwrap_err().contains("past the end"));
        assert!(decompress(&[1 << 5, 0], 3).unwrap_err().contains("back-reference"));
        assert!(decompress(&[1, b'a', b'b', 2 << 5, 1], 5).unwrap_err().contains("overrun"));
        assert!(decompress(&[0, b'a'], 2).unwrap_err().contains("expected 2"));
        assert!(decompress(&[0, b'a', 7 << 5], 20).unwrap_err().contains("missing"));
    }
}

//! Error types of every reader and writer in this crate.

use std::path::PathBuf;

/// An error's message with its first letter lower-cased and no trailing full stop
/// (OS and decoder messages start upper-case).
fn lower_first(e: &dyn std::fmt::Display) -> String {
    let s = e.to_string();
    let s = s.trim_end_matches('.');
    let mut c = s.chars();
    match c.next() {
        Some(f) => f.to_lowercase().chain(c).collect(),
        None => String::new(),
    }
}

/// Why a file could not be read. Every message starts with the file's path.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ReadError {
    /// The operating system could not open or read the file.
    #[error("{path}: {}", lower_first(error))]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error (its text is part of the message, so it is not chained as a source).
        error: std::io::Error,
    },
    /// The file ends before the header or data it announces.
    #[error("{path}: truncated {what}: expected {expected} bytes, found {found}")]
    Truncated {
        /// The file.
        path: PathBuf,
        /// Which part is cut short (`"sun rasterfile header"`, `"pixel data"`, …).
        what: &'static str,
        /// Bytes needed.
        expected: u64,
        /// Bytes present.
        found: u64,
    },
    /// The file does not start with the magic number of the expected format.
    #[error("{path}: not a {expected}: bad magic number {found}")]
    BadMagic {
        /// The file.
        path: PathBuf,
        /// The format that was expected.
        expected: &'static str,
        /// The first bytes found, as text.
        found: String,
    },
    /// The header gives a width or height of zero or beyond [`crate::MAX_SIDE`].
    #[error("{path}: unsupported image size {width}x{height} (each side must be 1..={max})", max = crate::MAX_SIDE)]
    Dimensions {
        /// The file.
        path: PathBuf,
        /// Width from the header.
        width: u64,
        /// Height from the header.
        height: u64,
    },
    /// The header announces more pixels than the reader's cap (`ReadOptions::max_pixels`).
    #[error(
        "{path}: image of {width}x{height} = {} pixels is over the limit of {max_pixels} pixels (raise it with --max-pixels)",
        width * height
    )]
    TooManyPixels {
        /// The file.
        path: PathBuf,
        /// Width from the header.
        width: u64,
        /// Height from the header.
        height: u64,
        /// The cap that was applied.
        max_pixels: u64,
    },
    /// A valid file of a kind this crate does not read (bit depth, compression, field layout …).
    #[error("{path}: unsupported {what}")]
    Unsupported {
        /// The file.
        path: PathBuf,
        /// What is unsupported, e.g. `"sun rasterfile depth 24 (only 8-bit is read)"`.
        what: String,
    },
    /// The header or data contradicts itself or the format.
    #[error("{path}: invalid {what}")]
    Invalid {
        /// The file.
        path: PathBuf,
        /// What is wrong, e.g. `"pgm maxval 0"`.
        what: String,
    },
    /// A label file breaks the ABW label rules (docs/method.md §2.1).
    #[error("{path}: {problem}")]
    Label {
        /// The file.
        path: PathBuf,
        /// Which label, where, and which rule it breaks.
        problem: String,
    },
    /// A line of a text file (`.gt-ang`, `.ms-nor`, PCD header) could not be parsed.
    #[error("{path}: line {line}: {problem}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// What is wrong with the line.
        problem: String,
    },
    /// LZF-compressed data (PCD `binary_compressed`) is corrupt.
    #[error("{path}: corrupt lzf data: {problem}")]
    Lzf {
        /// The file.
        path: PathBuf,
        /// What the decoder found.
        problem: String,
    },
    /// The `image` crate could not decode a PNG or TIFF.
    #[error("{path}: cannot decode image: {}", lower_first(error))]
    Image {
        /// The file.
        path: PathBuf,
        /// The decoder's error (its text is part of the message).
        error: image::ImageError,
    },
    /// The format could not be recognised from the magic bytes or the extension.
    #[error("{path}: unrecognised file format (expected sun rasterfile, pgm, png, tiff or pcd)")]
    UnknownFormat {
        /// The file.
        path: PathBuf,
    },
    /// A directory holds no ABW range files.
    #[error("{path}: no ABW range files (abw.train.N.range or abw.test.N.range) in this directory")]
    NoAbwFiles {
        /// The directory.
        path: PathBuf,
    },
}

impl ReadError {
    /// The file the error is about.
    pub fn path(&self) -> &std::path::Path {
        match self {
            ReadError::Io { path, .. }
            | ReadError::Truncated { path, .. }
            | ReadError::BadMagic { path, .. }
            | ReadError::Dimensions { path, .. }
            | ReadError::TooManyPixels { path, .. }
            | ReadError::Unsupported { path, .. }
            | ReadError::Invalid { path, .. }
            | ReadError::Label { path, .. }
            | ReadError::Parse { path, .. }
            | ReadError::Lzf { path, .. }
            | ReadError::Image { path, .. }
            | ReadError::UnknownFormat { path }
            | ReadError::NoAbwFiles { path } => path,
        }
    }
}

/// Why a file could not be written. Every message starts with the file's path.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum WriteError {
    /// The operating system could not create, write or rename the file.
    #[error("{path}: {}", lower_first(error))]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error (its text is part of the message, so it is not chained as a source).
        error: std::io::Error,
    },
    /// The `image` crate could not encode the image.
    #[error("{path}: cannot encode image: {}", lower_first(error))]
    Image {
        /// The file.
        path: PathBuf,
        /// The encoder's error (its text is part of the message).
        error: image::ImageError,
    },
    /// The data cannot be stored in this format (empty image, too large …).
    #[error("{path}: cannot write {what}")]
    Invalid {
        /// The file.
        path: PathBuf,
        /// What cannot be written and why.
        what: String,
    },
}

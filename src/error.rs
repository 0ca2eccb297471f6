//! One error type for the whole crate: every failure names *what* (usually a file) and *why*,
//! and, where it helps, what to do about it. No panics on user input.

use std::fmt;
use std::path::{Path, PathBuf};

#[derive(Debug)]
pub enum Error {
    /// Reading or writing `path` failed at the OS level.
    Io { path: PathBuf, source: std::io::Error },
    /// `path` exists but its contents are malformed (bad header, truncated, NaN, wrong topology …).
    Format { path: PathBuf, msg: String },
    /// Tensors, configs or meshes that do not fit together.
    Shape(String),
    /// Bad parameters or options.
    Config(String),
    /// One field of a parameter struct or job out of range, named as the library names it
    /// (`eta`, `fps`, `chunk`); a front end renames it to its own spelling ([`Error::renamed`]:
    /// the command line's `--eta`, the C ABI's struct fields).
    Invalid { field: &'static str, msg: String },
    /// A numeric failure (NaN/Inf loss, a solver that did not converge …).
    Numeric(String),
    /// The CUDA path is unavailable or failed.
    Device(String),
    /// Bytes or text that are not what they claim, found by a parser that does not know the
    /// file they came from ([`Error::in_file`] names it).
    Malformed(String),
    /// Memory for a frame could not be had (asked of the allocator fallibly, or over a limit
    /// the caller set): the message says how much, and what to do.
    OutOfMemory(String),
}

pub type Result<T> = std::result::Result<T, Error>;

impl Error {
    pub fn io(path: impl AsRef<Path>, source: std::io::Error) -> Self {
        Error::Io { path: path.as_ref().to_path_buf(), source }
    }
    pub fn format(path: impl AsRef<Path>, msg: impl Into<String>) -> Self {
        Error::Format { path: path.as_ref().to_path_buf(), msg: msg.into() }
    }
    pub fn shape(msg: impl Into<String>) -> Self {
        Error::Shape(msg.into())
    }
    pub fn config(msg: impl Into<String>) -> Self {
        Error::Config(msg.into())
    }
    /// Field `field` of a parameter struct or job is out of range: `msg` says what it must be.
    pub fn invalid(field: &'static str, msg: impl Into<String>) -> Self {
        Error::Invalid { field, msg: msg.into() }
    }
    /// An [`Error::Invalid`]'s field under a front end's name for it (`name(field)`); any other
    /// error as it is.
    pub fn renamed(self, name: impl Fn(&'static str) -> &'static str) -> Self {
        match self {
            Error::Invalid { field, msg } => Error::Invalid { field: name(field), msg },
            e => e,
        }
    }
    pub fn numeric(msg: impl Into<String>) -> Self {
        Error::Numeric(msg.into())
    }
    pub fn device(msg: impl Into<String>) -> Self {
        Error::Device(msg.into())
    }
    /// Attach a file to an error that did not know it (e.g. a shape error while loading `path`).
    pub fn in_file(self, path: impl AsRef<Path>) -> Self {
        match self {
            Error::Shape(m) | Error::Config(m) | Error::Numeric(m) | Error::Malformed(m) => {
                Error::format(path, m)
            }
            e => e,
        }
    }
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Error::Io { path, source } => write!(f, "{}: {}", path.display(), source),
            Error::Format { path, msg } => write!(f, "{}: {}", path.display(), msg),
            Error::Shape(m) => write!(f, "shape mismatch: {m}"),
            Error::Config(m) => write!(f, "invalid option: {m}"),
            Error::Invalid { field, msg } => write!(f, "invalid option {field}: {msg}"),
            Error::Numeric(m) => write!(f, "numeric failure: {m}"),
            Error::Device(m) => write!(f, "device: {m}"),
            Error::OutOfMemory(m) => write!(f, "out of memory: {m}"),
            Error::Malformed(m) => write!(f, "malformed data: {m}"),
        }
    }
}

impl std::error::Error for Error {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            Error::Io { source, .. } => Some(source),
            _ => None,
        }
    }
}

//! The crate's one error type.

use std::path::PathBuf;

/// Everything that can go wrong building or loading a soft body.
#[derive(Debug, thiserror::Error)]
pub enum SoftBodyError {
    /// A mesh file could not be read from disk.
    #[error("mesh {path}: cannot read file: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The OS error.
        source: std::io::Error,
    },
    /// A mesh file was read but its content is not a valid mesh.
    #[error("mesh {path}: {what}")]
    Malformed {
        /// The file (or a description of the in-memory source).
        path: PathBuf,
        /// What is wrong and where.
        what: String,
    },
    /// The file extension names no format we load.
    #[error("mesh {path}: unsupported format (expected .obj, .gltf, .glb or .ply)")]
    UnsupportedFormat {
        /// The file.
        path: PathBuf,
    },
    /// A soft-body configuration value is out of range or inconsistent.
    #[error("soft body config: {0}")]
    Config(String),
    /// A handle refers to a soft body that has been removed.
    #[error("soft body handle {0:?} is not in this set")]
    InvalidHandle(crate::body::handle::SoftBodyHandle),
}

impl SoftBodyError {
    pub(crate) fn malformed(path: impl Into<PathBuf>, what: impl Into<String>) -> Self {
        Self::Malformed {
            path: path.into(),
            what: what.into(),
        }
    }
}

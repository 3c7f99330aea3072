//! Errors that point into a source file (spec, effect, log).
use std::fmt;
use std::path::{Path, PathBuf};

/// A 1-based line/column position in a file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SourcePos {
    pub line: usize,
    pub column: usize,
}

impl SourcePos {
    /// Position of a byte offset in `text`.
    pub fn from_offset(text: &str, offset: usize) -> Self {
        let offset = offset.min(text.len());
        let before = &text[..offset];
        let line = before.matches('\n').count() + 1;
        let column = before.rfind('\n').map_or(offset, |nl| offset - nl - 1) + 1;
        SourcePos { line, column }
    }
}

/// An error in a file, with the place it happened when known.
#[derive(Debug, Clone, thiserror::Error)]
pub struct SourceError {
    pub file: PathBuf,
    pub pos: Option<SourcePos>,
    pub message: String,
}

impl SourceError {
    pub fn new(file: &Path, pos: Option<SourcePos>, message: impl Into<String>) -> Self {
        SourceError {
            file: file.to_path_buf(),
            pos,
            message: message.into(),
        }
    }
}

impl fmt::Display for SourceError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.pos {
            Some(p) => write!(
                f,
                "{}:{}:{}: {}",
                self.file.display(),
                p.line,
                p.column,
                self.message
            ),
            None => write!(f, "{}: {}", self.file.display(), self.message),
        }
    }
}

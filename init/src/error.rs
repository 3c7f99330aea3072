//! What `kinegen init` refuses, located: the file, and the line of the element
//! (or YAML key) the problem is in.
use std::fmt;
use std::path::{Path, PathBuf};

/// A description kinegen cannot turn into a spec. Displayed as
/// `FILE:LINE: message`, the CLI's exit-2 form.
#[derive(Debug, Clone, PartialEq)]
pub struct InitError {
    pub file: PathBuf,
    /// 1-based; `None` when the problem is the whole file (or an option).
    pub line: Option<usize>,
    pub column: Option<usize>,
    pub message: String,
}

impl InitError {
    pub fn at(file: &Path, line: Option<usize>, message: impl Into<String>) -> InitError {
        InitError {
            file: file.to_path_buf(),
            line,
            column: None,
            message: message.into(),
        }
    }
}

impl fmt::Display for InitError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.file.display())?;
        if let Some(l) = self.line {
            write!(f, ":{l}")?;
            if let Some(c) = self.column {
                write!(f, ":{c}")?;
            }
        }
        write!(f, ": {}", self.message)
    }
}

impl std::error::Error for InitError {}

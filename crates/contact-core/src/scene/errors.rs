//! What validation reports: every problem found, each at an RFC 6901 pointer into the
//! submitted document.

use std::fmt;

use serde::Serialize;

/// One problem found in a scene, located by an RFC 6901 JSON pointer into the submitted
/// document ("" is the document itself). A missing required field is reported at the pointer
/// it would have.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct FieldError {
    pub pointer: String,
    pub message: String,
}

/// All the problems found in a scene (never empty when returned as an error).
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct ValidationErrors(pub Vec<FieldError>);

impl fmt::Display for ValidationErrors {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let n = self.0.len();
        write!(
            f,
            "invalid scene ({n} problem{})",
            if n == 1 { "" } else { "s" }
        )?;
        for e in &self.0 {
            let at = if e.pointer.is_empty() {
                "(document)"
            } else {
                &e.pointer
            };
            write!(f, "\n  at {at}: {}", e.message)?;
        }
        Ok(())
    }
}

impl std::error::Error for ValidationErrors {}

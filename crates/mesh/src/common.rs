//! Pieces every importer shares: turning a polygon into triangles (or counting why it
//! was dropped) and logging the skip counts, so PLY, OBJ and STL treat bad faces alike.

use std::path::Path;

use crate::{ImportReport, MeshError, MeshVisitor};

/// Fan-triangulates polygons and drops short or degenerate ones, counting each case.
#[derive(Default)]
pub(crate) struct PolygonEmitter {
    scratch: Vec<u32>,
    /// Polygons seen, to poll [`MeshVisitor::cancelled`] every [`POLL_EVERY`]: skipped
    /// faces reach no visitor call, and a file of 10^9 of them must stay interruptible.
    seen: u64,
}

impl PolygonEmitter {
    /// Deliver the polygon `corners` (already validated indices) as triangles.
    ///
    /// Fewer than 3 corners: counted in `short_faces_skipped`. Any index repeated: the
    /// whole face is counted in `degenerate_faces_skipped`. More than 3 corners: fan
    /// `(0, i, i + 1)`, counted in `polygons_triangulated`.
    #[inline]
    pub(crate) fn emit(
        &mut self,
        corners: &[u32],
        visitor: &mut dyn MeshVisitor,
        report: &mut ImportReport,
    ) -> Result<(), MeshError> {
        self.seen += 1;
        if self.seen.is_multiple_of(POLL_EVERY) {
            poll(visitor)?;
        }
        match *corners {
            [a, b, c] => {
                if a == b || b == c || a == c {
                    report.degenerate_faces_skipped += 1;
                } else {
                    visitor.triangle([a, b, c])?;
                    report.triangles += 1;
                }
                Ok(())
            }
            [] | [_] | [_, _] => {
                report.short_faces_skipped += 1;
                Ok(())
            }
            [first, ..] => self.emit_polygon(first, corners, visitor, report),
        }
    }

    fn emit_polygon(
        &mut self,
        first: u32,
        corners: &[u32],
        visitor: &mut dyn MeshVisitor,
        report: &mut ImportReport,
    ) -> Result<(), MeshError> {
        self.scratch.clear();
        self.scratch.extend_from_slice(corners);
        self.scratch.sort_unstable();
        if self.scratch.windows(2).any(|w| w[0] == w[1]) {
            report.degenerate_faces_skipped += 1;
            return Ok(());
        }
        for pair in corners[1..].windows(2) {
            visitor.triangle([first, pair[0], pair[1]])?;
            report.triangles += 1;
        }
        report.polygons_triangulated += 1;
        Ok(())
    }
}

/// Units of work (vertices, corners, skipped faces) between two polls of
/// [`MeshVisitor::cancelled`]: 65536 is well under a millisecond of any reader's work,
/// and the poll (an atomic load in the CLI) costs nothing at that rate.
pub(crate) const POLL_EVERY: u64 = 1 << 16;

/// [`MeshError::Interrupted`] when the visitor says stop.
#[inline]
pub(crate) fn poll(visitor: &dyn MeshVisitor) -> Result<(), MeshError> {
    if visitor.cancelled() {
        return Err(MeshError::Interrupted);
    }
    Ok(())
}

/// Distinct names [`ImportReport::ignored_by_name`] keeps; later ones go under `other names`
/// (with a space: no OBJ keyword or PLY element key is spelt so).
const MAX_IGNORED_NAMES: usize = 32;

/// Longest name kept, in characters (an OBJ keyword is whatever starts a line).
const MAX_IGNORED_NAME_CHARS: usize = 40;

/// Count `count` ignored statements or element entries called `name`.
pub(crate) fn note_ignored(report: &mut ImportReport, name: &str, count: u64) {
    report.ignored_statements += count;
    let names = &mut report.ignored_by_name;
    let name = match name.char_indices().nth(MAX_IGNORED_NAME_CHARS) {
        Some((cut, _)) => format!("{}...", &name[..cut]),
        None => name.to_string(),
    };
    let key = match names.contains_key(&name) || names.len() < MAX_IGNORED_NAMES {
        true => name,
        false => "other names".to_string(),
    };
    *names.entry(key).or_default() += count;
}

/// `cstype (2), element camera (1)`: the ignored names, most frequent first.
fn ignored_list(report: &ImportReport) -> String {
    let mut names: Vec<(&String, &u64)> = report.ignored_by_name.iter().collect();
    names.sort_by(|a, b| b.1.cmp(a.1).then(a.0.cmp(b.0)));
    let names: Vec<String> = names.iter().map(|(n, c)| format!("{n} ({c})")).collect();
    names.join(", ")
}

/// Log each kind of skipped input once, with its count.
pub(crate) fn log_skips(path: &Path, report: &ImportReport) {
    let p = path.display();
    if report.degenerate_faces_skipped > 0 {
        tracing::warn!(
            "{p}: skipped {} degenerate faces (a vertex index repeated)",
            report.degenerate_faces_skipped
        );
    }
    if report.short_faces_skipped > 0 {
        tracing::warn!(
            "{p}: skipped {} faces with fewer than 3 corners",
            report.short_faces_skipped
        );
    }
    if report.ignored_statements > 0 {
        tracing::warn!(
            "{p}: ignored {} unsupported statements or elements: {}",
            report.ignored_statements,
            ignored_list(report)
        );
    }
    if report.trailing_bytes_ignored > 0 {
        tracing::warn!(
            "{p}: ignoring {} bytes after the last element the header declares (more faces than declared, or garbage)",
            report.trailing_bytes_ignored
        );
    }
    if report.unterminated_last_line {
        tracing::warn!(
            "{p}: the file does not end with a newline; if it was cut short, its last number was read incomplete"
        );
    }
    if report.polygons_triangulated > 0 {
        tracing::debug!(
            "{p}: fan-triangulated {} polygons",
            report.polygons_triangulated
        );
    }
}

/// Fail with [`MeshError::Empty`] when nothing usable was read, else log the skips.
pub(crate) fn finish_report(path: &Path, report: ImportReport) -> Result<ImportReport, MeshError> {
    log_skips(path, &report);
    if report.triangles == 0 {
        return Err(MeshError::Empty {
            path: path.to_path_buf(),
        });
    }
    Ok(report)
}

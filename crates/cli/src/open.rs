//! Opening the MODEL argument of `info`, `render` and `extract`: a local path (memory-mapped) or an
//! `http://` URL (range requests through `tessera-http`).

use std::path::Path;
use std::sync::Arc;

use tessera_format::{FormatError, Model, PatchReader};
use tessera_http::{is_url, RemoteModel};

/// The model at `arg`, local or remote (callers add the context of their message).
pub fn open_model(arg: &Path) -> Result<Arc<dyn PatchReader>, FormatError> {
    let s = arg.to_string_lossy();
    Ok(if is_url(&s) {
        Arc::new(RemoteModel::open(&s)?)
    } else {
        Arc::new(Model::open(arg)?)
    })
}

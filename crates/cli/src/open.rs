//! Opening the MODEL argument of `info`, `render` and `extract`: a local path (memory-mapped) or an
//! `http://` URL (range requests through `tessera-http`).

use std::path::Path;
use std::sync::Arc;

use tessera_format::{FormatError, Model, PatchReader};
use tessera_http::{is_url, RemoteModel};

/// The model at `arg`, local or remote, its whole index read (callers add the context
/// of their message).
pub fn open_model(arg: &Path) -> Result<Arc<dyn PatchReader>, FormatError> {
    open_model_paged(arg, false)
}

/// The model at `arg`; with `paged`, a remote model reads only the top of its index
/// first and the rest as the view needs it (what progressive rendering wants). A local
/// model's index is always read whole: it is memory-mapped, reading it costs no
/// transfer.
pub fn open_model_paged(arg: &Path, paged: bool) -> Result<Arc<dyn PatchReader>, FormatError> {
    let s = arg.to_string_lossy();
    Ok(match (is_url(&s), paged) {
        (true, true) => Arc::new(RemoteModel::open_paged(&s)?),
        (true, false) => Arc::new(RemoteModel::open(&s)?),
        (false, _) => Arc::new(Model::open(arg)?),
    })
}

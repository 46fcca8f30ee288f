//! Builds the browser viewer into the binary: when `web/dist` (or `TESSERA_WEB_DIST`)
//! holds a complete build of it (`scripts/build-web`), its files are embedded with
//! `include_bytes!` and `tessera serve` serves them at `/` with no `--web`; otherwise
//! the list is empty and the server says how to get the viewer.

use std::path::PathBuf;

/// The viewer's files, as `scripts/build-web` writes them.
const FILES: [&str; 7] = [
    "index.html",
    "embed.html",
    "tessera.js",
    "tessera_worker.js",
    "tessera_web.js",
    "tessera_web_bg.wasm",
    "package.json",
];

/// Embedded too when the build has them: the three.js adapter, its example page and the
/// three.js files it loads (`scripts/build-web` copies them from web/node_modules).
const OPTIONAL: [&str; 6] = [
    "tessera-three.js",
    "three.html",
    "three/three.module.js",
    "three/three.core.js",
    "three/addons/controls/OrbitControls.js",
    "three/LICENSE",
];

fn main() {
    println!("cargo:rerun-if-env-changed=TESSERA_WEB_DIST");
    let manifest = PathBuf::from(std::env::var_os("CARGO_MANIFEST_DIR").unwrap());
    let dist = std::env::var_os("TESSERA_WEB_DIST")
        .map(PathBuf::from)
        .unwrap_or_else(|| manifest.join("../../web/dist"));
    let mut code = String::from(
        "/// The browser viewer's files built into this binary (name, bytes); empty when\n\
         /// `web/dist` was not built (`scripts/build-web`) before this crate.\n\
         pub static EMBEDDED_WEB: &[(&str, &[u8])] = &[\n",
    );
    // Their gzipped copies (`NAME.gz`, written by scripts/build-web beside the files
    // that compress), sent to clients that accept gzip.
    let mut gzipped = String::from(
        "/// Gzipped copies of [`EMBEDDED_WEB`]'s files that compress (name, bytes).\n\
         pub static EMBEDDED_WEB_GZIP: &[(&str, &[u8])] = &[\n",
    );
    if FILES.iter().all(|f| dist.join(f).is_file()) {
        // An optional file added later changes the directory.
        println!("cargo:rerun-if-changed={}", dist.display());
        let optional = OPTIONAL.into_iter().filter(|f| dist.join(f).is_file());
        for f in FILES.into_iter().chain(optional) {
            let p = dist.join(f).canonicalize().unwrap();
            println!("cargo:rerun-if-changed={}", p.display());
            code += &format!(
                "    ({f:?}, include_bytes!({:?})),\n",
                p.display().to_string()
            );
            let gz = dist.join(format!("{f}.gz"));
            // Only a copy at least as new as the file (a stale one would be wrong).
            let newer = |a: &PathBuf, b: &PathBuf| {
                let m = |p: &PathBuf| std::fs::metadata(p).and_then(|m| m.modified()).ok();
                m(a).zip(m(b)).is_some_and(|(a, b)| a >= b)
            };
            if gz.is_file() && newer(&gz, &p) {
                let gz = gz.canonicalize().unwrap();
                println!("cargo:rerun-if-changed={}", gz.display());
                gzipped += &format!(
                    "    ({f:?}, include_bytes!({:?})),\n",
                    gz.display().to_string()
                );
            }
        }
    } else {
        // Built later: the directory (or its parent, while it does not exist) changes.
        // The parent by name, not `dist/..`: a path through a missing directory cannot
        // be checked, so cargo would run this script (and relink the server) on every
        // build.
        let watch = if dist.is_dir() {
            dist.clone()
        } else {
            dist.parent().map_or_else(|| dist.clone(), PathBuf::from)
        };
        println!("cargo:rerun-if-changed={}", watch.display());
        println!(
            "cargo:warning=the browser viewer is not built into this tessera (no {}): \
             `tessera serve` will serve models but no viewer page; run scripts/build-web, \
             then build again (or serve one with --web DIR)",
            dist.join("index.html").display()
        );
    }
    code += "];\n";
    code += &gzipped;
    code += "];\n";
    let out = PathBuf::from(std::env::var_os("OUT_DIR").unwrap()).join("embedded_web.rs");
    if std::fs::read_to_string(&out).ok().as_deref() != Some(code.as_str()) {
        std::fs::write(&out, code).unwrap();
    }
}

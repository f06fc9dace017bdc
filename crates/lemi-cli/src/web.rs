//! The web viewer's files: `web/viewer` (HTML and scripts, in lemi's source tree) and three.js
//! from the npm package in `web/node_modules` (installed by `npm ci` in `web/`), copied into an
//! export directory so that it works offline, served from that directory alone.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context};

/// The viewer's own files, relative to `web/viewer`.
const VIEWER_FILES: [&str; 3] = ["index.html", "viewer.js", "predict.js"];

/// The files of the three.js package the viewer imports, relative to `node_modules/three`.
const THREE_FILES: [&str; 14] = [
    "LICENSE",
    "build/three.module.js",
    "build/three.core.js",
    "examples/jsm/loaders/GLTFLoader.js",
    // meshoptimizer's decoder (MIT, WebAssembly inside the module) for EXT_meshopt_compression
    "examples/jsm/libs/meshopt_decoder.module.js",
    "examples/jsm/utils/BufferGeometryUtils.js",
    "examples/jsm/utils/SkeletonUtils.js",
    // KTX2 textures (`--textures ktx2`): the container reader and the Zstandard decoder
    // (WebAssembly inside the module); BC blocks need no Basis transcoder, ETC1S and UASTC
    // bundles' textures go through Binomial's transcoder (Apache-2.0, as three.js ships it)
    "examples/jsm/loaders/KTX2Loader.js",
    "examples/jsm/libs/basis/basis_transcoder.js",
    "examples/jsm/libs/basis/basis_transcoder.wasm",
    "examples/jsm/libs/ktx-parse.module.js",
    "examples/jsm/libs/zstddec.module.js",
    "examples/jsm/utils/WorkerPool.js",
    "examples/jsm/math/ColorSpaces.js",
];

/// `web/` of lemi's source tree, unless `--web-dir` says otherwise.
pub fn web_dir(given: Option<&Path>) -> PathBuf {
    match given {
        Some(d) => d.to_path_buf(),
        None => Path::new(env!("CARGO_MANIFEST_DIR")).join("../../web"),
    }
}

/// Copies the viewer and three.js into `out` (`out/index.html`, `out/vendor/three/…`).
pub fn install_viewer(out: &Path, given: Option<&Path>) -> anyhow::Result<()> {
    let web = web_dir(given);
    let three = web.join("node_modules/three");
    if !three.join("package.json").is_file() {
        bail!(
            "{}: three.js is not installed there; run `npm ci` in {} (the viewer's three.js comes from npm), or pass --web-dir",
            three.display(),
            web.display()
        );
    }
    for f in VIEWER_FILES {
        copy(&web.join("viewer").join(f), &out.join(f))?;
    }
    for f in THREE_FILES {
        copy(&three.join(f), &out.join("vendor/three").join(f))?;
    }
    Ok(())
}

fn copy(from: &Path, to: &Path) -> anyhow::Result<()> {
    let bytes = std::fs::read(from).with_context(|| format!("reading {}", from.display()))?;
    if let Some(dir) = to.parent() {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    lemi_core::container::write_atomic(to, &bytes)
        .with_context(|| format!("writing {}", to.display()))
}

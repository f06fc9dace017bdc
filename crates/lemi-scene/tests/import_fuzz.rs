//! Property test: random bytes, random truncations and random byte changes of valid files never
//! make any reader panic. The loader turns a reader panic into an error mentioning a "reader
//! failure"; the property asserts that this never happens, so a panic anywhere fails the test.

mod import_common;

use std::path::Path;

use import_common::*;
use lemi_scene::{load, LoadOptions};
use proptest::prelude::*;

const KINDS: [&str; 6] = ["gltf", "glb", "obj", "ply", "ply", "ply.gz"];

/// A valid file of each kind (index as in [`KINDS`]), made once.
fn valid_files() -> &'static [Vec<u8>] {
    static FILES: std::sync::OnceLock<Vec<Vec<u8>>> = std::sync::OnceLock::new();
    FILES.get_or_init(make_valid_files)
}

fn make_valid_files() -> Vec<Vec<u8>> {
    let dir = tempfile::tempdir().expect("tempdir");
    let gltf = std::fs::read(write_gltf(dir.path(), "s.gltf", GltfStorage::DataUri)).expect("read");
    let glb = std::fs::read(write_gltf(dir.path(), "s.glb", GltfStorage::Binary)).expect("read");
    let obj = b"v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvn 0 0 1\nf 1/1/1 2/1/1 3/1/1 4/1/1\n\
f 1 3 4\nl 1 2\n"
        .to_vec();
    let ascii = ply_bytes(PlyFormat::Ascii);
    let be = ply_bytes(PlyFormat::Be);
    let gz = gzip(&ply_bytes(PlyFormat::Le));
    vec![gltf, glb, obj, ascii, be, gz]
}

fn check(dir: &Path, kind: &str, bytes: &[u8]) -> Result<(), TestCaseError> {
    let path = dir.join(format!("case.{kind}"));
    std::fs::write(&path, bytes).map_err(|e| TestCaseError::fail(e.to_string()))?;
    if let Err(e) = load(&[path.display().to_string()], &LoadOptions::default()) {
        let msg = e.to_string();
        prop_assert!(!msg.contains("reader failure"), "{kind}: {msg}");
        prop_assert!(
            msg.contains("case."),
            "{kind}: error does not name the file: {msg}"
        );
    }
    Ok(())
}

proptest! {
    #[test]
    fn random_bytes_never_panic(kind in 0usize..6, bytes in proptest::collection::vec(any::<u8>(), 0..512)) {
        let dir = tempfile::tempdir().expect("tempdir");
        check(dir.path(), KINDS[kind], &bytes)?;
    }

    #[test]
    fn truncations_and_byte_changes_never_panic(
        kind in 0usize..6,
        cut in 0.0f64..1.0,
        edits in proptest::collection::vec((0.0f64..1.0, any::<u8>()), 0..6),
    ) {
        let files = valid_files();
        let mut bytes = files[kind].clone();
        for (at, b) in edits {
            let n = bytes.len();
            if n > 0 {
                bytes[((at * n as f64) as usize).min(n - 1)] = b;
            }
        }
        let keep = (cut * bytes.len() as f64) as usize;
        bytes.truncate(keep.max(1));
        let dir = tempfile::tempdir().expect("tempdir");
        check(dir.path(), KINDS[kind], &bytes)?;
        // The untruncated file with the edits applied, too.
        let mut whole = files[kind].clone();
        let n = whole.len();
        whole[((cut * n as f64) as usize).min(n - 1)] ^= 0x5a;
        check(dir.path(), KINDS[kind], &whole)?;
    }
}

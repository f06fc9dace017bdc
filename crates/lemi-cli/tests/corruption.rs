//! Every single-byte corruption and every truncation of every file of a small bundle is detected
//! (`docs/RELIABILITY.md`): at every byte position of the manifest and of each cell file, each
//! of the 255 other byte values, and the file cut off there, is an error of the reader naming the
//! file: never a panic, never the damaged bytes accepted. Cell files are checked as every reader
//! of a bundle checks them (against the manifest's size and hash) and as a resumed bake checks
//! them, without a manifest (the container's own checksum and header).

mod common;

use std::collections::BTreeMap;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::Path;

use common::{lemi, stderr, tmp};
use lemi_core::bundle::{
    check_cell_bytes, manifest_path, Bundle, BundleError, CellCheck, Manifest,
};

/// How the damaged versions of one file fared.
#[derive(Debug, Default)]
struct Tally {
    damaged: u64,
    detected: u64,
    /// Error messages by their first words (what the reader said), with counts.
    errors: BTreeMap<String, u64>,
}

impl Tally {
    /// Tries `read` on every single-byte change and every truncation of `good`; each must be an
    /// error naming `path`.
    fn run(path: &Path, good: &[u8], read: impl Fn(&[u8]) -> Result<(), BundleError>) -> Tally {
        let mut t = Tally::default();
        let mut damaged = good.to_vec();
        let mut one = |bytes: &[u8], what: &dyn Fn() -> String| {
            t.damaged += 1;
            match catch_unwind(AssertUnwindSafe(|| read(bytes))) {
                Err(_) => panic!("{}: {}: the reader panicked", path.display(), what()),
                Ok(Ok(())) => panic!("{}: {}: accepted", path.display(), what()),
                Ok(Err(e)) => {
                    assert_eq!(e.path, path, "{}: {e}", what());
                    assert!(e.to_string().contains(&*path.to_string_lossy()), "{e}");
                    t.detected += 1;
                    let kind = e.kind.to_string();
                    let key: String = kind
                        .split([':', '(', ';'])
                        .next()
                        .unwrap_or("")
                        .split_whitespace()
                        .take(6)
                        .map(|w| {
                            if w.bytes().any(|b| b.is_ascii_digit()) {
                                "N"
                            } else {
                                w
                            }
                        })
                        .collect::<Vec<_>>()
                        .join(" ");
                    *t.errors.entry(key).or_default() += 1;
                }
            }
        };
        for at in 0..good.len() {
            for value in 0..=255u8 {
                if value != good[at] {
                    damaged[at] = value;
                    one(&damaged, &|| format!("byte {at} set to {value:#04x}"));
                }
            }
            damaged[at] = good[at];
            one(&good[..at], &|| format!("cut to {at} bytes"));
        }
        t
    }

    fn report(&self, what: &str, bytes: usize) {
        eprintln!(
            "{what}: {bytes} bytes, {} damaged versions, {} detected ({:.4} %)",
            self.damaged,
            self.detected,
            100.0 * self.detected as f64 / self.damaged as f64
        );
        for (e, n) in &self.errors {
            eprintln!("    {n:>8}  {e}");
        }
    }
}

#[test]
fn every_byte_change_and_truncation_of_a_small_bundle_is_detected() {
    let d = tmp("corruption", "bundle");
    let bundle = d.join("bundle");
    let walls = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../fuzz/corpus/ply/walls.ply"
    );
    // two cells of the six-triangle PLY of the fuzz corpus, small layers
    let o = lemi(&[
        "bake",
        walls,
        "-o",
        bundle.to_str().unwrap(),
        "--resolution",
        "16",
        "--layers",
        "3",
        "--alpha-deg",
        "5",
        "--region",
        "-5,0,-5,15,5,5",
        "--cell-size",
        "10",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let b = Bundle::open(&bundle).unwrap();
    assert_eq!(b.manifest().cells.len(), 2);

    let mp = manifest_path(&bundle);
    let good = std::fs::read(&mp).unwrap();
    let t = Tally::run(&mp, &good, |bytes| {
        Manifest::decode(&mp, bytes)
            .and_then(|m| Bundle::from_manifest(&bundle, m))
            .map(|_| ())
    });
    t.report("manifest.json", good.len());
    let mut total = (t.damaged, t.detected);

    let m = b.manifest();
    for entry in &m.cells {
        let path = bundle.join(&entry.file);
        let good = std::fs::read(&path).unwrap();
        let cell = m.grid.cell_of(entry.id).unwrap();
        let with_manifest = CellCheck {
            id: entry.id,
            entry: Some(entry),
            params_hash: &m.params_hash,
            scene_fingerprint: &m.scene.fingerprint,
            cell: None,
        };
        // what a resumed bake checks, with no manifest yet
        let without = CellCheck {
            entry: None,
            cell: Some(&cell),
            ..with_manifest
        };
        assert!(check_cell_bytes(&path, &good, &with_manifest).is_ok());
        assert!(check_cell_bytes(&path, &good, &without).is_ok());
        for (how, check) in [("with the manifest", with_manifest), ("without", without)] {
            let t = Tally::run(&path, &good, |bytes| {
                check_cell_bytes(&path, bytes, &check).map(|_| ())
            });
            t.report(&format!("{} ({how})", entry.file), good.len());
            total.0 += t.damaged;
            total.1 += t.detected;
        }
    }
    eprintln!("all: {} damaged versions, {} detected", total.0, total.1);
    assert_eq!(total.0, total.1);
    let _ = std::fs::remove_dir_all(&d);
}

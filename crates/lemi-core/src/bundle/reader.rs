//! The one reader of a bundle: every check a cell file must pass before anything uses it, in one
//! place, for the bake (resuming, merging), the runtime, the certificate and every strategy.
//!
//! A cell file is used only when all of these hold, checked in this order (the first that fails
//! is the error, naming the file):
//! 1. the cell is listed in the manifest ([`BundleErrorKind::NotBaked`]);
//! 2. the file can be read ([`BundleErrorKind::Io`]);
//! 3. its size and BLAKE3 hash are the manifest's ([`BundleErrorKind::Size`],
//!    [`BundleErrorKind::Hash`]): the file was not changed after baking;
//! 4. the container decodes: magic, version, its own checksum, a well-formed header and blobs
//!    ([`BundleErrorKind::Container`]);
//! 5. it was baked with the manifest's parameters and from its scene ([`BundleErrorKind::Params`],
//!    [`BundleErrorKind::Scene`]);
//! 6. it holds the cell asked for ([`BundleErrorKind::WrongCell`]).
//!
//! A resumed bake has no manifest yet; it checks a file on disk against the job with
//! [`read_cell_file`] and a [`CellCheck`] without the manifest's size and hash, but with the exact
//! cell (a region moved by a fraction of a cell keeps the ids, not the reference viewpoints).

use std::path::{Path, PathBuf};

use glam::DVec3;

use super::{cell_file_name, BundleError, BundleErrorKind, CellEntry, CellFile, Manifest};
use crate::cell::{CellId, ViewCell};

/// What a cell file must match to be used.
#[derive(Clone, Copy, Debug)]
pub struct CellCheck<'a> {
    pub id: CellId,
    /// The manifest's entry (size and hash), when there is a manifest.
    pub entry: Option<&'a CellEntry>,
    pub params_hash: &'a str,
    pub scene_fingerprint: &'a str,
    /// The exact cell (index, centre and extent) when the caller knows it; otherwise only the
    /// index is compared with `id`.
    pub cell: Option<&'a ViewCell>,
}

/// A cell file that passed its checks, with the manifest entry its bytes make.
#[derive(Clone, Debug, PartialEq)]
pub struct VerifiedCell {
    pub file: CellFile,
    pub entry: CellEntry,
}

/// Reads the cell file at `path` and runs every check of `check` on it (steps 2–6 of the module
/// docs).
pub fn read_cell_file(path: &Path, check: &CellCheck) -> Result<VerifiedCell, BundleError> {
    let bytes = std::fs::read(path).map_err(|e| BundleError::new(path, BundleErrorKind::Io(e)))?;
    check_cell_bytes(path, &bytes, check)
}

/// Runs every check of `check` on `bytes`, the contents of the cell file at `path` (steps 3–6 of
/// the module docs; errors name `path`).
pub fn check_cell_bytes(
    path: &Path,
    bytes: &[u8],
    check: &CellCheck,
) -> Result<VerifiedCell, BundleError> {
    let fail = |kind| BundleError::new(path, kind);
    let hash = blake3::hash(bytes).to_hex().to_string();
    if let Some(entry) = check.entry {
        if bytes.len() as u64 != entry.bytes {
            return Err(fail(BundleErrorKind::Size {
                actual: bytes.len() as u64,
                expected: entry.bytes,
            }));
        }
        if hash != entry.blake3 {
            return Err(fail(BundleErrorKind::Hash));
        }
    }
    let file = CellFile::decode(bytes).map_err(|e| fail(BundleErrorKind::Container(e)))?;
    if file.header.params_hash != check.params_hash {
        return Err(fail(BundleErrorKind::Params {
            found: file.header.params_hash.clone(),
            expected: check.params_hash.to_string(),
        }));
    }
    if file.header.scene_fingerprint != check.scene_fingerprint {
        return Err(fail(BundleErrorKind::Scene {
            found: file.header.scene_fingerprint.clone(),
            expected: check.scene_fingerprint.to_string(),
        }));
    }
    let found = file.header.cell.id();
    let moved = check.cell.is_some_and(|c| *c != file.header.cell);
    if found != check.id || moved {
        return Err(fail(BundleErrorKind::WrongCell {
            found,
            expected: check.id,
            moved: found == check.id,
        }));
    }
    let entry = CellEntry {
        id: check.id,
        file: cell_file_name(check.id),
        bytes: bytes.len() as u64,
        blake3: hash,
    };
    Ok(VerifiedCell { file, entry })
}

/// An opened bundle: its directory and manifest, and the one way to read its cells.
#[derive(Clone, Debug)]
pub struct Bundle {
    dir: PathBuf,
    manifest: Manifest,
}

impl Bundle {
    /// Reads and checks the manifest of the bundle directory `dir` (format, version, parameters in
    /// range, and that its parameters hash is the hash of its parameters).
    pub fn open(dir: &Path) -> Result<Bundle, BundleError> {
        Bundle::from_manifest(dir, Manifest::read(dir)?)
    }

    /// A bundle over a manifest already read (or built) for `dir`, with the same checks as
    /// [`Bundle::open`].
    pub fn from_manifest(dir: &Path, manifest: Manifest) -> Result<Bundle, BundleError> {
        if let Err(e) = manifest.params.validate() {
            return Err(BundleError::invalid(
                super::manifest_path(dir),
                format!("params.{}: {e}", e.parameter()),
            ));
        }
        let hash = manifest.params.hash();
        if manifest.params_hash != hash {
            return Err(BundleError::invalid(
                super::manifest_path(dir),
                format!(
                    "params_hash {} is not the hash of its params ({hash}): the manifest was edited or damaged",
                    manifest.params_hash
                ),
            ));
        }
        Ok(Bundle {
            dir: dir.to_path_buf(),
            manifest,
        })
    }

    pub fn dir(&self) -> &Path {
        &self.dir
    }

    pub fn manifest(&self) -> &Manifest {
        &self.manifest
    }

    pub fn into_manifest(self) -> Manifest {
        self.manifest
    }

    /// The baked cells' ids, in manifest order.
    pub fn cell_ids(&self) -> Vec<CellId> {
        self.manifest.cells.iter().map(|c| c.id).collect()
    }

    /// The first baked cell (in manifest order), e.g. for a default viewpoint at its centre.
    pub fn first_cell(&self) -> Option<ViewCell> {
        let id = self.manifest.cells.first()?.id;
        self.manifest.grid.cell_of(id).ok()
    }

    /// The manifest's entry for a cell, if it was baked.
    pub fn entry(&self, id: CellId) -> Option<&CellEntry> {
        self.manifest.cells.iter().find(|c| c.id == id)
    }

    /// Where a cell's file is (whether or not it was baked).
    pub fn cell_path(&self, id: CellId) -> PathBuf {
        match self.entry(id) {
            Some(e) => self.dir.join(&e.file),
            None => self.dir.join(cell_file_name(id)),
        }
    }

    /// Reads a baked cell and runs every check of the module docs on it.
    pub fn cell(&self, id: CellId) -> Result<CellFile, BundleError> {
        self.verified_cell(id).map(|v| v.file)
    }

    /// [`Bundle::cell`] with the cell's manifest entry (its size on disk).
    pub fn verified_cell(&self, id: CellId) -> Result<VerifiedCell, BundleError> {
        let Some(entry) = self.entry(id) else {
            return Err(BundleError::new(
                &self.dir,
                BundleErrorKind::NotBaked {
                    id,
                    baked: self.cell_ids(),
                },
            ));
        };
        read_cell_file(
            &self.dir.join(&entry.file),
            &CellCheck {
                id,
                entry: Some(entry),
                params_hash: &self.manifest.params_hash,
                scene_fingerprint: &self.manifest.scene.fingerprint,
                cell: None,
            },
        )
    }

    /// The grid cell containing `point` (half-open on the upper side), whether baked or not.
    /// For an object bundle: its one cell if `point` lies in the object's view cell.
    pub fn locate(&self, point: DVec3) -> Result<ViewCell, BundleError> {
        let grid = &self.manifest.grid;
        if let Some(o) = &self.manifest.object {
            return self.manifest.locate(point).ok_or_else(|| {
                BundleError::new(
                    &self.dir,
                    BundleErrorKind::OutsideObjectCell {
                        point: point.to_array(),
                        cell: o.cell.describe(),
                    },
                )
            });
        }
        grid.locate(point).ok_or_else(|| {
            BundleError::new(
                &self.dir,
                BundleErrorKind::OutsideGrid {
                    point: point.to_array(),
                    origin: grid.origin.to_array(),
                    cell_size: grid.cell_size,
                    counts: grid.counts.to_array(),
                },
            )
        })
    }

    /// The baked cell containing `point`, read and verified.
    pub fn cell_at(&self, point: DVec3) -> Result<(ViewCell, CellFile), BundleError> {
        let cell = self.locate(point)?;
        Ok((cell, self.cell(cell.id())?))
    }

    /// Checks that a scene given to draw the bundle with (its fingerprint) is the one it was
    /// baked from.
    pub fn expect_scene(&self, fingerprint: &str) -> Result<(), BundleError> {
        let baked = &self.manifest.scene.fingerprint;
        if baked == fingerprint {
            return Ok(());
        }
        Err(BundleError::new(
            super::manifest_path(&self.dir),
            BundleErrorKind::OtherScene {
                baked: baked.clone(),
                given: fingerprint.to_string(),
            },
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::super::tests::sample_cell;
    use super::super::*;
    use crate::cell::CellGrid;
    use crate::Aabb;

    /// A one-cell bundle in a fresh directory: the sample cell at grid index (1, 0, 2).
    fn bundle() -> (PathBuf, Manifest, CellFile) {
        let dir = std::env::temp_dir().join(format!(
            "lemi-reader-{}-{}",
            std::process::id(),
            rand_suffix()
        ));
        std::fs::create_dir_all(dir.join("cells")).unwrap();
        let grid = CellGrid::tile(
            Aabb::new(DVec3::new(0.0, -3.3, 0.0), DVec3::new(30.0, 6.7, 30.0)),
            10.0,
        )
        .unwrap();
        let mut file = sample_cell();
        file.header.cell = grid.cell(glam::IVec3::new(1, 0, 2)).unwrap();
        let params = BakeParams {
            cell_size: 10.0,
            cell_height: None,
            resolution: 64,
            target: LayerTarget::Layers(1),
            faces: vec![Face::PosX],
            alpha: 0.001,
            output_fov_deg: None,
            output_width: None,
            micro_grid: 8,
            micro_threshold: 0.5,
            layering: Layering::Optimal,
            texture_format: Default::default(),
            outline_copies: false,
            outline_fringe: false,
        };
        file.header.params_hash = params.hash();
        let bytes = file.encode().unwrap();
        let id = file.header.cell.id();
        std::fs::write(dir.join(cell_file_name(id)), &bytes).unwrap();
        let manifest = Manifest {
            format: MANIFEST_FORMAT.into(),
            version: BUNDLE_VERSION,
            generator: "test".into(),
            scene: SceneRef {
                sources: vec!["builtin:test".into()],
                up: "y".into(),
                fingerprint: file.header.scene_fingerprint.clone(),
                triangles: 4,
            },
            params_hash: params.hash(),
            params,
            grid,
            cells: vec![CellEntry {
                id,
                file: cell_file_name(id),
                bytes: bytes.len() as u64,
                blake3: blake3::hash(&bytes).to_hex().to_string(),
            }],
            object: None,
        };
        manifest.write(&dir).unwrap();
        (dir, manifest, file)
    }

    fn rand_suffix() -> u64 {
        use std::sync::atomic::{AtomicU64, Ordering};
        static N: AtomicU64 = AtomicU64::new(0);
        N.fetch_add(1, Ordering::Relaxed)
    }

    fn id(s: &str) -> CellId {
        s.parse().unwrap()
    }

    /// Rewrites the cell file with `edit` applied and the manifest entry updated to match, so
    /// only the check under test can fail.
    fn rewrite(dir: &Path, manifest: &mut Manifest, file: &CellFile, edit: impl Fn(&mut CellFile)) {
        let mut f = file.clone();
        edit(&mut f);
        let bytes = f.encode().unwrap();
        std::fs::write(dir.join(&manifest.cells[0].file), &bytes).unwrap();
        manifest.cells[0].bytes = bytes.len() as u64;
        manifest.cells[0].blake3 = blake3::hash(&bytes).to_hex().to_string();
        manifest.write(dir).unwrap();
    }

    #[test]
    fn an_intact_cell_reads_back_and_is_located() {
        let (dir, manifest, file) = bundle();
        let b = Bundle::open(&dir).unwrap();
        assert_eq!(b.cell_ids(), vec![id("1_0_2")]);
        assert_eq!(b.cell(id("1_0_2")).unwrap(), file);
        let v = b.verified_cell(id("1_0_2")).unwrap();
        assert_eq!(v.entry, manifest.cells[0]);
        let (cell, f) = b.cell_at(DVec3::new(12.0, 0.0, 21.0)).unwrap();
        assert_eq!(cell, file.header.cell);
        assert_eq!(f, file);
        assert!(b.expect_scene(&manifest.scene.fingerprint).is_ok());
        std::fs::remove_dir_all(dir).ok();
    }

    #[test]
    fn every_check_fires() {
        let (dir, mut manifest, file) = bundle();
        let kind = |dir: &Path, cell: &str| {
            let b = Bundle::open(dir).unwrap();
            let e = b.cell(id(cell)).unwrap_err();
            let text = e.to_string();
            (e.kind, e.path, text)
        };
        let cell_path = dir.join(&manifest.cells[0].file);

        // 1. not baked
        let (k, p, text) = kind(&dir, "0_0_0");
        assert!(matches!(k, BundleErrorKind::NotBaked { .. }), "{text}");
        assert_eq!(p, dir);
        assert!(text.contains("0_0_0") && text.contains("1_0_2"), "{text}");
        // outside the grid
        let b = Bundle::open(&dir).unwrap();
        let e = b.locate(DVec3::new(-50.0, 0.0, 0.0)).unwrap_err();
        assert!(matches!(e.kind, BundleErrorKind::OutsideGrid { .. }), "{e}");
        assert!(e.to_string().contains("outside the baked region"), "{e}");

        // 3. size, then hash (same size)
        let good = std::fs::read(&cell_path).unwrap();
        std::fs::write(&cell_path, &good[..good.len() - 1]).unwrap();
        let (k, p, text) = kind(&dir, "1_0_2");
        assert!(matches!(k, BundleErrorKind::Size { .. }), "{text}");
        assert_eq!(p, cell_path);
        assert!(text.contains("1_0_2.lemicell") && text.contains("bake it again"));
        let mut flipped = good.clone();
        let n = flipped.len();
        flipped[n / 2] ^= 0x10;
        std::fs::write(&cell_path, &flipped).unwrap();
        let (k, _, text) = kind(&dir, "1_0_2");
        assert!(matches!(k, BundleErrorKind::Hash), "{text}");
        assert!(text.contains("BLAKE3"), "{text}");

        // 4. the container's own checks (the manifest agrees with the damaged bytes)
        manifest.cells[0].blake3 = blake3::hash(&flipped).to_hex().to_string();
        manifest.write(&dir).unwrap();
        let (k, _, text) = kind(&dir, "1_0_2");
        assert!(matches!(k, BundleErrorKind::Container(_)), "{text}");

        // 5. parameters and scene
        rewrite(&dir, &mut manifest, &file, |f| {
            f.header.params_hash = "0".repeat(64)
        });
        let (k, _, text) = kind(&dir, "1_0_2");
        assert!(matches!(k, BundleErrorKind::Params { .. }), "{text}");
        assert!(text.contains("other parameters"), "{text}");
        rewrite(&dir, &mut manifest, &file, |f| {
            f.header.scene_fingerprint = "1".repeat(64)
        });
        let (k, _, text) = kind(&dir, "1_0_2");
        assert!(matches!(k, BundleErrorKind::Scene { .. }), "{text}");
        assert!(text.contains("another scene"), "{text}");

        // 6. another cell's file under this cell's name
        rewrite(&dir, &mut manifest, &file, |f| {
            f.header.cell.index = glam::IVec3::new(2, 0, 2)
        });
        let (k, _, text) = kind(&dir, "1_0_2");
        assert!(matches!(k, BundleErrorKind::WrongCell { .. }), "{text}");
        assert!(text.contains("holds cell 2_0_2, not 1_0_2"), "{text}");

        // 2. unreadable
        std::fs::remove_file(&cell_path).unwrap();
        let (k, _, text) = kind(&dir, "1_0_2");
        assert!(matches!(k, BundleErrorKind::Io(_)), "{text}");

        // the scene a caller draws with
        rewrite(&dir, &mut manifest, &file, |_| {});
        let b = Bundle::open(&dir).unwrap();
        let e = b.expect_scene("2222222222222222").unwrap_err();
        assert!(matches!(e.kind, BundleErrorKind::OtherScene { .. }), "{e}");
        assert!(e.to_string().contains("manifest.json"), "{e}");
        std::fs::remove_dir_all(dir).ok();
    }

    #[test]
    fn the_manifest_is_checked_when_opened() {
        let (dir, mut manifest, _) = bundle();
        manifest.params_hash = "f".repeat(64);
        manifest.write(&dir).unwrap();
        let e = Bundle::open(&dir).unwrap_err();
        assert!(e.to_string().contains("params_hash"), "{e}");
        manifest.version = 1;
        manifest.write(&dir).unwrap();
        let e = Bundle::open(&dir).unwrap_err();
        assert!(e.to_string().contains("version 1"), "{e}");
        // a block-compressed bundle is version 8, or 4, 5 or 7 when baked before version 8; a
        // PNG bundle is none of them
        for v in [4, 5, 7, 8] {
            manifest.version = v;
            let path = manifest_path(&dir);
            let decode = |m: &Manifest| Manifest::decode(&path, &m.encode().unwrap());
            let e = decode(&manifest).unwrap_err();
            assert!(e.to_string().contains(&format!("version {v}")), "{e}");
            let mut block = manifest.clone();
            block.params.texture_format = crate::compress::TextureFormat::Bc1;
            block.params_hash = block.params.hash();
            assert_eq!(decode(&block).unwrap().version, v);
        }
        std::fs::write(manifest_path(&dir), b"{").unwrap();
        assert!(Bundle::open(&dir).is_err());
        let e = Bundle::open(&dir.join("missing")).unwrap_err();
        assert!(matches!(e.kind, BundleErrorKind::Io(_)), "{e}");
        std::fs::remove_dir_all(dir).ok();
    }

    #[test]
    fn the_manifest_ends_with_the_checksum_of_its_bytes() {
        let (dir, manifest, _) = bundle();
        let bytes = std::fs::read(manifest_path(&dir)).unwrap();
        assert_eq!(bytes, manifest.encode().unwrap());
        let text = String::from_utf8(bytes.clone()).unwrap();
        let at = text.rfind("\"checksum\": \"blake3:").unwrap();
        let hex = &text[at + 20..at + 84];
        assert_eq!(&text[at + 84..], "\"\n}");
        assert_eq!(blake3::hash(&bytes[..at]).to_hex().as_str(), hex);
        assert!(text[..at].ends_with(",\n  "));
        // still JSON, the checksum one more member
        let v: serde_json::Value = serde_json::from_slice(&bytes).unwrap();
        assert_eq!(v["checksum"], format!("blake3:{hex}"));
        assert_eq!(Manifest::read(&dir).unwrap(), manifest);
        std::fs::remove_dir_all(dir).ok();
    }

    #[test]
    fn a_manifest_written_before_the_checksum_still_reads() {
        let (dir, manifest, _) = bundle();
        // what `Manifest::write` wrote before the checksum was added
        std::fs::write(
            manifest_path(&dir),
            serde_json::to_vec_pretty(&manifest).unwrap(),
        )
        .unwrap();
        let b = Bundle::open(&dir).unwrap();
        assert_eq!(b.manifest(), &manifest);
        assert!(b.cell(id("1_0_2")).is_ok());
        // but not one that names a checksum lemi did not write
        let mut v = serde_json::to_value(&manifest).unwrap();
        v["checksum"] = "blake3:00".into();
        std::fs::write(manifest_path(&dir), serde_json::to_vec_pretty(&v).unwrap()).unwrap();
        let e = Bundle::open(&dir).unwrap_err();
        assert!(e.to_string().contains("`checksum` is damaged"), "{e}");
        std::fs::remove_dir_all(dir).ok();
    }

    /// Every single-byte change (all 255 other values at every position) and every truncation of
    /// a manifest is an error naming it: the checksum covers every byte, whitespace included.
    #[test]
    fn every_byte_change_and_truncation_of_the_manifest_is_detected() {
        let (dir, _, _) = bundle();
        let path = manifest_path(&dir);
        let good = std::fs::read(&path).unwrap();
        let mut checked = 0;
        let mut damaged = Vec::with_capacity(good.len());
        let mut expect_error = |bytes: &[u8], what: &dyn Fn() -> String| {
            // `Bundle::open` of these bytes, without writing each to disk
            match Manifest::decode(&path, bytes).and_then(|m| Bundle::from_manifest(&dir, m)) {
                Ok(_) => panic!("{} accepted", what()),
                Err(e) => assert!(e.path == path, "{}: {e}", what()),
            }
            checked += 1;
        };
        for at in 0..good.len() {
            for value in 0..=255u8 {
                if value == good[at] {
                    continue;
                }
                damaged.clear();
                damaged.extend_from_slice(&good);
                damaged[at] = value;
                expect_error(&damaged, &|| format!("byte {at} set to {value:#04x}"));
            }
            expect_error(&good[..at], &|| format!("cut to {at} bytes"));
        }
        assert_eq!(checked, good.len() * 256);
        std::fs::remove_dir_all(dir).ok();
    }

    #[test]
    fn resuming_compares_the_whole_cell() {
        let (dir, manifest, file) = bundle();
        let path = dir.join(&manifest.cells[0].file);
        let mut moved = file.header.cell;
        moved.center.x += 0.5;
        let check = CellCheck {
            id: file.header.cell.id(),
            entry: None,
            params_hash: &manifest.params_hash,
            scene_fingerprint: &manifest.scene.fingerprint,
            cell: Some(&moved),
        };
        let e = read_cell_file(&path, &check).unwrap_err();
        assert!(
            matches!(e.kind, BundleErrorKind::WrongCell { moved: true, .. }),
            "{e}"
        );
        let same = CellCheck {
            cell: Some(&file.header.cell),
            ..check
        };
        let v = read_cell_file(&path, &same).unwrap();
        assert_eq!(v.entry, manifest.cells[0]);
        std::fs::remove_dir_all(dir).ok();
    }
}

//! Crash-safe bakes (`docs/RELIABILITY.md`): a bake killed with SIGKILL at random moments and then
//! run again (the same command, which resumes) ends with the bundle of an uninterrupted bake, byte
//! for byte; after every kill, each cell file present either is refused by the reader with an
//! error naming it or is the uninterrupted bake's file byte for byte. A full disk (a file size
//! limit on the bake's process), a read-only bundle directory and a bundle directory deleted
//! during the bake are each one clear error naming the file and the problem, exit non-zero, no
//! panic, and leave every cell already written intact, so that running the command again
//! finishes the bundle.
//!
//! The full measurement, 20 kills during a 12-cell bake, is the ignored test
//! `twenty_kills_during_a_twelve_cell_bake` (a few minutes):
//! `cargo test -p lemi-cli --test crash_safety -- --ignored --nocapture`.

mod common;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Output;
use std::sync::OnceLock;
use std::time::{Duration, Instant};

use common::{
    assert_clean_error_all, assert_same_bundle, bundle_files, lemi, lemi_command, spawn_lemi,
    stderr, tmp, SIX_CELLS,
};
use lemi_core::bundle::{check_cell_bytes, Bundle, CellCheck};
use lemi_core::cell::CellId;
use lemi_core::container::is_temp_file_name;

/// Twelve cells (4 × 3) of the city of [`SIX_CELLS`].
const TWELVE_CELLS: &[&str] = &[
    "builtin:city:20000",
    "--region",
    "0,1.7,-10,40,1.7,20",
    "--cell-size",
    "10",
    "--resolution",
    "32",
    "--layers",
    "4",
    "--alpha-deg",
    "0.5",
];

fn bake_args(flags: &[&str], bundle: &Path) -> Vec<String> {
    let mut a: Vec<String> = vec!["bake".into()];
    a.extend(flags.iter().map(|s| s.to_string()));
    a.extend(["-o".into(), bundle.display().to_string(), "--json".into()]);
    a
}

/// An uninterrupted bake: its files, what the reader checks cells against, and its wall time.
struct Clean {
    bundle: PathBuf,
    files: BTreeMap<String, Vec<u8>>,
    params_hash: String,
    fingerprint: String,
    /// The manifest's cells in bake order, with their sizes.
    cells: Vec<(CellId, u64)>,
    seconds: f64,
}

fn clean_bake(flags: &[&str], name: &str) -> Clean {
    let bundle = tmp("crash", name).join("bundle");
    let t = Instant::now();
    let o = run(&bake_args(flags, &bundle));
    let seconds = t.elapsed().as_secs_f64();
    assert!(o.status.success(), "{}", stderr(&o));
    let m = Bundle::open(&bundle).unwrap().into_manifest();
    Clean {
        files: bundle_files(&bundle),
        params_hash: m.params_hash.clone(),
        fingerprint: m.scene.fingerprint.clone(),
        cells: m.cells.iter().map(|c| (c.id, c.bytes)).collect(),
        bundle,
        seconds,
    }
}

static SIX: OnceLock<Clean> = OnceLock::new();

/// The six-cell clean bake, shared by the tests of this file (removed when the process exits).
fn six() -> &'static Clean {
    SIX.get_or_init(|| {
        extern "C" fn remove() {
            if let Some(parent) = SIX.get().and_then(|c| c.bundle.parent()) {
                let _ = std::fs::remove_dir_all(parent);
            }
        }
        // SAFETY: registers a function without arguments to run at `exit`.
        unsafe { libc::atexit(remove) };
        clean_bake(SIX_CELLS, "clean6")
    })
}

fn run(args: &[String]) -> Output {
    lemi(&args.iter().map(String::as_str).collect::<Vec<_>>())
}

/// `lemi bake --json`'s count of cells baked and skipped.
fn baked_skipped(o: &Output) -> (u64, u64) {
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    (v["baked"].as_u64().unwrap(), v["skipped"].as_u64().unwrap())
}

/// What an interrupted or failed bake left in the bundle directory.
#[derive(Debug, Default)]
struct Left {
    /// Cell files the reader accepts (each must be the clean bake's bytes).
    cells: usize,
    /// Cell files the reader refuses.
    refused: usize,
    /// Temporary files of writes that never finished.
    temp: usize,
    manifest: bool,
    /// What must never be: a file the reader accepts that is not the clean bake's, an error
    /// that does not name its file, a file that is no part of a bundle.
    wrong: Vec<String>,
}

/// Looks at every file an interrupted or failed bake left in `bundle` (see [`Left`]).
fn inspect(bundle: &Path, clean: &Clean) -> Left {
    let mut left = Left::default();
    if !bundle.exists() {
        return left;
    }
    for (name, bytes) in bundle_files(bundle) {
        let path = bundle.join(&name);
        let file_name = path.file_name().unwrap().to_string_lossy().into_owned();
        if is_temp_file_name(&file_name) {
            left.temp += 1;
            continue;
        }
        let accepted = if name == "manifest.json" {
            left.manifest = true;
            Bundle::open(bundle).map(|_| ())
        } else if let Some(id) = name
            .strip_prefix("cells/")
            .and_then(|n| n.strip_suffix(".lemicell"))
            .and_then(|n| n.parse::<CellId>().ok())
        {
            let check = CellCheck {
                id,
                entry: None,
                params_hash: &clean.params_hash,
                scene_fingerprint: &clean.fingerprint,
                cell: None,
            };
            check_cell_bytes(&path, &bytes, &check).map(|_| ())
        } else {
            left.wrong
                .push(format!("{}: not a file of a bundle", path.display()));
            continue;
        };
        match accepted {
            Ok(()) if clean.files.get(&name) == Some(&bytes) => {
                left.cells += usize::from(name != "manifest.json");
            }
            Ok(()) => left.wrong.push(format!(
                "{}: accepted by the reader but not the clean bake's bytes",
                path.display()
            )),
            Err(e) if e.path == path => {
                eprintln!("refused, as it must be: {e}");
                left.refused += 1;
            }
            Err(e) => left.wrong.push(format!(
                "{}: an error naming another file: {e}",
                path.display()
            )),
        }
    }
    left
}

/// [`inspect`], which must find nothing wrong.
fn inspect_sound(bundle: &Path, clean: &Clean) -> Left {
    let left = inspect(bundle, clean);
    assert!(left.wrong.is_empty(), "{:#?}", left.wrong);
    left
}

/// xorshift64*: the kill moments, reproducible from the printed seed (`LEMI_KILL_SEED`).
struct Rng(u64);

impl Rng {
    fn from_env() -> Rng {
        let seed = std::env::var("LEMI_KILL_SEED")
            .ok()
            .and_then(|s| s.parse().ok())
            .unwrap_or_else(|| {
                std::time::SystemTime::now()
                    .duration_since(std::time::UNIX_EPOCH)
                    .unwrap()
                    .as_nanos() as u64
            });
        eprintln!("kill moments from LEMI_KILL_SEED={seed}");
        Rng(seed | 1)
    }
    /// Uniform in [0, 1).
    fn next(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        (self.0.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// Starts the bake and sends it SIGKILL after `after` (unless it finished first). Returns whether
/// it was killed.
fn kill_after(args: &[String], after: Duration) -> bool {
    let mut child = spawn_lemi(args);
    let t = Instant::now();
    while t.elapsed() < after {
        if child.try_wait().unwrap().is_some() {
            return false;
        }
        std::thread::sleep(Duration::from_millis(2).min(after - t.elapsed().min(after)));
    }
    // `Child::kill` is SIGKILL on Unix.
    let killed = child.kill().is_ok();
    let o = child.wait_with_output().unwrap();
    killed && !o.status.success()
}

/// One bundle: a bake killed after each of `kills` in turn (the first in a fresh directory, each
/// next one resuming what the last left), each time checked with [`inspect`]; then the same
/// command run to the end, which must give the clean bundle byte for byte. A first bake that
/// finishes before its kill (the machine was faster than when the clean bake was timed) is
/// started again in a fresh directory with 0.6 times the delay. Returns a line for the record
/// and how many kills landed.
fn killed_and_resumed(
    flags: &[&str],
    clean: &Clean,
    bundle: &Path,
    kills: &[Duration],
) -> (String, usize) {
    let args = bake_args(flags, bundle);
    let mut line = String::new();
    let mut landed = 0;
    for (i, after) in kills.iter().enumerate() {
        let mut after = *after;
        let killed = loop {
            let killed = kill_after(&args, after);
            if killed || i > 0 || after < Duration::from_millis(20) {
                break killed;
            }
            line += &format!("finished before {} ms; ", after.as_millis());
            std::fs::remove_dir_all(bundle).unwrap();
            after = after.mul_f64(0.6);
        };
        landed += usize::from(killed);
        let left = inspect_sound(bundle, clean);
        line += &format!(
            "killed after {:>4} ms{}: {} cells complete, {} refused, {} temporary files{}; ",
            after.as_millis(),
            if killed { "" } else { " (had finished)" },
            left.cells,
            left.refused,
            left.temp,
            if left.manifest { ", manifest" } else { "" }
        );
    }
    let temp_before = inspect_sound(bundle, clean).temp;
    let o = run(&args);
    assert!(o.status.success(), "resuming: {}", stderr(&o));
    let (baked, skipped) = baked_skipped(&o);
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["stale_temp_files_removed"], temp_before);
    assert_same_bundle(&clean.bundle, bundle);
    line += &format!("resumed: {skipped} skipped, {baked} baked; identical");
    (line, landed)
}

#[test]
fn bakes_killed_at_random_moments_resume_to_the_clean_bundle() {
    let clean = six();
    let d = tmp("crash", "kills");
    let mut rng = Rng::from_env();
    // Five bundles, each killed once at a moment in its fifth of the clean bake's wall time
    // (stratified), two of them killed again while resuming: 7 kills.
    let t = clean.seconds;
    let n = 5;
    let mut lines = Vec::new();
    let mut landed = 0;
    for trial in 0..n {
        let mut kills = vec![Duration::from_secs_f64(
            t * (trial as f64 + rng.next()) / n as f64,
        )];
        if trial % 2 == 1 {
            kills.push(Duration::from_secs_f64(t * rng.next()));
        }
        let bundle = d.join(format!("bundle-{trial}"));
        let (line, k) = killed_and_resumed(SIX_CELLS, clean, &bundle, &kills);
        lines.push(line);
        landed += k;
    }
    eprintln!(
        "clean bake of 6 cells: {:.1} s; {landed} kills landed; {n} of {n} bundles identical",
        clean.seconds
    );
    for l in &lines {
        eprintln!("{l}");
    }
    assert!(landed >= n, "only {landed} kills landed");
    let _ = std::fs::remove_dir_all(&d);
}

/// The aim: 20 SIGKILLs at random moments during a 12-cell bake, each bundle resumed to
/// the end: 20 of 20 identical to the clean one. A few minutes; run explicitly.
#[test]
#[ignore]
fn twenty_kills_during_a_twelve_cell_bake() {
    let clean = clean_bake(TWELVE_CELLS, "clean12");
    assert_eq!(clean.cells.len(), 12);
    let d = tmp("crash", "twenty");
    let mut rng = Rng::from_env();
    let n = 20;
    let (mut identical, mut landed) = (0, 0);
    for trial in 0..n {
        // stratified: kill `trial` lands in the trial-th twentieth of the clean bake's time
        let after = Duration::from_secs_f64(clean.seconds * (trial as f64 + rng.next()) / n as f64);
        let bundle = d.join(format!("bundle-{trial}"));
        let (line, k) = killed_and_resumed(TWELVE_CELLS, &clean, &bundle, &[after]);
        identical += 1;
        landed += k;
        eprintln!("{:>2}: {line}", trial + 1);
        let _ = std::fs::remove_dir_all(&bundle);
    }
    eprintln!(
        "clean bake of 12 cells: {:.1} s; {landed} SIGKILLs landed; {identical} of {n} bundles \
         resumed to the clean bundle byte for byte",
        clean.seconds
    );
    assert_eq!(landed, n);
    let _ = std::fs::remove_dir_all(&d);
    let _ = std::fs::remove_dir_all(clean.bundle.parent().unwrap());
}

/// A copy of the clean bundle's first `n` cells (in bake order) in a fresh bundle directory: what
/// a bake stopped after `n` cells leaves.
fn partial_bundle(clean: &Clean, bundle: &Path, n: usize) {
    std::fs::create_dir_all(bundle.join("cells")).unwrap();
    for (id, _) in clean.cells.iter().take(n) {
        let name = format!("cells/{id}.lemicell");
        std::fs::write(bundle.join(&name), &clean.files[&name]).unwrap();
    }
}

#[test]
fn a_full_disk_is_a_clear_error_and_loses_no_cell() {
    use std::os::unix::process::CommandExt;
    let clean = six();
    // A file size limit that the first cell fits and a later, larger one does not: writing it
    // fails with EFBIG, as on a full disk.
    let first = clean.cells[0].1;
    let (limit, fits) = match clean.cells.iter().position(|c| c.1 > first) {
        Some(i) => (first, i),
        None => (first - 1, 0),
    };
    let d = tmp("crash", "full");
    let bundle = d.join("bundle");
    let mut cmd = lemi_command(&bake_args(SIX_CELLS, &bundle));
    // SAFETY: only async-signal-safe calls (signal, setrlimit) between fork and exec.
    unsafe {
        cmd.pre_exec(move || {
            // SIGXFSZ would kill the process; ignored, the write fails with EFBIG instead.
            libc::signal(libc::SIGXFSZ, libc::SIG_IGN);
            let lim = libc::rlimit {
                rlim_cur: limit as libc::rlim_t,
                rlim_max: limit as libc::rlim_t,
            };
            if libc::setrlimit(libc::RLIMIT_FSIZE, &lim) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            Ok(())
        });
    }
    let o = cmd.output().unwrap();
    let failing = format!("{}.lemicell", clean.cells[fits].0);
    assert_clean_error_all(
        &o,
        &[
            &failing,
            "File too large",
            "disk is full",
            "run the same command again",
        ],
    );
    let left = inspect_sound(&bundle, clean);
    eprintln!(
        "file size limit {limit} bytes: {left:?}; {}",
        stderr(&o).trim()
    );
    assert_eq!(
        (left.cells, left.refused, left.temp),
        (fits, 0, 0),
        "{left:?}"
    );
    assert!(!left.manifest);
    // the same command without the limit finishes the bundle, keeping the cells written
    let o = run(&bake_args(SIX_CELLS, &bundle));
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(baked_skipped(&o).1, fits as u64);
    assert_same_bundle(&clean.bundle, &bundle);
    let _ = std::fs::remove_dir_all(&d);
}

/// A small tmpfs mounted on a directory, unmounted when dropped (pass or fail).
struct Tmpfs(PathBuf);

impl Tmpfs {
    fn mount(dir: &Path, bytes: u64) -> Result<Tmpfs, String> {
        std::fs::create_dir_all(dir).map_err(|e| e.to_string())?;
        let o = std::process::Command::new("mount")
            .args(["-t", "tmpfs", "-o", &format!("size={bytes}"), "tmpfs"])
            .arg(dir)
            .output()
            .map_err(|e| format!("mount: {e}"))?;
        if !o.status.success() {
            return Err(format!(
                "mount -t tmpfs: {}",
                String::from_utf8_lossy(&o.stderr).trim()
            ));
        }
        Ok(Tmpfs(dir.to_path_buf()))
    }

    fn resize(&self, bytes: u64) {
        let o = std::process::Command::new("mount")
            .args(["-o", &format!("remount,size={bytes}")])
            .arg(&self.0)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    }
}

impl Drop for Tmpfs {
    fn drop(&mut self) {
        let _ = std::process::Command::new("umount")
            .arg("-l")
            .arg(&self.0)
            .status();
    }
}

/// A full disk for real: the bundle on a tmpfs with room for the first cell file and less than
/// a page more, so writing the second fails with ENOSPC. Needs the right to mount (root in CI).
#[test]
fn a_full_tmpfs_is_a_clear_error_and_loses_no_cell() {
    let clean = six();
    let d = tmp("crash", "tmpfs");
    let page = 4096;
    let room = clean.cells[0].1.div_ceil(page) * page + page;
    let fs = match Tmpfs::mount(&d.join("fs"), room) {
        Ok(fs) => fs,
        Err(why) => {
            println!("SKIPPED a_full_tmpfs_is_a_clear_error_and_loses_no_cell: {why}");
            return;
        }
    };
    assert!(clean.cells[1].1 > page, "the second cell fits in a page");
    let bundle = fs.0.join("bundle");
    let o = run(&bake_args(SIX_CELLS, &bundle));
    let failing = format!("{}.lemicell", clean.cells[1].0);
    assert_clean_error_all(
        &o,
        &[
            &failing,
            "No space left on device",
            "disk is full",
            "run the same command again",
        ],
    );
    let left = inspect_sound(&bundle, clean);
    eprintln!("tmpfs of {room} bytes: {left:?}; {}", stderr(&o).trim());
    assert_eq!((left.cells, left.refused, left.temp), (1, 0, 0), "{left:?}");
    // room again: the same command keeps the cell written and finishes the bundle
    fs.resize(64 << 20);
    let o = run(&bake_args(SIX_CELLS, &bundle));
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(baked_skipped(&o), (5, 1));
    assert_same_bundle(&clean.bundle, &bundle);
    drop(fs);
    let _ = std::fs::remove_dir_all(&d);
}

/// How [`ReadOnly`] keeps the bake from writing.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Denial {
    /// The immutable attribute (`chattr +i`): refused to root too, which ignores permission bits.
    Immutable,
    /// Mode 0555, the bake run by the user running the tests (not root).
    Bits,
    /// Mode 0555, the bake run as the unprivileged user 65534 (root, where the file system has
    /// no immutable attribute).
    OtherUser,
}

/// Makes directories read-only for the bake and undoes it when dropped (pass or fail).
struct ReadOnly(Vec<PathBuf>, Denial);

impl ReadOnly {
    fn new(dirs: &[&Path]) -> Result<ReadOnly, String> {
        // SAFETY: geteuid has no preconditions.
        let root = unsafe { libc::geteuid() } == 0;
        let chattr = |d: &Path| -> Result<(), String> {
            let o = std::process::Command::new("chattr")
                .arg("+i")
                .arg(d)
                .output()
                .map_err(|e| format!("chattr: {e}"))?;
            if !o.status.success() {
                return Err(format!(
                    "chattr +i {}: {}",
                    d.display(),
                    String::from_utf8_lossy(&o.stderr).trim()
                ));
            }
            Ok(())
        };
        let denial = match dirs.first() {
            Some(d) if root => match chattr(d) {
                Ok(()) => Denial::Immutable,
                Err(why) => {
                    eprintln!("{why}: the bake runs as user 65534 on mode 0555 instead");
                    Denial::OtherUser
                }
            },
            _ if root => Denial::Immutable,
            _ => Denial::Bits,
        };
        let mut ro = ReadOnly(Vec::new(), denial);
        for (i, d) in dirs.iter().enumerate() {
            if denial == Denial::Immutable {
                if i > 0 {
                    chattr(d)?;
                }
            } else {
                use std::os::unix::fs::PermissionsExt;
                std::fs::set_permissions(d, std::fs::Permissions::from_mode(0o555))
                    .map_err(|e| format!("chmod 0555 {}: {e}", d.display()))?;
            }
            ro.0.push(d.to_path_buf());
        }
        Ok(ro)
    }

    /// Runs `lemi ARGS` as [`Denial`] says.
    fn run(&self, args: &[String]) -> Output {
        use std::os::unix::process::CommandExt;
        let mut c = lemi_command(args);
        if self.1 == Denial::OtherUser {
            c.uid(65534).gid(65534);
        }
        c.output().expect("the lemi binary runs")
    }
}

impl Drop for ReadOnly {
    fn drop(&mut self) {
        for d in &self.0 {
            if self.1 == Denial::Immutable {
                let _ = std::process::Command::new("chattr")
                    .arg("-i")
                    .arg(d)
                    .status();
            } else {
                use std::os::unix::fs::PermissionsExt;
                let _ = std::fs::set_permissions(d, std::fs::Permissions::from_mode(0o755));
            }
        }
    }
}

#[test]
fn a_read_only_bundle_directory_is_a_clear_error_and_loses_no_cell() {
    let clean = six();
    let d = tmp("crash", "readonly");
    // 1. cells/ read-only, two cells of six already baked: the third cannot be written
    let bundle = d.join("bundle");
    partial_bundle(clean, &bundle, 2);
    let ro = match ReadOnly::new(&[&bundle, &bundle.join("cells")]) {
        Ok(ro) => {
            eprintln!("read-only by {:?}", ro.1);
            ro
        }
        Err(why) => {
            println!(
                "SKIPPED a_read_only_bundle_directory_is_a_clear_error_and_loses_no_cell: {why}"
            );
            return;
        }
    };
    let o = ro.run(&bake_args(SIX_CELLS, &bundle));
    let failing = format!("{}.lemicell", clean.cells[2].0);
    assert_clean_error_all(
        &o,
        &[
            &failing,
            "cannot write",
            "read-only",
            "run the same command again",
        ],
    );
    eprintln!("{}", stderr(&o).trim());
    drop(ro);
    let left = inspect_sound(&bundle, clean);
    assert_eq!((left.cells, left.refused, left.temp), (2, 0, 0), "{left:?}");
    let o = run(&bake_args(SIX_CELLS, &bundle));
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(baked_skipped(&o), (4, 2));
    assert_same_bundle(&clean.bundle, &bundle);

    // 2. every cell baked, only the bundle directory read-only: the manifest cannot be written
    std::fs::remove_file(bundle.join("manifest.json")).unwrap();
    let ro = ReadOnly::new(&[&bundle]).unwrap();
    let o = ro.run(&bake_args(SIX_CELLS, &bundle));
    assert_clean_error_all(&o, &["manifest.json", "cannot write", "read-only"]);
    eprintln!("{}", stderr(&o).trim());
    drop(ro);
    let left = inspect_sound(&bundle, clean);
    assert_eq!((left.cells, left.refused, left.temp), (6, 0, 0), "{left:?}");
    let o = run(&bake_args(SIX_CELLS, &bundle));
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(baked_skipped(&o), (0, 6));
    assert_same_bundle(&clean.bundle, &bundle);
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn a_bundle_directory_deleted_during_the_bake_is_a_clear_error() {
    let clean = six();
    let d = tmp("crash", "deleted");
    let bundle = d.join("bundle");
    let args = bake_args(SIX_CELLS, &bundle);
    // Deleted as soon as the first cell file is there; tried again if the bake finished first.
    let o = (0..3)
        .find_map(|_| {
            let _ = std::fs::remove_dir_all(&bundle);
            let child = spawn_lemi(&args);
            let t = Instant::now();
            while std::fs::read_dir(bundle.join("cells")).map_or(true, |rd| {
                !rd.filter_map(|e| e.ok())
                    .any(|e| e.file_name().to_string_lossy().ends_with(".lemicell"))
            }) {
                assert!(t.elapsed() < Duration::from_secs(120), "no cell baked");
                std::thread::sleep(Duration::from_millis(5));
            }
            // the bake may be writing a file in it: retried until the directory is gone
            while bundle.exists() {
                let _ = std::fs::remove_dir_all(&bundle);
            }
            let o = child.wait_with_output().unwrap();
            (!o.status.success()).then_some(o)
        })
        .expect("the bake always finished before its directory was deleted");
    let b = bundle.display().to_string();
    assert_clean_error_all(&o, &[&b, "cannot write", "no longer exists", "deleted"]);
    eprintln!("{}", stderr(&o).trim());
    // nothing was recreated behind the user's back
    assert!(!bundle.exists());
    let o = run(&args);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_same_bundle(&clean.bundle, &bundle);
    let _ = std::fs::remove_dir_all(&d);
}

/// The inspection can fail: a cell file that is not the clean one but that the reader accepts,
/// and a stray file, are found.
#[test]
fn the_inspection_finds_what_must_never_be() {
    let clean = six();
    let d = tmp("crash", "inspect");
    let bundle = d.join("bundle");
    partial_bundle(clean, &bundle, 2);
    let left = inspect_sound(&bundle, clean);
    assert_eq!((left.cells, left.refused, left.temp), (2, 0, 0));
    // the second cell's bytes under the first cell's name: the reader refuses it (wrong cell)
    let a = format!("cells/{}.lemicell", clean.cells[0].0);
    let b = format!("cells/{}.lemicell", clean.cells[1].0);
    std::fs::write(bundle.join(&a), &clean.files[&b]).unwrap();
    let left = inspect_sound(&bundle, clean);
    assert_eq!((left.cells, left.refused), (1, 1));
    // a cell the reader accepts that is not the clean bake's (baked at another place: the
    // check without a manifest knows the cell's index, not where the grid puts it)
    let other = d.join("other");
    let o = run(&bake_args(
        &[
            &SIX_CELLS[..2],
            &["0.5,1.7,-10,30.5,1.7,10"],
            &SIX_CELLS[3..],
        ]
        .concat(),
        &other,
    ));
    assert!(o.status.success(), "{}", stderr(&o));
    std::fs::copy(other.join(&a), bundle.join(&a)).unwrap();
    let left = inspect(&bundle, clean);
    assert_eq!(left.wrong.len(), 1, "{:?}", left.wrong);
    assert!(
        left.wrong[0].contains("not the clean bake's bytes"),
        "{:?}",
        left.wrong
    );
    // a stray file
    std::fs::write(bundle.join("cells/stray.bin"), b"x").unwrap();
    let left = inspect(&bundle, clean);
    assert_eq!(left.wrong.len(), 2, "{:?}", left.wrong);
    let _ = std::fs::remove_dir_all(&d);
}

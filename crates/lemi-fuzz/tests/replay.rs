//! Replays every file of `fuzz/corpus/<target>/` and `fuzz/regressions/<target>/` through its
//! target: none may panic (a panic caught inside a reader counts too: the panic hook sees it), and
//! none may allocate more than `lemi_fuzz::MAX_ALLOCATION` at once (the allocator aborts the
//! test binary). Every target must have a non-empty corpus.

use std::cell::Cell;
use std::path::Path;
use std::time::Instant;

use lemi_fuzz::{fuzz_dir, CappedAlloc, TARGETS};

#[global_allocator]
static ALLOC: CappedAlloc = CappedAlloc;

thread_local! {
    static PANICKED: Cell<bool> = const { Cell::new(false) };
}

/// The files of `dir`, sorted (none if it does not exist).
fn files(dir: &Path) -> Vec<std::path::PathBuf> {
    let mut out: Vec<_> = std::fs::read_dir(dir)
        .map(|rd| {
            rd.filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| p.is_file())
                .collect()
        })
        .unwrap_or_default();
    out.sort();
    out
}

#[test]
fn every_corpus_and_regression_file_replays_without_a_panic() {
    let previous = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        PANICKED.with(|p| p.set(true));
        previous(info);
    }));
    let root = fuzz_dir();
    let mut failures = Vec::new();
    for &(name, target) in TARGETS {
        let corpus = files(&root.join("corpus").join(name));
        assert!(!corpus.is_empty(), "fuzz/corpus/{name}/ has no seed files");
        let regressions = files(&root.join("regressions").join(name));
        let start = Instant::now();
        for file in corpus.iter().chain(&regressions) {
            let data = std::fs::read(file).unwrap_or_else(|e| panic!("{}: {e}", file.display()));
            PANICKED.with(|p| p.set(false));
            let outcome = std::panic::catch_unwind(|| target(&data));
            if outcome.is_err() || PANICKED.with(|p| p.get()) {
                failures.push(format!("{name}: {}", file.display()));
            }
        }
        eprintln!(
            "{name}: {} corpus + {} regression files in {:.2} s",
            corpus.len(),
            regressions.len(),
            start.elapsed().as_secs_f64()
        );
    }
    assert!(failures.is_empty(), "panicked on: {failures:#?}");
}

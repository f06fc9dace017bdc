//! Shards on shared storage, as a Kubernetes Indexed Job or a Slurm array runs them: every
//! `lemi bake --shard K/N` started at the same time on one bundle directory, then `--merge`, gives
//! the single run's bundle byte for byte; two processes given the same shard at once leave only
//! cell files the bundle reader accepts.

mod common;

use std::path::Path;

use common::{assert_same_bundle, lemi, spawn_lemi, stderr, tmp, SIX_CELLS};
use lemi_core::bundle::Bundle;

fn bake_args(bundle: &Path, extra: &[&str]) -> Vec<String> {
    let mut a: Vec<String> = vec!["bake".into()];
    a.extend(SIX_CELLS.iter().map(|s| s.to_string()));
    a.extend(["-o".into(), bundle.display().to_string()]);
    a.extend(extra.iter().map(|s| s.to_string()));
    a
}

/// Runs the processes at once and waits for all; each must succeed. Returns their outputs.
fn run_all_at_once(runs: Vec<Vec<String>>) -> Vec<std::process::Output> {
    let children: Vec<_> = runs.iter().map(|a| (a, spawn_lemi(a))).collect();
    children
        .into_iter()
        .map(|(args, child)| {
            let o = child.wait_with_output().unwrap();
            assert!(
                o.status.success(),
                "lemi {}: {}",
                args.join(" "),
                stderr(&o)
            );
            o
        })
        .collect()
}

/// How many cells a `lemi bake --json` run baked (rather than skipped).
fn baked(o: &std::process::Output) -> u64 {
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    v["baked"].as_u64().unwrap()
}

/// The eight shards, all started at once on the six cells (two shards get no cell, as
/// pods of an Indexed Job with more completions than cells), then the merge.
#[test]
fn concurrent_shards_then_merge_equal_a_single_run() {
    let d = tmp("concurrent", "shards");
    let single = d.join("single");
    let o = lemi(
        &bake_args(&single, &[])
            .iter()
            .map(String::as_str)
            .collect::<Vec<_>>(),
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let cells = Bundle::open(&single).unwrap().manifest().cells.len();
    assert_eq!(cells, 6);

    let n = 8;
    let sharded = d.join("sharded");
    run_all_at_once(
        (0..n)
            .map(|k| bake_args(&sharded, &["--shard", &format!("{k}/{n}")]))
            .collect(),
    );
    let o = lemi(&["bake", "--merge", sharded.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_same_bundle(&single, &sharded);
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn the_same_shard_twice_at_once_leaves_no_cell_a_reader_rejects() {
    let d = tmp("concurrent", "same-shard");
    // Two processes bake shard 0/2 (three cells) at once, writing the same cell files; the other
    // shard runs at the same time too. The test means something only if both wrote a cell
    // (neither found all done when it started): tried up to three times until they did.
    let bundle = (0..3)
        .find_map(|attempt| {
            let bundle = d.join(format!("bundle-{attempt}"));
            let outs = run_all_at_once(vec![
                bake_args(&bundle, &["--shard", "0/2", "--json"]),
                bake_args(&bundle, &["--shard", "0/2", "--json"]),
                bake_args(&bundle, &["--shard", "1/2"]),
            ]);
            let (a, b) = (baked(&outs[0]), baked(&outs[1]));
            eprintln!(
                "attempt {attempt}: the two runs of shard 0/2 baked {a} and {b} of its 3 cells"
            );
            (a + b > 3).then_some(bundle)
        })
        .expect("the two runs of one shard never overlapped");
    let o = lemi(&["bake", "--merge", bundle.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    // every cell file, read with every check of the one reader
    let b = Bundle::open(&bundle).unwrap();
    let ids: Vec<_> = b.manifest().cells.iter().map(|c| c.id).collect();
    assert_eq!(ids.len(), 6);
    for id in ids {
        if let Err(e) = b.cell(id) {
            panic!("cell {id}: {e}");
        }
    }
    // no temporary file left in the bundle
    let leftovers: Vec<String> = std::fs::read_dir(bundle.join("cells"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| !n.ends_with(".lemicell"))
        .collect();
    assert!(leftovers.is_empty(), "{leftovers:?}");
    // and the bundle is the single run's
    let single = d.join("single");
    let o = lemi(
        &bake_args(&single, &[])
            .iter()
            .map(String::as_str)
            .collect::<Vec<_>>(),
    );
    assert!(o.status.success(), "{}", stderr(&o));
    assert_same_bundle(&single, &bundle);
    let _ = std::fs::remove_dir_all(&d);
}

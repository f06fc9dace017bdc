//! What the CLI test suites share: running the binary, its stderr, a scratch directory, and the
//! check that a failure is a clean error (non-zero exit, no panic, the message names the problem).

use std::path::PathBuf;
use std::process::{Command, Output};

/// Runs `lemi ARGS` (with `XDG_RUNTIME_DIR` set, so Mesa stays quiet) and waits for it.
pub fn lemi(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_lemi"))
        .args(args)
        .env("XDG_RUNTIME_DIR", std::env::temp_dir())
        .output()
        .expect("the lemi binary runs")
}

pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// A fresh directory for one test, named after the suite, the process and `name`.
pub fn tmp(suite: &str, name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("lemi-{suite}-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// The command failed cleanly, and its stderr mentions every one of `needles`.
pub fn assert_clean_error_all(o: &Output, needles: &[&str]) {
    let e = stderr(o);
    assert!(!o.status.success(), "expected failure, stderr: {e}");
    assert_ne!(o.status.code(), Some(0));
    assert!(!e.contains("panicked"), "panic: {e}");
    for needle in needles {
        assert!(e.contains(needle), "error should mention `{needle}`: {e}");
    }
}

/// The command failed cleanly, and its stderr mentions `needle`.
#[allow(dead_code)] // not every suite checks a single message
pub fn assert_clean_error(o: &Output, needle: &str) {
    assert_clean_error_all(o, &[needle]);
}

//! The cluster manifests `deploy/k8s/bake-job.yaml` and `deploy/slurm/bake.sbatch` are the single
//! source of the command lines a cluster runs: the Kubernetes manifest validates against the
//! Kubernetes schemas (offline, with `kubernetes-validate`), and the `lemi bake` lines of both
//! files, run here one process per index with test values for the scene, the bundle and the
//! amount of work, then merged as the files merge, give the single run's bundle byte for byte.

mod common;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::OnceLock;
use std::time::{Duration, Instant};

use common::{assert_same_bundle, lemi, stderr, tmp};
use yaml_rust2::{Yaml, YamlLoader};

fn repo_file(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../..")
        .join(rel)
}

/// The values the tests put in place of the files' scene, region and sizes: six cells of a small
/// built-in city, small layers, so that each process runs for seconds.
fn test_values(bundle: &Path) -> BTreeMap<&'static str, String> {
    BTreeMap::from([
        ("SCENE", "builtin:city:20000".to_string()),
        ("BUNDLE", bundle.display().to_string()),
        ("REGION", "0,1.7,-10,30,1.7,10".to_string()),
        ("RESOLUTION", "32".to_string()),
        ("LAYERS", "4".to_string()),
    ])
}

/// The directory of the `lemi` binary under test, first on `PATH`, so the files' `lemi` is it.
fn path_with_lemi(extra_first: Option<&Path>) -> std::ffi::OsString {
    let bin = Path::new(env!("CARGO_BIN_EXE_lemi"))
        .parent()
        .expect("the binary has a directory")
        .to_path_buf();
    let mut dirs: Vec<PathBuf> = extra_first.into_iter().map(Path::to_path_buf).collect();
    dirs.push(bin);
    dirs.extend(std::env::split_paths(
        &std::env::var_os("PATH").unwrap_or_default(),
    ));
    std::env::join_paths(dirs).unwrap()
}

fn wait_within(child: Child, what: &str, limit: Duration) -> std::process::Output {
    let t = Instant::now();
    let mut child = child;
    loop {
        if child.try_wait().unwrap().is_some() {
            return child.wait_with_output().unwrap();
        }
        if t.elapsed() > limit {
            let _ = child.kill();
            let o = child.wait_with_output().unwrap();
            panic!("{what} still runs after {limit:?}: {}", stderr(&o));
        }
        std::thread::sleep(Duration::from_millis(100));
    }
}

fn spawn(cmd: &mut Command) -> Child {
    cmd.env("XDG_RUNTIME_DIR", std::env::temp_dir())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("the command starts")
}

fn manifest() -> Vec<Yaml> {
    let path = repo_file("deploy/k8s/bake-job.yaml");
    let text = std::fs::read_to_string(&path).unwrap();
    YamlLoader::load_from_str(&text).unwrap()
}

/// The Job named `name`.
fn job<'a>(docs: &'a [Yaml], name: &str) -> &'a Yaml {
    docs.iter()
        .find(|d| d["kind"].as_str() == Some("Job") && d["metadata"]["name"].as_str() == Some(name))
        .unwrap_or_else(|| panic!("no Job {name} in bake-job.yaml"))
}

fn strings(y: &Yaml) -> Vec<String> {
    y.as_vec()
        .expect("a list")
        .iter()
        .map(|v| v.as_str().expect("a string").to_string())
        .collect()
}

/// A container's `env` list as a map (plain values only).
fn env_of(container: &Yaml) -> BTreeMap<String, String> {
    container["env"]
        .as_vec()
        .map(|v| v.as_slice())
        .unwrap_or_default()
        .iter()
        .filter_map(|e| {
            Some((
                e["name"].as_str()?.to_string(),
                e["value"].as_str()?.to_string(),
            ))
        })
        .collect()
}

/// Kubernetes' expansion of `$(NAME)` in a container's command and args from its environment.
fn expand(arg: &str, env: &BTreeMap<String, String>) -> String {
    let mut out = arg.to_string();
    for (k, v) in env {
        out = out.replace(&format!("$({k})"), v);
    }
    assert!(
        !out.contains("$("),
        "`{arg}` names a variable the env does not set"
    );
    out
}

/// The bake flags of the files as one run (`--shard K/N` removed), run once: what every sharded
/// run must equal.
fn single_run() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let dir = tmp("deploy", "single");
        let docs = manifest();
        let container = &job(&docs, "lemi-bake")["spec"]["template"]["spec"]["containers"][0];
        let mut env = env_of(container);
        for (k, v) in test_values(&dir) {
            env.insert(k.to_string(), v);
        }
        env.insert("JOB_COMPLETION_INDEX".into(), "0".into());
        let mut args: Vec<String> = strings(&container["args"])
            .iter()
            .map(|a| expand(a, &env))
            .collect();
        let i = args.iter().position(|a| a == "--shard").expect("--shard");
        args.drain(i..i + 2);
        let o = lemi(&args.iter().map(String::as_str).collect::<Vec<_>>());
        assert!(o.status.success(), "{}", stderr(&o));
        dir
    })
}

#[test]
fn kubernetes_manifest_validates_offline() {
    let file = repo_file("deploy/k8s/bake-job.yaml");
    let run = Command::new("kubernetes-validate")
        .args(["--strict", "--quiet"])
        .arg(&file)
        .output();
    let o = match run {
        Ok(o) => o,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            lemi_testkit::skip(
                "kubernetes-validate is not installed (pip install kubernetes-validate; .ci/run \
                 installs it)",
            );
            return;
        }
        Err(e) => panic!("kubernetes-validate: {e}"),
    };
    assert!(
        o.status.success(),
        "{} does not validate: {}{}",
        file.display(),
        String::from_utf8_lossy(&o.stdout),
        stderr(&o)
    );
}

#[test]
fn kubernetes_job_lines_run_locally_equal_a_single_run() {
    let _one = lemi_testkit::serial();
    let docs = manifest();
    let bake = job(&docs, "lemi-bake");
    let spec = &bake["spec"];
    assert_eq!(spec["completionMode"].as_str(), Some("Indexed"));
    let n = spec["completions"].as_i64().expect("completions");
    assert!(spec["parallelism"]
        .as_i64()
        .is_some_and(|p| p >= 1 && p <= n));
    let pod = &spec["template"]["spec"];
    let claim = pod["volumes"][0]["persistentVolumeClaim"]["claimName"].as_str();
    assert!(claim.is_some(), "the bake mounts a PersistentVolumeClaim");
    let container = &pod["containers"][0];
    assert_eq!(strings(&container["command"]), ["lemi"]);
    let args = strings(&container["args"]);
    assert!(args
        .windows(2)
        .any(|w| w[0] == "--shard" && w[1].starts_with("$(JOB_COMPLETION_INDEX)/")));
    let index = container["env"]
        .as_vec()
        .and_then(|v| {
            v.iter()
                .find(|e| e["name"].as_str() == Some("JOB_COMPLETION_INDEX"))
        })
        .expect("JOB_COMPLETION_INDEX in the env");
    assert_eq!(
        index["valueFrom"]["fieldRef"]["fieldPath"].as_str(),
        Some("metadata.annotations['batch.kubernetes.io/job-completion-index']")
    );
    let mut env = env_of(container);
    assert_eq!(
        env.get("SHARDS"),
        Some(&n.to_string()),
        "SHARDS = completions"
    );

    let dir = tmp("deploy", "k8s");
    let bundle = dir.join("bundle");
    for (k, v) in test_values(&bundle) {
        assert!(env.contains_key(k), "the bake Job sets {k}");
        env.insert(k.to_string(), v);
    }
    // one process per index, all at once, as the Job's pods
    let children: Vec<Child> = (0..n)
        .map(|k| {
            env.insert("JOB_COMPLETION_INDEX".into(), k.to_string());
            let argv: Vec<String> = args.iter().map(|a| expand(a, &env)).collect();
            spawn(Command::new(env!("CARGO_BIN_EXE_lemi")).args(&argv))
        })
        .collect();
    for (k, c) in children.into_iter().enumerate() {
        let o = wait_within(c, &format!("shard {k}"), Duration::from_secs(600));
        assert!(o.status.success(), "shard {k}: {}", stderr(&o));
    }

    // the merge Job's script, with its env (the bundle replaced), under sh
    let merge = &job(&docs, "lemi-bake-merge")["spec"]["template"]["spec"]["containers"][0];
    let command = strings(&merge["command"]);
    assert_eq!(command, ["sh", "-c"]);
    let script = strings(&merge["args"]).concat();
    assert!(script.contains("lemi bake --merge"), "{script}");
    let mut menv = env_of(merge);
    assert_eq!(
        menv.get("SHARDS"),
        Some(&n.to_string()),
        "the merge waits for SHARDS"
    );
    menv.insert("BUNDLE".into(), bundle.display().to_string());
    let o = wait_within(
        spawn(
            Command::new("sh")
                .arg("-c")
                .arg(&script)
                .envs(&menv)
                .env("PATH", path_with_lemi(None)),
        ),
        "the merge",
        Duration::from_secs(120),
    );
    assert!(o.status.success(), "merge: {}", stderr(&o));
    assert_same_bundle(single_run(), &bundle);
    let _ = std::fs::remove_dir_all(&dir);
}

/// The default the script gives a variable (`NAME="${NAME:-value}"`).
fn script_default(script: &str, name: &str) -> String {
    let start = format!("{name}=\"${{{name}:-");
    let line = script
        .lines()
        .find(|l| l.starts_with(&start))
        .unwrap_or_else(|| panic!("bake.sbatch sets no default for {name}"));
    let rest = &line[start.len()..];
    rest[..rest.find("}\"").expect("closing brace")].to_string()
}

#[test]
fn slurm_script_runs_locally_equal_a_single_run_and_submits_a_dependent_merge() {
    let _one = lemi_testkit::serial();
    let file = repo_file("deploy/slurm/bake.sbatch");
    let script = std::fs::read_to_string(&file).unwrap();
    let n: u32 = script_default(&script, "SHARDS").parse().unwrap();
    let docs = manifest();
    let k8s_env = env_of(&job(&docs, "lemi-bake")["spec"]["template"]["spec"]["containers"][0]);
    for name in ["CELL_SIZE", "RESOLUTION", "LAYERS", "SHARDS", "REGION"] {
        assert_eq!(
            Some(&script_default(&script, name)),
            k8s_env.get(name),
            "{name}: bake.sbatch and bake-job.yaml differ"
        );
    }

    let dir = tmp("deploy", "slurm");
    let bundle = dir.join("bundle");
    let values = test_values(&bundle);
    let bash = |args: &[&str]| {
        let mut c = Command::new("bash");
        c.arg(&file)
            .args(args)
            .envs(values.iter().map(|(k, v)| (*k, v.as_str())))
            .env("PATH", path_with_lemi(None));
        c
    };
    // one array task per index, all at once
    let children: Vec<Child> = (0..n)
        .map(|k| spawn(bash(&["shard"]).env("SLURM_ARRAY_TASK_ID", k.to_string())))
        .collect();
    for (k, c) in children.into_iter().enumerate() {
        let o = wait_within(c, &format!("task {k}"), Duration::from_secs(600));
        assert!(o.status.success(), "task {k}: {}", stderr(&o));
    }
    let o = wait_within(
        spawn(&mut bash(&["merge"])),
        "the merge",
        Duration::from_secs(120),
    );
    assert!(o.status.success(), "merge: {}", stderr(&o));
    assert_same_bundle(single_run(), &bundle);

    // submitting: an array of SHARDS tasks, then the merge depending on all of them (afterok),
    // through a stand-in `sbatch` that records its arguments
    let fake = dir.join("fake-bin");
    std::fs::create_dir_all(&fake).unwrap();
    let log = dir.join("sbatch.log");
    let sbatch = fake.join("sbatch");
    std::fs::write(
        &sbatch,
        format!(
            "#!/bin/sh\necho \"$*\" >> '{log}'\n\
             if [ \"$(wc -l < '{log}')\" -eq 1 ]; then echo 4242; else echo 4243; fi\n",
            log = log.display()
        ),
    )
    .unwrap();
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(&sbatch, std::fs::Permissions::from_mode(0o755)).unwrap();
    }
    let o = Command::new("bash")
        .arg(&file)
        .env("PATH", path_with_lemi(Some(&fake)))
        .output()
        .unwrap();
    assert!(o.status.success(), "submit: {}", stderr(&o));
    let calls: Vec<String> = std::fs::read_to_string(&log)
        .unwrap()
        .lines()
        .map(str::to_string)
        .collect();
    assert_eq!(calls.len(), 2, "{calls:?}");
    assert!(
        calls[0].contains(&format!("--array=0-{}", n - 1)) && calls[0].ends_with(" shard"),
        "{calls:?}"
    );
    assert!(
        calls[1].contains("--dependency=afterok:4242") && calls[1].ends_with(" merge"),
        "{calls:?}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

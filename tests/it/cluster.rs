//! Cluster-scale runs as the shipped job templates (`docs/cluster/`) run them: every shard
//! a separate process started by `shard.sh` with the scheduler's index in its environment,
//! all writing to one results directory, reduced by `merge.sh` — and the result compared
//! byte for byte with one unsharded run.

use crate::common::{hybridnav, repo, stderr, tmp_dir};
use crate::montecarlo::assert_same_run;
use std::path::Path;
use std::process::{Child, Command};

const TRIALS: &str = "7";
const SEED: &str = "3";
const SHARDS: u32 = 3;

/// `sh docs/cluster/<script>` with the environment the templates set.
fn script(name: &str, results: &Path, scheduler_env: &[(&str, String)]) -> Command {
    let mut c = Command::new("sh");
    c.arg(repo().join("docs/cluster").join(name))
        .current_dir(repo())
        .env_remove("SLURM_ARRAY_TASK_ID")
        .env_remove("SLURM_ARRAY_TASK_MIN")
        .env_remove("SLURM_ARRAY_TASK_COUNT")
        .env_remove("JOB_COMPLETION_INDEX")
        .env("HYBRIDNAV", env!("CARGO_BIN_EXE_hybridnav"))
        .env("WORLD", "worlds/default.toml")
        .env("TRIALS", TRIALS)
        .env("SEED", SEED)
        .env("SHARDS", SHARDS.to_string())
        .env("THREADS", "1")
        .env("RESULTS", results);
    for (k, v) in scheduler_env {
        c.env(k, v);
    }
    c
}

fn wait_ok(mut child: Child, what: &str) {
    let status = child.wait().expect("wait for a shard");
    assert!(status.success(), "{what} failed: {status}");
}

fn single_run(dir: &Path) {
    let o = hybridnav(&[
        "run",
        "worlds/default.toml",
        "--trials",
        TRIALS,
        "--seed",
        SEED,
        "--threads",
        "2",
        "--quiet",
        "--out",
        dir.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
}

#[test]
fn kubernetes_indexed_job_shards_merge_to_the_single_run() {
    let base = tmp_dir("cluster-k8s");
    let results = base.join("results");
    // All completions at once, as `parallelism` ≥ `completions` would start them.
    let children: Vec<Child> = (0..SHARDS)
        .map(|i| {
            script(
                "shard.sh",
                &results,
                &[("JOB_COMPLETION_INDEX", i.to_string())],
            )
            .spawn()
            .expect("start shard.sh")
        })
        .collect();
    for (i, c) in children.into_iter().enumerate() {
        wait_ok(c, &format!("completion index {i}"));
    }
    let o = script("merge.sh", &results, &[]).output().unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    let single = base.join("single");
    single_run(&single);
    assert_same_run(&results.join("merged"), &single);
}

#[test]
fn slurm_array_shards_merge_to_the_single_run_and_a_requeued_task_resumes() {
    let base = tmp_dir("cluster-slurm");
    let results = base.join("results");
    let task = |id: u32| {
        vec![
            ("SLURM_ARRAY_TASK_ID", id.to_string()),
            ("SLURM_ARRAY_TASK_MIN", "1".to_string()),
            ("SLURM_ARRAY_TASK_COUNT", SHARDS.to_string()),
        ]
    };
    let children: Vec<Child> = (1..=SHARDS)
        .map(|id| script("shard.sh", &results, &task(id)).spawn().unwrap())
        .collect();
    for (i, c) in children.into_iter().enumerate() {
        wait_ok(c, &format!("array task {}", i + 1));
    }
    // Slurm requeues task 2 (node failure after it finished writing): it resumes its own
    // shard and changes nothing.
    let before = std::fs::read(results.join("task-2/summary.json")).unwrap();
    let o = script("shard.sh", &results, &task(2)).output().unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(
        std::fs::read(results.join("task-2/summary.json")).unwrap(),
        before
    );
    let o = script("merge.sh", &results, &[]).output().unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    let single = base.join("single");
    single_run(&single);
    assert_same_run(&results.join("merged"), &single);

    // An array of the wrong size is refused by the task itself, naming the variables.
    let mut wrong = task(1);
    wrong[2].1 = "4".into();
    let o = script("shard.sh", &base.join("other"), &wrong)
        .output()
        .unwrap();
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("the Slurm array has 4 tasks"),
        "{}",
        stderr(&o)
    );
    // Outside a scheduler the script says what it needs.
    let o = script("shard.sh", &base.join("other"), &[])
        .output()
        .unwrap();
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("JOB_COMPLETION_INDEX"),
        "{}",
        stderr(&o)
    );
}

#[test]
fn the_templates_agree_with_the_scripts_they_run() {
    let read = |f: &str| std::fs::read_to_string(repo().join("docs/cluster").join(f)).unwrap();
    // Slurm: the array's size is SHARDS, and the task runs shard.sh.
    let sbatch = read("slurm-array.sbatch");
    let array = sbatch
        .lines()
        .find_map(|l| l.strip_prefix("#SBATCH --array=1-"))
        .expect("an --array line");
    // SHARDS defaults to the array's size (a submission that overrides --array on the
    // command line exports SHARDS with it, as .ci/slurm-test does).
    assert!(
        sbatch.contains(&format!("export SHARDS=${{SHARDS:-{array}}}")),
        "{array}"
    );
    assert!(sbatch.contains("docs/cluster/shard.sh"));
    assert!(read("slurm-merge.sbatch").contains("docs/cluster/merge.sh"));
    for f in [
        "slurm-array.sbatch",
        "slurm-merge.sbatch",
        "shard.sh",
        "merge.sh",
    ] {
        let o = Command::new("bash")
            .arg("-n")
            .arg(repo().join("docs/cluster").join(f))
            .output()
            .unwrap();
        assert!(o.status.success(), "{f}: {}", stderr(&o));
    }
    // Kubernetes: Indexed completion mode, completions = SHARDS, the script as command.
    let job = read("k8s-indexed-job.yaml");
    let completions = job
        .lines()
        .find_map(|l| l.trim().strip_prefix("completions: "))
        .expect("completions");
    assert!(job.contains("completionMode: Indexed"));
    let shards_value = job
        .split("name: SHARDS")
        .nth(1)
        .and_then(|rest| rest.lines().nth(1))
        .expect("a SHARDS value");
    assert_eq!(shards_value.trim(), format!("value: \"{completions}\""));
    assert!(job.contains("docs/cluster/shard.sh"));
    assert!(read("k8s-merge-job.yaml").contains("docs/cluster/merge.sh"));
    // Both manifests are YAML Kubernetes accepts the shape of (when PyYAML is here).
    if crate::common::python_has(&["yaml"]) {
        let check = "import sys, yaml\n\
            for f in sys.argv[1:]:\n\
            \x20   d = yaml.safe_load(open(f))\n\
            \x20   assert d['apiVersion'] == 'batch/v1' and d['kind'] == 'Job', f\n\
            \x20   c = d['spec']['template']['spec']['containers'][0]\n\
            \x20   assert c['command'][0].startswith('docs/cluster/'), f\n\
            print('yaml ok')";
        let o = Command::new("python3")
            .args(["-c", check])
            .arg(repo().join("docs/cluster/k8s-indexed-job.yaml"))
            .arg(repo().join("docs/cluster/k8s-merge-job.yaml"))
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", stderr(&o));
    }
}

/// A task requeued into a results directory that holds another run's shard (the run was
/// resubmitted with another seed without clearing `RESULTS`) is refused, naming the
/// difference, and leaves that shard as it was: nothing is mixed.
#[test]
fn a_task_resubmitted_with_another_seed_does_not_mix_runs() {
    let base = tmp_dir("cluster-mix");
    let results = base.join("results");
    let slurm = |seed: &str| {
        let mut c = script(
            "shard.sh",
            &results,
            &[
                ("SLURM_ARRAY_TASK_ID", "1".to_string()),
                ("SLURM_ARRAY_TASK_MIN", "1".to_string()),
                ("SLURM_ARRAY_TASK_COUNT", SHARDS.to_string()),
            ],
        );
        c.env("SEED", seed);
        c.output().expect("run shard.sh")
    };
    let o = slurm(SEED);
    assert!(o.status.success(), "{}", stderr(&o));
    let task = results.join("task-1");
    let before: Vec<(String, Vec<u8>)> = ["run.json", "summary.json", "epochs.csv"]
        .iter()
        .map(|f| (f.to_string(), std::fs::read(task.join(f)).unwrap()))
        .collect();
    let o = slurm("4");
    let e = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{e}");
    assert!(e.contains("holds a different run (seed 4 vs 3)"), "{e}");
    for (f, bytes) in before {
        assert!(
            std::fs::read(task.join(&f)).unwrap() == bytes,
            "{f} changed"
        );
    }
    let _ = std::fs::remove_dir_all(&base);
}

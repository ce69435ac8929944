#!/bin/sh
# One task of a sharded hybridnav Monte Carlo run: runs shard K of N into
# $RESULTS/task-<index>, where K comes from the scheduler (`--shard auto/N`: Slurm's
# SLURM_ARRAY_TASK_ID or Kubernetes' JOB_COMPLETION_INDEX). A task that is requeued or
# restarted after a node failure resumes its own shard: trials already written are kept.
#
# Environment (the job templates set them):
#   WORLD     world file, as the task sees it (default worlds/default.toml)
#   TRIALS    trials of the whole run (all shards together)
#   SEED      master seed (default: the world's)
#   SHARDS    number of shards N (= array size / completions)
#   RESULTS   shared directory every task can write (default ./results)
#   THREADS   worker threads per task (default: all the task's cores)
#   OUTPUTS   what each task writes (`run --outputs`; default all; keep `trials`, which
#             the merge reads), e.g. summary,trials for a run of 10⁶ trials
#   HYBRIDNAV the binary (default: hybridnav on PATH)
set -eu
: "${TRIALS:?set TRIALS, the trials of the whole run}"
: "${SHARDS:?set SHARDS, the number of shards}"
WORLD=${WORLD:-worlds/default.toml}
RESULTS=${RESULTS:-./results}
HYBRIDNAV=${HYBRIDNAV:-hybridnav}
TASK=${SLURM_ARRAY_TASK_ID:-${JOB_COMPLETION_INDEX:?neither SLURM_ARRAY_TASK_ID nor JOB_COMPLETION_INDEX is set: run this from a Slurm array or an Indexed Job}}
OUT="$RESULTS/task-$TASK"
mkdir -p "$RESULTS"
set -- run "$WORLD" --trials "$TRIALS" --shard "auto/$SHARDS" --out "$OUT" --quiet
if [ -n "${SEED:-}" ]; then set -- "$@" --seed "$SEED"; fi
if [ -n "${THREADS:-}" ]; then set -- "$@" --threads "$THREADS"; fi
if [ -n "${OUTPUTS:-}" ]; then set -- "$@" --outputs "$OUTPUTS"; fi
# A directory with a manifest is this task's earlier attempt: continue it.
if [ -f "$OUT/run.json" ]; then set -- "$@" --resume; fi
exec "$HYBRIDNAV" "$@"

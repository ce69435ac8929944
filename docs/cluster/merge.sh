#!/bin/sh
# Reduces the shards of a run (the task-* directories shard.sh wrote under $RESULTS) into
# $RESULTS/merged: exactly the files one unsharded run would have written. It refuses a
# missing shard, a shard given twice, or shards of different worlds or seeds.
set -eu
RESULTS=${RESULTS:-./results}
HYBRIDNAV=${HYBRIDNAV:-hybridnav}
# MERGE_OUTPUTS: what the merged run writes (`merge --outputs`; default all).
exec "$HYBRIDNAV" merge "$RESULTS"/task-* --out "$RESULTS/merged" --outputs "${MERGE_OUTPUTS:-all}"

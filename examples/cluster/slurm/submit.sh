#!/bin/bash
# Runs a campaign on a Slurm cluster in N shards and aggregates it at the end:
#
#   examples/cluster/slurm/submit.sh CAMPAIGN.toml OUT_FOLDER N [sbatch options…]
#
# CAMPAIGN.toml and OUT_FOLDER must be on a file system every node mounts; `fdi-launch` must be
# on the nodes' PATH (or FDI_LAUNCH its path). The sbatch options (`--partition=…`,
# `--time=…`, `--account=…`) go to both jobs. Progress:
# `fdi-launch sweep CAMPAIGN.toml --status --out OUT_FOLDER`.
set -euo pipefail
if [ $# -lt 3 ]; then
  echo "usage: $0 CAMPAIGN.toml OUT_FOLDER N [sbatch options…]" >&2
  exit 2
fi
here=$(cd "$(dirname "$0")" && pwd)
campaign=$(realpath "$1")
out=$(realpath -m "$2")
shards=$3
shift 3
case $shards in
  '' | *[!0-9]*) echo "$0: N must be a whole number of shards, not '$shards'" >&2; exit 2 ;;
esac
export FDI_CAMPAIGN=$campaign FDI_OUT=$out
mkdir -p "$out"
# `--parsable` prints `JOBID` or `JOBID;CLUSTER`.
shard_job=$(sbatch --parsable --array=1-"$shards" "$@" "$here/shard.sbatch")
shard_job=${shard_job%%;*}
aggregate_job=$(sbatch --parsable --dependency=afterany:"$shard_job" "$@" "$here/aggregate.sbatch")
aggregate_job=${aggregate_job%%;*}
echo "shards: job $shard_job (array 1-$shards)"
echo "aggregate: job $aggregate_job (after every shard)"
echo "progress: fdi-launch sweep $campaign --status --out $out"

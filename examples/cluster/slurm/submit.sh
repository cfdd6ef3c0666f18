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
mkdir -p "$out"
# Passed explicitly: a site may not export the submitting shell's environment by default.
# FDI_SHARD_COUNT makes task K shard K of N even when it is sent again alone
# (`sbatch --array=K`).
export_list="ALL,FDI_CAMPAIGN=$campaign,FDI_OUT=$out,FDI_SHARD_COUNT=$shards"
# `--parsable` prints `JOBID` or `JOBID;CLUSTER`.
shard_job=$(sbatch --parsable --export="$export_list" --array=1-"$shards" "$@" "$here/shard.sbatch")
shard_job=${shard_job%%;*}
echo "shards: job $shard_job (array 1-$shards)"
aggregate_job=$(sbatch --parsable --export="$export_list" --dependency=afterany:"$shard_job" "$@" \
  "$here/aggregate.sbatch")
aggregate_job=${aggregate_job%%;*}
echo "aggregate: job $aggregate_job (after every shard)"
echo "progress: fdi-launch sweep $campaign --status --out $out"
echo "shard K again: sbatch --export=$export_list --array=K $here/shard.sbatch"

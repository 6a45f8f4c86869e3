#!/usr/bin/env bash
# A basin map on a Slurm cluster: 16 array tasks, one shard each, then one merge.
#
#   sbatch deploy/slurm-basins.sh                                  # the 16 shards
#   sbatch --dependency=afterok:<jobid> --wrap \
#     'chaosctl merge out/basins.shard-*-of-16.json --out out/basins'   # the merge
#
# Shard I of N runs grid points k with k mod N = I. Every task must see the same arguments (and
# the same --config file, if any): merge checks that and refuses shards of another grid.
#SBATCH --job-name=chaosd-basins
#SBATCH --array=0-15
#SBATCH --cpus-per-task=4
#SBATCH --time=02:00:00
#SBATCH --output=out/basins-%a.log
set -euo pipefail
N=16
mkdir -p out
chaosctl basins --vary q1=-1.5:1.5:0.01 --mu 0:3:0.05 \
    --jobs "${SLURM_CPUS_PER_TASK:-1}" --output out/basins \
    --shard "${SLURM_ARRAY_TASK_ID}/${N}"

#!/bin/bash
# Peak memory of each method against the up-front estimate (docs/benchmarks.md, "Memory").
# One `cellflip bench` process per run (its peak is the process's); one CSV line per run.
# Usage: tools/memory.sh [path/to/cellflip]   (default: target/release/cellflip)
set -euo pipefail
B=${1:-target/release/cellflip}
echo "method,scene,res,particles,peak_mib,estimate_mib"
run() { # method scene res
  local o
  o=$("$B" bench --scene "$2" --res "$3" --steps 2 --warmup 1 --method "$1")
  local parts peak est
  parts=$(echo "$o" | grep -oP '\), \K[0-9]+(?= particles)')
  peak=$(echo "$o" | grep -oP 'so far\): \K[0-9]+')
  est=$(echo "$o" | grep -oP 'estimated up front \K[0-9]+')
  echo "$1,$2,$3,$parts,$peak,$est"
}
for m in flip ccp idp nbflip powerpic; do
  for r in 48 64 96; do run $m dam-3d $r; done
  for r in 40 64; do run $m deep-pool-3d $r; done
  for r in 512 1024; do run $m dam-2d $r; done
  run $m deep-pool-2d 512
done
for m in flip ccp idp nbflip; do run $m deep-pool-3d 96; done
for r in 64 96 128; do for s in drop-3d falling-obstacle-3d; do run ccp $s $r; run flip $s $r; done; done

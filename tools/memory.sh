#!/bin/bash
# Peak memory of each method against the up-front estimate (docs/benchmarks/memory.md).
# One `cellflip bench` process per run (its peak is the process's); one CSV line per run.
# Usage: tools/memory.sh [path/to/cellflip]   (default: target/release/cellflip)
set -euo pipefail
B=${1:-target/release/cellflip}
# The estimate's inputs follow: cells, seeded fluid cells, particles seeded, particles held.
echo "method,scene,res,particles,peak_mib,start_peak_mib,estimate_mib,cells,fluid_cells,seeded,held"
run() { # method scene res
  local o
  o=$("$B" bench --scene "$2" --res "$3" --steps 2 --warmup 1 --method "$1")
  local parts peak start est inputs
  parts=$(echo "$o" | grep -oP '\), \K[0-9]+(?= particles)')
  peak=$(echo "$o" | grep -oP 'so far\): \K[0-9]+')
  start=$(echo "$o" | grep -oP '\(\K[0-9]+(?= after seeding)')
  est=$(echo "$o" | grep -oP 'estimated up front \K[0-9]+')
  inputs=$(echo "$o" | grep -oP 'from \K[0-9]+ cells, [0-9]+ seeded fluid cells, [0-9]+ particles seeded, [0-9]+' |
    tr -dc '0-9 ' | tr -s ' ' ',')
  echo "$1,$2,$3,$parts,$peak,$start,$est,$inputs"
}
for m in flip ccp idp nbflip powerpic; do
  for r in 48 64 96; do run $m dam-3d $r; done
  for r in 40 64; do run $m deep-pool-3d $r; done
  for r in 512 1024; do run $m dam-2d $r; done
  run $m deep-pool-2d 512
done
for m in flip ccp idp nbflip; do run $m deep-pool-3d 96; done
for r in 64 96 128; do for s in drop-3d falling-obstacle-3d; do run ccp $s $r; run flip $s $r; done; done
# The band methods' fit (docs/benchmarks/memory.md): their particles held and their start.
for m in ccp nbflip; do for s in drop-3d falling-obstacle-3d; do run $m $s 160; done; done
for r in 64 96 128; do run nbflip deep-pool-3d $r; done

#!/usr/bin/env bash
# build.sh — a headless MantaFlow (thunil/mantaflow) with OpenMP, for bench.py and manta_dam.py.
#
# The caller provides the source tree (tested: master 4944451, 2022-07-21; e.g.
# `git archive master | tar -x -C SRC` from a clone of thunil/mantaflow). Needs cmake, g++ and
# python3-dev (Debian: apt-get install -y cmake). About 3.5 min on 2 cores. The result is `manta`
# (v0.13, fp32, OpenMP, -O3, Python embedded) that runs scene scripts: `manta scene.py args`.
#
# usage (from the project root): MANTA_SRC=SRC tools/mantaflow/build.sh   (or: build.sh SRC)
#   builds in $MANTA_BUILD (default $OUT/manta-build, $OUT default: a new temp dir)
# Prints last: "MANTA_BIN=<path of the built manta binary>" (use it for bench.py and manta_dam.py).
set -eu
SRC=${1:-${MANTA_SRC:?set MANTA_SRC (or pass it as the argument) to a thunil/mantaflow source tree}}
[ -f "$SRC/CMakeLists.txt" ] || { echo "build: $SRC has no CMakeLists.txt"; exit 1; }
command -v cmake > /dev/null || { echo "build: cmake missing (apt-get install -y cmake)"; exit 1; }
SRC=$(cd "$SRC" && pwd)
OUT=${OUT:-$(mktemp -d)}
BUILD=${MANTA_BUILD:-$OUT/manta-build}
mkdir -p "$BUILD" && cd "$BUILD"
cmake "$SRC" -DGUI=OFF -DOPENMP=ON -DNUMPY=OFF -DCMAKE_BUILD_TYPE=Release > cmake.log 2>&1 || { tail -20 cmake.log; exit 1; }
make -j2 > make.log 2>&1 || { tail -30 make.log; exit 1; }
[ -x "$BUILD/manta" ] || { echo "build: no manta binary in $BUILD (see make.log)"; exit 1; }
echo "MANTA_BIN=$BUILD/manta"

#!/bin/sh
# Builds lemon_solve next to this script (needs LEMON: apt-get install liblemon-dev).
set -e
cd "$(dirname "$0")"
g++ -O2 -std=c++17 lemon_solve.cpp -llemon -o lemon_solve

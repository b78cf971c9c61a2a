#!/bin/bash
# Apply this folder's patches to the GridPACK built by ../shared/reference/gridpack/build.sh and
# rebuild its dsf_obs.x driver (about 1 minute on 2 cores). Idempotent: an applied patch is
# skipped. Usage, as root, after build.sh:
#   GRIDPACK_HOME=/opt/gridpack experiments/reference/gridpack_patches/apply.sh
set -euo pipefail
HERE=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
GRIDPACK_HOME=${GRIDPACK_HOME:-/opt/gridpack}
SRC=$GRIDPACK_HOME/gridpack
[ -f "$SRC/src/CMakeLists.txt" ] && [ -f "$GRIDPACK_HOME/build/CMakeCache.txt" ] || {
  echo "no GridPACK build under $GRIDPACK_HOME: run ../shared/reference/gridpack/build.sh first"
  exit 1; }
for p in "$HERE"/*.patch; do
  if patch -d "$SRC" -p1 -R --dry-run -s -f < "$p" >/dev/null 2>&1; then
    echo "patch $(basename "$p"): already applied"
  else
    patch -d "$SRC" -p1 -N < "$p"
  fi
done
nice -n 19 make -C "$GRIDPACK_HOME/build" -j"${JOBS:-2}" dsf_obs.x >/dev/null
echo "$GRIDPACK_HOME/build/applications/dynamic_simulation_full_y/dsf_obs.x"

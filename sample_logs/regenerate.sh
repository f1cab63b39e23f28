#!/usr/bin/env bash
# Regenerate the simulated sample logs (deterministic: same seed, same bytes).
# Usage: sample_logs/regenerate.sh   (from the repository root, after `make setup`)
# The same simulated office run is written in every format sonarmap reads; the corridor
# and orchard worlds as MCAP only. Ground truth (<stem>.truth.yaml/.pgm/.csv) is written
# once per world, beside the MCAP log.
set -euo pipefail
cd "$(dirname "$0")/.."
SM=${SONARMAP:-.venv/bin/sonarmap}
COMMON=(--speed 0.5 --ring-rate 5 --seed 1 --sonar-model ideal)
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT

for world in office corridor orchard; do
  rm -rf "sample_logs/$world"
  mkdir -p "sample_logs/$world"
  "$SM" simulate "sample_logs/worlds/$world.toml" -o "sample_logs/$world/$world.mcap" \
    -f mcap --compression zstd "${COMMON[@]}" >/dev/null
done
# The office run in the other formats (the truth files of these copies are dropped).
"$SM" simulate sample_logs/worlds/office.toml -o "$tmp/office.bag" -f ros1 --compression lz4 "${COMMON[@]}" >/dev/null
"$SM" simulate sample_logs/worlds/office.toml -o "$tmp/office_ros2" -f ros2 --compression zstd "${COMMON[@]}" >/dev/null
"$SM" simulate sample_logs/worlds/office.toml -o "$tmp/office_csv" -f csv-set "${COMMON[@]}" >/dev/null
mv "$tmp/office.bag" "$tmp/office_ros2" "$tmp/office_csv" sample_logs/office/
du -sh sample_logs/*/

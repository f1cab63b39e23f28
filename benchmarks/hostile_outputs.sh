#!/usr/bin/env bash
# Issue 58 (data loss, side files, hangs, paths): each case's exit code, stderr lines (batch
# progress excluded), wall seconds and the command's max RSS (MB; a batch's workers are
# separate processes). Usage: benchmarks/hostile_outputs.sh [SCRATCH_DIR]
set -u
ROOT=$(cd "$(dirname "$0")/.." && pwd)
S=$ROOT/.venv/bin/sonarmap
R=$ROOT/sample_logs
T=${1:-$(mktemp -d)}
mkdir -p "$T"
m() {
  local name=$1; shift
  /usr/bin/time -f "%e %M" -o "$T/t" "$@" > /dev/null 2> "$T/e"; local rc=$?
  read -r s kb < <(tail -1 "$T/t")
  printf "| %-34s | %d | %d | %5.1f | %4d |\n" "$name" $rc \
    "$(grep -vc '^sonarmap: batch:' "$T/e")" "$s" $((kb / 1024))
}
echo "| case | exit | stderr lines | wall (s) | max RSS (MB) |"
echo "| --- | --: | --: | --: | --: |"
mkdir -p "$T/r/logs" && cp "$R/office/office.mcap" "$T/r/logs/" && echo notes > "$T/r/logs/summary.md"
m "1 batch, user summary.md in -o" "$S" batch "$T/r/logs" -o "$T/r/logs" --workers 1 -q
mkdir -p "$T/r2/office" && echo '{"acc":0.9}' > "$T/r2/office/metrics.json"
echo x > "$T/r2/office/features.parquet"
m "2 run --force on a names-only dir" "$S" run "$R/office/office.mcap" -o "$T/r2/office" --force -q
m "2 batch onto a names-only dir" "$S" batch "$R/office/office.mcap" -o "$T/r2" --workers 1 -q
cp "$R"/office/office.truth.* "$T/" && "$S" run "$R/office/office.mcap" -o "$T/run" -q
m "3 evaluate -o truth.yaml --force" "$S" evaluate "$T/run" --truth "$T/office.truth.yaml" \
  -o "$T/office.truth.yaml" --force
m "5 -c /dev/zero" "$S" run "$R/office/office.mcap" -o "$T/x" -c /dev/zero -q
m "5 @/dev/zero manifest" "$S" batch @/dev/zero -o "$T/x"
printf 'P5\n100000 100000\n255\n' > "$T/huge.pgm"
sed 's/office.truth.pgm/huge.pgm/' "$T/office.truth.yaml" > "$T/huge.yaml"
m "5 truth PGM 100000x100000" "$S" evaluate "$T/run" --truth "$T/huge.yaml"
sed 's/origin: \[/origin: [100000.0, 100000.0, 0.0] #/' "$T/office.truth.yaml" > "$T/far.yaml"
m "6 truth map 100 km away" "$S" evaluate "$T/run" --truth "$T/far.yaml"
m "7 --memory-limit 100MB" "$S" batch "$R/office/office.mcap" -o "$T/ml" --workers 1 \
  --memory-limit 100MB -q
mkdir -p "$T/loop/a" && cp "$R/office/office.mcap" "$T/loop/a" && ln -s .. "$T/loop/a/up"
ln -s a "$T/loop/b"
m "8 symlink loop tree" "$S" batch "$T/loop" -o "$T/loopout" --workers 1 -q
m "11 -o name of 300 bytes" "$S" run "$R/office/office.mcap" -o "$T/$(printf 'a%.0s' $(seq 300))" -q
cp -r "$R/office/office_csv" "$T/neg"
for f in poses ranges; do
  awk -F, 'NR==1{print;next}{OFS=",";$1=$1-1700000200;print}' "$T/neg/$f.csv" > "$T/n.csv"
  mv "$T/n.csv" "$T/neg/$f.csv"
done
m "14 CSV times before 0" "$S" run "$T/neg" -o "$T/negout" -q
cp -r "$R/office/office_csv" "$T/far200" && sed -i '2,$s/,5.0$/,200.0/' "$T/far200/sensors.csv"
python3 - "$T" <<'EOF'
import math, sys
t = sys.argv[1]
out = ["[grid]", "max_cells = 2000000"]
for line in open(f"{t}/far200/sensors.csv").read().split("\n")[1:]:
    if line.strip():
        n, x, y, yaw = line.split(",")[:4]
        out += ["[[sensors.mounts]]", f'name = "{n}"', f"x = {x}", f"y = {y}",
                f"yaw_deg = {math.degrees(float(yaw))}", "max_range = 5.0"]
open(f"{t}/c200.toml", "w").write("\n".join(out) + "\n")
EOF
m "13 mounts 5 m, log claims 200 m" "$S" run "$T/far200" -o "$T/f200" -c "$T/c200.toml" -q
cp -r "$R/office/office_ros2" "$T/bag" && mv "$T/bag/office_ros2.db3.zstd" "$T/x.db3.zstd"
sed -i 's#  - office_ros2.db3.zstd#  - ../x.db3.zstd#' "$T/bag/metadata.yaml"
m "16 metadata names ../x.db3" "$S" info "$T/bag"
printf 'office.mcap\nb\0ad.mcap\n' > "$T/nul.txt" && cp "$R/office/office.mcap" "$T/"
m "11 manifest line with a NUL byte" "$S" batch "@$T/nul.txt" -o "$T/mo1" -q
printf '%s\n' "$(printf 'x%.0s' $(seq 5000))" > "$T/long.txt"
m "11 manifest name of 5000 chars" "$S" batch "@$T/long.txt" -o "$T/mo2" -q
python3 - "$T" "$R" <<'EOF'
import random, struct, sys
t, r = sys.argv[1], sys.argv[2]
bag = bytearray(open(f"{r}/office/office.bag", "rb").read())
k = bag.index(b"index_pos=") + 10
bag[k:k + 8] = bytes(8)  # unindexed: only a forward walk finds the records
pos, chunks = 13, []
while pos + 8 <= len(bag):
    hlen = struct.unpack_from("<I", bag, pos)[0]
    dlen = struct.unpack_from("<I", bag, pos + 4 + hlen)[0]
    h = bytes(bag[pos + 4:pos + 4 + hlen])
    if h[h.index(b"op=") + 3] == 5:
        chunks.append(pos)
    pos += 8 + hlen + dlen
bag[chunks[1]:chunks[1] + 200] = random.Random(1).randbytes(200)
open(f"{t}/framing.bag", "wb").write(bag)
mc = bytearray(open(f"{r}/office/office.mcap", "rb").read())
mc[-8:] = bytes(8)  # no end magic: scanned
mc[168222:168222 + 200] = random.Random(2).randbytes(200)  # the second chunk's head
open(f"{t}/framing.mcap", "wb").write(mc)
EOF
m "9 bag framing garbage, no index" "$S" run "$T/framing.bag" -o "$T/fb" -q
m "9 mcap framing garbage, no summary" "$S" run "$T/framing.mcap" -o "$T/fm" -q
mkdir -p "$T/gold/goldens/office" && echo '{"acc": 0.9}' > "$T/gold/goldens/office/metrics.json"
printf '[[log]]\nname = "office"\npath = "%s"\n' "$R/office/office.mcap" > "$T/gold/suite.toml"
m "4 regress --update over a user dir" "$S" regress --suite "$T/gold/suite.toml" \
  --goldens "$T/gold/goldens" --update --workers 1 -q

#!/usr/bin/env bash
# A full disk while a checkpoint is written: one-line error naming the file, exit 2, no partial
# file left, the reason at the end of log.txt. Needs a small tmpfs (root); skipped otherwise.
# Usage: check_disk_full.sh <build/apps dir> <tiny dataset dir>
set -u
apps=$1 data=$2
mnt=$(mktemp -d)
if ! mount -t tmpfs -o size=1m tmpfs "$mnt" 2>/dev/null; then
  rmdir "$mnt"
  echo "SKIP: cannot mount a tmpfs here (needs root); the disk-full case is not tested"
  exit 77
fi
trap 'umount "$mnt"; rmdir "$mnt"' EXIT
err=$("$apps/transhuman-train" --config tests/configs/tiny_train.yaml --out "$mnt/run" --max-steps 1 \
  data.root="$data" data.split_file="$data/split.yaml" model.grouping.cache_dir="$data/../kmeans_cache" \
  train.val_views=0 2>&1 >/dev/null)
rc=$?
last=$(printf '%s\n' "$err" | tail -1)
leftovers=$(find "$mnt" -name '*.tmp*' | wc -l)
echo "exit $rc; last stderr line: $last; partial files left: $leftovers"
echo "log.txt ends with: $(tail -1 "$mnt/run/log.txt")"
[[ $rc -eq 2 ]] || { echo "FAIL: exit code $rc, expected 2"; exit 1; }
[[ "$last" == *"transhuman-train: error: cannot write '$mnt/run/checkpoints/"*"(disk full?)"* ]] || { echo "FAIL: message"; exit 1; }
[[ $leftovers -eq 0 ]] || { echo "FAIL: partial files left"; exit 1; }
tail -1 "$mnt/run/log.txt" | grep -q "error: cannot write" || { echo "FAIL: log.txt does not end with the error"; exit 1; }
echo "passed"

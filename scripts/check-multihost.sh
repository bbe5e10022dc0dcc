#!/usr/bin/env bash
# Two "machines" on this one: two network namespaces joined by a veth pair (10.231.0.1 and
# 10.231.0.2, a private test range that exists only between them), one rank in each, rank 0's
# address as MASTER_ADDR and the veth as GLOO_SOCKET_IFNAME. Checks, on the tiny dataset:
#   - training: the weights of 2 ranks across the link are bit-identical to the same 2 ranks
#     over loopback;
#   - evaluation: 2 ranks across the link write the rows of one process;
#   - faults over the link (delay and loss where the kernel has netem, the link down for 20 s
#     with a 60 s and a 10 s timeout, a rank SIGKILLed, a wrong MASTER_ADDR, a port in use, two
#     runs given one MASTER_PORT): exit codes, seconds to exit, the checkpoint left, resume.
# Prints a Markdown table of the faults. Namespaces, links and processes are removed by a trap,
# also on failure. Needs root (ip netns); exits 77 (skipped) where namespaces cannot be made.
#
#   scripts/check-multihost.sh [APPS_DIR] [TINY_DATASET] [CHECKPOINT]
#     (default build/apps, a fresh tiny dataset, a checkpoint trained here for the evaluation)
#   TH_MULTIHOST_FAULTS=0   only the two equality checks
#   TH_MULTIHOST_TABLE=FILE also write the fault table there
#   TH_MULTIHOST_KEEP=1     keep the logs and run folders (the folder is printed)
set -uo pipefail
repo=$(cd "$(dirname "$0")/.." && pwd)
apps=$(cd "${1:-$repo/build/apps}" && pwd)
cd "$repo"
work=$(mktemp -d "${TMPDIR:-/tmp}/th-multihost.XXXXXX")
tag=$$
ns_a=th-mh-a-$tag ns_b=th-mh-b-$tag
if_a=tha$((tag % 100000)) if_b=thb$((tag % 100000))
addr_a=10.231.0.1 addr_b=10.231.0.2
pids=()

cleanup() {
  local p
  for p in "${pids[@]}"; do kill -9 "$p" 2>/dev/null; done
  for ns in "$ns_a" "$ns_b"; do
    if ip netns list 2>/dev/null | grep -q "^$ns\b"; then
      for p in $(ip netns pids "$ns" 2>/dev/null); do kill -9 "$p" 2>/dev/null; done
      ip netns del "$ns" 2>/dev/null
    fi
  done
  ip link del "$if_a" 2>/dev/null
  if [[ -n ${TH_MULTIHOST_KEEP:-} ]]; then echo "check-multihost: logs kept in $work"; else rm -rf "$work"; fi
}
trap cleanup EXIT
trap 'exit 130' INT TERM

log() { echo "check-multihost: $*"; }
die() {
  echo "check-multihost: FAIL: $*" >&2
  exit 1
}

# The two hosts.
if [[ $(id -u) -ne 0 ]] || ! ip netns add "$ns_a" 2>/dev/null; then
  log "skipped: network namespaces cannot be made here (needs root and ip netns)"
  exit 77
fi
ip netns add "$ns_b" || die "cannot make namespace $ns_b"
ip link add "$if_a" type veth peer name "$if_b" || die "cannot make a veth pair"
ip link set "$if_a" netns "$ns_a" && ip link set "$if_b" netns "$ns_b" || die "cannot move the veth ends"
ip -n "$ns_a" addr add "$addr_a/24" dev "$if_a" && ip -n "$ns_b" addr add "$addr_b/24" dev "$if_b" ||
  die "cannot address the veth ends"
for ns in "$ns_a" "$ns_b"; do ip -n "$ns" link set lo up; done
ip -n "$ns_a" link set "$if_a" up && ip -n "$ns_b" link set "$if_b" up || die "cannot bring the link up"
log "hosts: $ns_a ($addr_a on $if_a) and $ns_b ($addr_b on $if_b)"

if [[ -n ${2:-} ]]; then
  data=$(cd "$2" && pwd)
else
  data=$work/tiny
  "$apps/transhuman-synth" --config configs/synth/tiny.yaml --out "$data" >/dev/null 2>&1 ||
    die "cannot generate the tiny dataset"
fi
common=(--threads 1 "data.root=$data" "data.split_file=$data/split.yaml" "model.grouping.cache_dir=$work/kmeans"
        train.val_views=0)
train_args=("$apps/transhuman-train" --config tests/configs/tiny_train.yaml "${common[@]}")

port() { echo $((20000 + RANDOM % 30000)); }

# rank NS|- RANK ADDR PORT LOG CMD...: one rank of 2 in namespace NS ("-": this machine's
# loopback), in the background; its pid is appended to pids.
rank() {
  local ns=$1 r=$2 addr=$3 p=$4 out=$5
  shift 5
  local ifname=
  [[ $ns == "$ns_a" ]] && ifname=$if_a
  [[ $ns == "$ns_b" ]] && ifname=$if_b
  local envs=(RANK=$r WORLD_SIZE=2 LOCAL_RANK=0 LOCAL_WORLD_SIZE=1 MASTER_ADDR=$addr MASTER_PORT=$p)
  [[ -n $ifname ]] && envs+=(GLOO_SOCKET_IFNAME=$ifname)
  if [[ $ns == - ]]; then
    env "${envs[@]}" "$@" >"$out" 2>&1 &
  else
    ip netns exec "$ns" env "${envs[@]}" "$@" >"$out" 2>&1 &
  fi
  pids+=($!)
  last_pid=$!
}

# pair NAME OUT ARGS...: a run of 2 ranks on port $p, rank 0 in the first namespace (writing OUT
# when not empty), rank 1 in the second, logs $work/NAME0.log and NAME1.log; sets r0 and r1.
pair() {
  local name=$1 out=$2
  shift 2
  local outs=()
  [[ -n $out ]] && outs=(--out "$out")
  rank "$ns_a" 0 $addr_a "$p" "$work/${name}0.log" "$@" "${outs[@]}"
  r0=$last_pid
  rank "$ns_b" 1 $addr_a "$p" "$work/${name}1.log" "$@"
  r1=$last_pid
}

# reap VAR PID: waits for background PID (in this shell: a subshell cannot) and sets VAR to its
# exit status.
reap() {
  local s=0
  wait "$2" || s=$?
  printf -v "$1" '%s' "$s"
}

# Two checkpoints hold the same tensors, bit for bit: the same multiset of tensor storages
# (the archive numbers its records in the order it meets them, which may differ).
same_weights() {
  /usr/bin/python3 - "$1" "$2" <<'PY'
import sys, zipfile
def blobs(path):
    z = zipfile.ZipFile(path)
    return sorted(z.read(n) for n in z.namelist() if "/data/" in n)
a, b = blobs(sys.argv[1]), blobs(sys.argv[2])
sys.exit(0 if a and a == b else 1)
PY
}

# 1. Training: loopback against the link, 3 steps.
steps=3
p=$(port)
rank - 0 127.0.0.1 "$p" "$work/lo0.log" "${train_args[@]}" --out "$work/lo" --max-steps $steps --rank-state "$work/lo_state"
r0=$last_pid
rank - 1 127.0.0.1 "$p" "$work/lo1.log" "${train_args[@]}" --max-steps $steps --rank-state "$work/lo_state"
r1=$last_pid
reap s0 $r0; reap s1 $r1
[[ $s0 == 0 && $s1 == 0 ]] || { cat "$work"/lo*.log; die "training over loopback failed"; }
p=$(port)
pair mh "$work/mh" "${train_args[@]}" --max-steps $steps --rank-state "$work/mh_state"
reap s0 $r0; reap s1 $r1
[[ $s0 == 0 && $s1 == 0 ]] || { cat "$work"/mh*.log; die "training across the link failed"; }
grep -q "joined (gloo via $addr_a" "$work/mh0.log" || die "rank 0 did not join through $addr_a"
for r in 0 1; do
  same_weights "$work/lo_state/rank$r.pt" "$work/mh_state/rank$r.pt" ||
    die "rank $r's weights across the link differ from loopback's"
done
same_weights "$work/mh_state/rank0.pt" "$work/mh_state/rank1.pt" || die "the two ranks' weights differ"
log "training: 2 ranks across $if_a-$if_b, $steps steps: weights bit-identical to the same ranks over loopback, and rank 0 = rank 1"

# 2. Sharded evaluation across the link against one process.
ckpt=${3:-}
if [[ -z $ckpt ]]; then
  "${train_args[@]}" --out "$work/single" >"$work/single.log" 2>&1 || { cat "$work/single.log"; die "training the checkpoint failed"; }
  ckpt=$work/single/checkpoints/latest.pt
fi
eval_args=("$apps/transhuman-eval" --config tests/configs/tiny_train.yaml "${common[@]}" --checkpoint "$ckpt")
[[ -n ${3:-} ]] && eval_args=("$apps/transhuman-eval" --config tests/configs/tiny_surface.yaml "${common[@]}" --checkpoint "$ckpt")
t0=$(date +%s.%N)
"${eval_args[@]}" --out "$work/e1" >"$work/e1.log" 2>&1 || { cat "$work/e1.log"; die "evaluation (1 process) failed"; }
t1=$(date +%s.%N)
p=$(port)
pair e2r "$work/e2" "${eval_args[@]}"
reap s0 $r0; reap s1 $r1
[[ $s0 == 0 && $s1 == 0 ]] || { cat "$work"/e2*.log; die "sharded evaluation across the link failed"; }
t2=$(date +%s.%N)
rows() { cut -d, -f1-6,8- "$1"; }
diff <(rows "$work/e1/per_image.csv") <(rows "$work/e2/per_image.csv") || die "per_image.csv rows differ"
views=$(($(wc -l <"$work/e1/per_image.csv") - 1))
log "evaluation: $views views, rows identical (timing aside) with 1 process and 2 ranks across the link;" \
  "wall $(printf '%.1f' "$(echo "$t1 - $t0" | bc)") s and $(printf '%.1f' "$(echo "$t2 - $t1" | bc)") s"
echo "| rows | 1 process | 2 ranks across the link |" >"$work/equality.md"
[[ ${TH_MULTIHOST_FAULTS:-1} == 0 ]] && exit 0

# 3. Faults. Each row: case, exit codes of the ranks, seconds from the fault to the last exit,
# what the last checkpoint holds, what --resume did.
table=("| case | exit codes (rank 0, rank 1) | seconds to exit | checkpoint left | resume |" "|---|---|---|---|---|")
failures=0
row() { table+=("| $1 | $2 | $3 | $4 | $5 |"); }
bad() {
  echo "check-multihost: FAIL: $*" >&2
  failures=$((failures + 1))
}
long=(train.epochs=40 train.iters_per_epoch=3 train.save_every_epochs=1)  # 120 steps
# The training step a run's last checkpoint holds (it loads, or says why not).
checkpoint_step() {
  /usr/bin/python3 -c "
import sys, torch
print('loads, step', int(torch.jit.load(sys.argv[1]).step))" "$1/checkpoints/latest.pt" 2>/dev/null || echo "does not load"
}
last_step() { grep -o '"step": [0-9]*' "$1/metrics.jsonl" 2>/dev/null | tail -1 | grep -o '[0-9]*$'; }
# Waits until the run in $1 has logged a step >= $2 (or 120 s).
wait_step() {
  local i
  for ((i = 0; i < 1200; ++i)); do
    [[ $(last_step "$1") -ge $2 ]] 2>/dev/null && return 0
    sleep 0.1
  done
  return 1
}
# resume_run DIR TIMEOUT STEPS: 2 ranks across the link continue DIR to STEPS steps.
resume_run() {
  local p
  p=$(port)
  rank "$ns_a" 0 $addr_a "$p" "$1/resume0.log" "${train_args[@]}" "${long[@]}" train.dist_timeout_s=$2 --out "$1" --resume --max-steps "$3"
  local a=$last_pid
  rank "$ns_b" 1 $addr_a "$p" "$1/resume1.log" "${train_args[@]}" "${long[@]}" train.dist_timeout_s=$2 --max-steps "$3"
  local b=$last_pid
  local sa sb
  reap sa $a; reap sb $b
  if [[ $sa == 0 && $sb == 0 ]]; then echo "resumed, exit 0 and 0, $(last_step "$1") steps"; else echo "FAILED ($sa, $sb)"; fi
}

# Delay and loss.
if ip netns exec "$ns_a" tc qdisc add dev "$if_a" root netem delay 50ms loss 1% 2>/dev/null; then
  p=$(port)
  pair net "$work/net" "${train_args[@]}" --max-steps $steps --rank-state "$work/net_state"
  a=$r0 b=$r1
  reap sa $a; reap sb $b
  ip netns exec "$ns_a" tc qdisc del dev "$if_a" root
  same="weights differ"
  same_weights "$work/lo_state/rank0.pt" "$work/net_state/rank0.pt" && same="same weights as loopback"
  row "50 ms delay, 1% loss" "$sa, $sb" "-" "$same" "-"
  [[ $sa == 0 && $sb == 0 && $same == "same weights as loopback" ]] || bad "delay and loss: $sa $sb $same"
else
  row "50 ms delay, 1% loss" "skipped: this kernel has no netem qdisc (CONFIG_NET_SCH_NETEM)" "-" "-" "-"
fi

# The link down for 20 s, with a timeout of 60 s (the run continues) and of 10 s (it stops).
for timeout in 60 10; do
  dir=$work/down$timeout
  p=$(port)
  pair down${timeout}_ "$dir" "${train_args[@]}" "${long[@]}" train.dist_timeout_s=$timeout
  a=$r0 b=$r1
  wait_step "$dir" 10 || bad "link down ($timeout s): the run did not reach step 10"
  ip -n "$ns_a" link set "$if_a" down
  t_fault=$(date +%s)
  sleep 20
  ip -n "$ns_a" link set "$if_a" up
  reap sa $a; reap sb $b
  secs=$(($(date +%s) - t_fault))
  msg=$(grep -h ': error:' "$work/down${timeout}_0.log" "$work/down${timeout}_1.log" | head -1 | cut -c1-160)
  if [[ $timeout == 60 ]]; then
    row "link down 20 s, dist_timeout_s 60" "$sa, $sb" "$secs (run ends)" "$(checkpoint_step "$dir")" "not needed"
    [[ $sa == 0 && $sb == 0 && $(last_step "$dir") == 120 ]] || bad "link down 20 s with timeout 60: exit $sa $sb"
  else
    left=$(checkpoint_step "$dir")
    res=$(resume_run "$dir" 60 120)
    row "link down 20 s, dist_timeout_s 10: ${msg//|/\\|}" "$sa, $sb" "$secs" "$left" "$res"
    [[ $sa == 2 && $sb == 2 ]] || bad "link down 20 s with timeout 10: exit $sa $sb (expected 2 2)"
    [[ $res == resumed* ]] || bad "link down 20 s with timeout 10: $res"
  fi
done

# One rank SIGKILLed.
dir=$work/kill
p=$(port)
pair kill "$dir" "${train_args[@]}" "${long[@]}" train.dist_timeout_s=10
a=$r0 b=$r1
wait_step "$dir" 10 || bad "kill: the run did not reach step 10"
kill -9 "$b"
t_fault=$(date +%s)
reap sa $a; reap sb $b
secs=$(($(date +%s) - t_fault))
msg=$(grep -h ': error:' "$work/kill0.log" | head -1 | cut -c1-160)
left=$(checkpoint_step "$dir")
res=$(resume_run "$dir" 60 120)
row "rank 1 SIGKILLed: ${msg//|/\\|}" "$sa, $sb (killed)" "$secs" "$left" "$res"
[[ $sa == 2 && $sb == 137 ]] || bad "SIGKILL of rank 1: exit $sa $sb (expected 2 137)"
[[ $res == resumed* ]] || bad "SIGKILL of rank 1: $res"

# A wrong MASTER_ADDR: rank 1 looks for rank 0 at an address no host has.
p=$(port)
rank "$ns_a" 0 $addr_a "$p" "$work/addr0.log" "${train_args[@]}" --max-steps 2 train.dist_timeout_s=10 --out "$work/addr"
a=$last_pid
rank "$ns_b" 1 10.231.0.3 "$p" "$work/addr1.log" "${train_args[@]}" --max-steps 2 train.dist_timeout_s=10
b=$last_pid
t0=$(date +%s)
reap sa $a; reap sb $b
secs=$(($(date +%s) - t0))
msg=$(grep -h ': error:' "$work/addr1.log" | head -1 | cut -c1-160)
row "wrong MASTER_ADDR for rank 1: ${msg//|/\\|}" "$sa, $sb" "$secs (from the start)" "none" "-"
[[ $sa == 2 && $sb == 2 ]] || bad "wrong MASTER_ADDR: exit $sa $sb (expected 2 2)"

# MASTER_PORT in use on rank 0's host.
p=$(port)
ip netns exec "$ns_a" /usr/bin/python3 -c "
import socket, time
s = socket.socket(); s.bind(('0.0.0.0', $p)); s.listen(1); time.sleep(60)" &
pids+=($!)
listener=$!
sleep 0.5
pair port "$work/port" "${train_args[@]}" --max-steps 2 train.dist_timeout_s=10
a=$r0 b=$r1
t0=$(date +%s)
reap sa $a; reap sb $b
secs=$(($(date +%s) - t0))
kill "$listener" 2>/dev/null
msg=$(grep -h ': error:' "$work/port0.log" "$work/port1.log" | cut -c1-160 | paste -sd " " -)
row "MASTER_PORT in use: ${msg//|/\\|}" "$sa, $sb" "$secs (from the start)" "none" "-"
[[ $sa == 2 && $sb == 2 ]] || bad "port in use: exit $sa $sb (expected 2 2)"

# Two runs given the same MASTER_PORT: the first runs on; the second's ranks are refused.
p=$(port)
dir=$work/first
pair first "$dir" "${train_args[@]}" --max-steps 30 "${long[@]}" train.dist_timeout_s=30 --rank-state "$work/first_state"
a=$r0 b=$r1
wait_step "$dir" 5 || bad "same port: the first run did not reach step 5"
pair second "$work/second" "${train_args[@]}" --max-steps 2 train.dist_timeout_s=10
c=$r0 d=$r1
t0=$(date +%s)
reap sc $c; reap sd $d
secs=$(($(date +%s) - t0))
reap sa $a; reap sb $b
msg=$(grep -h ': error:' "$work/second0.log" "$work/second1.log" | head -1 | cut -c1-160)
first="first run: exit $sa, $sb"
[[ $sa == 0 && $sb == 0 ]] && same_weights "$work/first_state/rank0.pt" "$work/first_state/rank1.pt" &&
  first="first run: exit 0, 0, ranks bit-identical"
row "a second run on the same MASTER_PORT: ${msg//|/\\|}" "$sc, $sd ($first)" "$secs" "-" "-"
[[ $sc == 2 && $sd == 2 && $first == *bit-identical ]] || bad "same port: second $sc $sd, $first"

printf '%s\n' "${table[@]}"
[[ -n ${TH_MULTIHOST_TABLE:-} ]] && printf '%s\n' "${table[@]}" >"$TH_MULTIHOST_TABLE"
((failures == 0)) || die "$failures fault case(s) did not behave"
log "every fault case behaved"

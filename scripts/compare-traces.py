#!/usr/bin/env python3
"""Compares two operator traces (Chrome trace JSON, as written by `transhuman-bench-model --trace`).

    scripts/compare-traces.py BEFORE.json AFTER.json [--top N]

Prints, per operator name, how often each trace calls it and the time spent in it, the operators
whose call counts differ, and the N operators with the most time. Exits 1 when the two traces do
not call the same operators the same number of times (the two builds compute differently), 0 when
they do (any difference in time is then the machine's or the code around the operators), and 2,
with one line on stderr, when a file cannot be read or is not such a trace.
"""
import argparse
import collections
import json
import sys


def fail(message):
    """One line on stderr and exit status 2 (1 means: the traces differ)."""
    print(f"compare-traces: error: {message}", file=sys.stderr)
    sys.exit(2)


def load(path):
    try:
        with open(path, encoding="utf-8") as f:
            data = json.load(f)
    except OSError as e:
        fail(f"cannot read '{path}': {e.strerror or e}")
    except (ValueError, RecursionError) as e:  # not JSON, not UTF-8, nested too deep
        fail(f"'{path}' is not JSON: {str(e).splitlines()[0] if str(e) else type(e).__name__}")
    events = data.get("traceEvents") if isinstance(data, dict) else data
    if not isinstance(events, list):
        fail(f"'{path}' is not a Chrome trace (a list of events, or an object with 'traceEvents')")
    calls, micros = collections.Counter(), collections.Counter()
    for i, e in enumerate(events):
        if not isinstance(e, dict) or e.get("ph") != "X":
            continue
        try:
            name, dur = str(e["name"]), float(e.get("dur", 0))
        except (KeyError, TypeError, ValueError):
            fail(f"'{path}': event {i} is a complete ('X') event without a name or with a duration that is not a number")
        calls[name] += 1
        micros[name] += dur
    if not calls:
        fail(f"'{path}' has no complete ('X') events")
    return calls, micros


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("before")
    ap.add_argument("after")
    ap.add_argument("--top", type=int, default=15)
    args = ap.parse_args()
    bc, bt = load(args.before)
    ac, at = load(args.after)
    differ = sorted(n for n in set(bc) | set(ac) if bc[n] != ac[n])
    print(f"operator calls: before {sum(bc.values())}, after {sum(ac.values())}; "
          f"{len(set(bc) | set(ac))} operator names")
    print(f"time in operators (inclusive, ms): before {sum(bt.values()) / 1e3:.1f}, after {sum(at.values()) / 1e3:.1f}")
    print(f"\n{'operator':48s} {'calls':>13s} {'ms before':>10s} {'ms after':>10s}")
    for name, _ in (bt + at).most_common(args.top):
        print(f"{name[:48]:48s} {bc[name]:>6d}/{ac[name]:<6d} {bt[name] / 1e3:10.1f} {at[name] / 1e3:10.1f}")
    if differ:
        print("\noperators whose call counts differ:")
        for name in differ:
            print(f"  {name}: before {bc[name]}, after {ac[name]}")
        return 1
    print("\nthe same operators, called the same number of times")
    return 0


if __name__ == "__main__":
    sys.exit(main())

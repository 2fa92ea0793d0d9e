#!/usr/bin/env python3
"""One Markdown report from a bench/run JSON file, optionally against an earlier one.

    bench/report.py RESULTS.json [EARLIER.json] > report.md

Every numeric figure of every benchmark is listed (nothing is dropped; a benchmark that failed
is listed with its error). Figures measured with a peer (PCL, OpenCV, Open3D) are marked as
such beside ours; figures that have a goal in GOALS below show it and whether it is met. With an
earlier file, each figure also shows its earlier value and the change.
"""
import json
import re
import sys

# (benchmark, regular expression on the figure's path, comparison, goal, what the goal is)
GOALS = [
    ("bench_integration", r"(^|\.)points_per_s$", ">=", 2.0e6, "issue 6: 2 M points/s distributed on two cores"),
    ("bench_integration", r"within_0\.5mm", ">=", 0.99, "issue 6: 99% of the merged surface within 0.5 mm"),
    ("bench_integration", r"completeness_1mm", ">=", 0.98, "issue 6: 98% of the reference within 1 mm"),
    ("bench_worldmodel", r"collision.*p99_ms$", "<", 1.0, "issue 10: p99 below 1 ms per collision query"),
    ("bench_worldmodel", r"(change_to_client|lcm).*(p99|max)_ms$", "<", 5.0, "issue 10: below 5 ms from change to client"),
]
PEERS = ("pcl", "opencv", "open3d", "ppf")


def flatten(value, path=""):
    if isinstance(value, dict):
        for k, v in value.items():
            yield from flatten(v, f"{path}.{k}" if path else k)
    elif isinstance(value, list):
        for i, v in enumerate(value):
            label = v.get("name") or v.get("method") or v.get("case") if isinstance(v, dict) else None
            key = f"[{label}]" if isinstance(label, str) and len(label) < 60 else f"[{i}]"
            yield from flatten(v, f"{path}{key}")
    elif isinstance(value, bool):
        yield path, value
    elif isinstance(value, (int, float)):
        yield path, value
    elif isinstance(value, str) and path.endswith("error"):
        yield path, value


def goal_of(bench, path):
    for b, pattern, op, goal, text in GOALS:
        if b == bench and re.search(pattern, path) and not any(p in path.lower() for p in PEERS):
            return op, goal, text
    return None


def fmt(v):
    if isinstance(v, bool) or isinstance(v, str):
        return str(v)
    if isinstance(v, int):
        return f"{v:,}"
    return f"{v:.4g}"


def main():
    if len(sys.argv) not in (2, 3):
        sys.exit(__doc__)
    try:
        new = json.load(open(sys.argv[1]))
        old = json.load(open(sys.argv[2])) if len(sys.argv) == 3 else None
    except (OSError, json.JSONDecodeError) as e:
        sys.exit(f"report: cannot read the results: {e}")
    print(f"# Benchmark report, {new.get('date', '?')}")
    print()
    print(f"Machine: {new.get('machine', '?')}; commit {new.get('commit', '?')}.")
    if old:
        print(f"Compared with {old.get('date', '?')}, commit {old.get('commit', '?')}.")
    print()
    unmet = []
    for bench, result in new.items():
        if not bench.startswith("bench_"):
            continue
        print(f"## {bench}")
        print()
        if isinstance(result, dict) and "error" in result and len(result) <= 3:
            print(f"**FAILED**: {result['error']}")
            print()
            unmet.append(f"{bench}: failed")
            continue
        earlier = dict(flatten(old.get(bench, {}))) if old else {}
        header = "| figure | value | goal | met |" + (" before | change |" if old else "")
        print(header)
        print("|" + "---|" * (header.count("|") - 1))
        for path, value in flatten(result):
            peer = any(p in path.lower() for p in PEERS)
            g = goal_of(bench, path)
            goal = met = ""
            if g and isinstance(value, (int, float)) and not isinstance(value, bool):
                op, target, text = g
                ok = value >= target if op == ">=" else value < target
                goal, met = f"{op} {fmt(target)} ({text})", "yes" if ok else "**no**"
                if not ok:
                    unmet.append(f"{bench} {path} = {fmt(value)} (goal {op} {fmt(target)})")
            row = f"| {'peer: ' if peer else ''}{path} | {fmt(value)} | {goal} | {met} |"
            if old:
                before = earlier.get(path)
                change = ""
                if isinstance(before, (int, float)) and isinstance(value, (int, float)) and not isinstance(value, bool) and before:
                    change = f"{100 * (value - before) / abs(before):+.1f}%"
                row += f" {fmt(before) if before is not None else ''} | {change} |"
            print(row)
        print()
    print("## Goals not met")
    print()
    print("\n".join(f"- {u}" for u in unmet) if unmet else "None.")


if __name__ == "__main__":
    main()

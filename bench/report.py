#!/usr/bin/env python3
"""One Markdown report from a bench/run JSON file, optionally against an earlier one.

    bench/report.py RESULTS.json [EARLIER.json] > report.md

First a short table of each stage's headline figures, each beside its peer measured in the same
run and its goal; then every numeric figure of every benchmark (nothing is dropped; a benchmark
that failed is listed with its error). Figures measured with a peer (PCL, OpenCV, Open3D) are marked as
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
# bench_worldmodel's "environment_recut_to_client" (seconds: a background re-cut) is not the
# change-to-client figure.
GOALS[-1] = ("bench_worldmodel", r"change_to_client\.(p99|max)_ms$", "<", 5.0, "issue 10: below 5 ms from change to client")
PEERS = ("pcl", "opencv", "open3d", "ppf")
ISSUE7 = "issue 7: at least 95% below 70% occlusion"


def get(d, *path):
    """d[path[0]][path[1]]...; a list is searched for the element whose name/method starts with the key."""
    for key in path:
        if isinstance(d, list):
            d = next((x for x in d if isinstance(x, dict) and str(x.get("name") or x.get("method") or "").startswith(key)), None) \
                if isinstance(key, str) else (d[key] if -len(d) <= key < len(d) else None)
        elif isinstance(d, dict):
            d = d.get(key)
        else:
            return None
        if d is None:
            return None
    return d


def below_70(bands):
    """Found share of the instances less than 70% occluded (symmetric criterion)."""
    return get(bands, "below 70%", "rate_symmetric_surface_10pct")


def speedup(lib):
    c, u = get(lib, "compressed", "search_seconds_per_scene"), get(lib, "full", "search_seconds_per_scene")
    return u / c if c and u else None


# (stage, figure, ours, peers [(name, value)], goal (op, value) or None); each value a function of the results.
HEADLINES = [
    ("store", "scans imported per second", lambda r: get(r, "bench_store", "scans_per_second"), [], None),
    ("meshing", "bun000: coverage within 0.5 mm", lambda r: get(r, "bench_meshing", "images", 0, "coverage_within_0_5mm"),
     [("PCL OrganizedFastMesh step 3", lambda r: get(r, "bench_meshing", "pcl_organized_fast_mesh", 1, "coverage_within_0_5mm"))], None),
    ("registration", "pairs registered with no prior (of 23)", lambda r: get(r, "bench_registration", "summary", "artisan_successes"),
     [("PCL FPFH+RANSAC+ICP", lambda r: get(r, "bench_registration", "summary", "pcl_fpfh_successes")),
      ("PCL ICP from identity", lambda r: get(r, "bench_registration", "summary", "pcl_icp_successes"))], (">=", 23)),
    ("registration", "median seconds per pair", lambda r: get(r, "bench_registration", "summary", "artisan_median_seconds"),
     [("PCL FPFH+RANSAC+ICP", lambda r: get(r, "bench_registration", "summary", "pcl_fpfh_median_seconds"))], ("<", 0.2)),
    ("merging", "0.5 mm: merged surface within 0.5 mm of the reference", lambda r: get(r, "bench_integration", "grid", 1, "accuracy_within_0_5mm"),
     [("PCL Poisson depth 9", lambda r: get(r, "bench_integration", "pcl_poisson", 1, "accuracy_within_0_5mm")),
      ("Open3D Poisson depth 9", lambda r: get(r, "bench_integration", "open3d_poisson", 1, "accuracy_within_0_5mm"))], (">=", 0.99)),
    ("merging", "0.5 mm: reference within 1 mm of the merge", lambda r: get(r, "bench_integration", "grid", 1, "completeness_within_1mm"),
     [("PCL Poisson depth 9", lambda r: get(r, "bench_integration", "pcl_poisson", 1, "completeness_within_1mm")),
      ("Open3D Poisson depth 9", lambda r: get(r, "bench_integration", "open3d_poisson", 1, "completeness_within_1mm"))], (">=", 0.98)),
    ("merging", "0.5 mm in memory: surface samples distributed per second", lambda r: get(r, "bench_integration", "grid_in_memory", 1, "distribute_samples_per_s"),
     [], (">=", 2.0e6)),
    ("merging", "0.5 mm: seconds to distribute and extract (in memory)",
     lambda r: (get(r, "bench_integration", "grid_in_memory", 1, "distribute_s") or 0) + (get(r, "bench_integration", "grid_in_memory", 1, "extract_s") or 0) or None,
     [("PCL Poisson depth 9", lambda r: get(r, "bench_integration", "pcl_poisson", 1, "seconds")),
      ("Open3D Poisson depth 9", lambda r: get(r, "bench_integration", "open3d_poisson", 1, "seconds"))], None),
    ("recognition", "found below 70% occlusion (symmetric criterion)", lambda r: below_70(get(r, "bench_recognition", "artisan_spin_images", "bands")),
     [("OpenCV PPF + ICP", lambda r: below_70(get(r, "bench_recognition", "opencv_ppf_icp", "bands")))], (">=", 0.95)),
    ("recognition", "found below 70% occlusion, held-out scenes (not tuned on)",
     lambda r: below_70(get(r, "bench_recognition", "artisan_spin_images", "held_out", "bands")),
     [("OpenCV PPF + ICP", lambda r: below_70(get(r, "bench_recognition", "opencv_ppf_icp", "held_out", "bands")))], (">=", 0.95)),
    ("recognition", "false positives per scene, held-out scenes",
     lambda r: get(r, "bench_recognition", "artisan_spin_images", "held_out", "false_positives_per_scene"),
     [("OpenCV PPF + ICP", lambda r: get(r, "bench_recognition", "opencv_ppf_icp", "held_out", "false_positives_per_scene"))], None),
    ("recognition", "false positives per scene", lambda r: get(r, "bench_recognition", "artisan_spin_images", "false_positives_per_scene"),
     [("OpenCV PPF + ICP", lambda r: get(r, "bench_recognition", "opencv_ppf_icp", "false_positives_per_scene"))], None),
    ("recognition", "seconds per scene", lambda r: get(r, "bench_recognition", "artisan_spin_images", "seconds_per_scene"),
     [("OpenCV PPF + ICP", lambda r: get(r, "bench_recognition", "opencv_ppf_icp", "seconds_per_scene"))], None),
    ("recognition", "30 models: compressed search speed-up over full search", lambda r: speedup(get(r, "bench_recognition", "library_30_models")),
     [], (">=", 3.0)),
    ("world model", "gripper collision query p99 [ms]", lambda r: get(r, "bench_worldmodel", "gripper", "collision", "p99_ms"), [], ("<", 1.0)),
    ("world model", "UR5 collision query p99 [ms]", lambda r: get(r, "bench_worldmodel", "arm", "collision", "p99_ms"), [], ("<", 1.0)),
    ("world model", "scene change to client, max [ms]", lambda r: get(r, "bench_worldmodel", "lcm_memq", "change_to_client", "max_ms"), [], ("<", 5.0)),
    ("sensors", "Vivid-sized acquisitions/s over loopback (1 client, raw)", lambda r: get(r, "bench_sensors", "memory", 0, "acquisitions_per_s"), [], None),
]


def headlines(results):
    print("## Headlines")
    print()
    print("| stage | figure | Artisan | peers (same run) | goal | met |")
    print("|---|---|---|---|---|---|")
    for stage, figure, ours, peers, goal in HEADLINES:
        try:
            value = ours(results)
        except Exception:  # a benchmark that failed or changed its output: shown as missing
            value = None
        peer_text = []
        for name, f in peers:
            try:
                v = f(results)
            except Exception:
                v = None
            peer_text.append(f"{name}: {fmt(v) if v is not None else 'not measured'}")
        goal_text = met = ""
        if goal:
            op, target = goal
            goal_text = f"{op} {fmt(target)}"
            if isinstance(value, (int, float)) and not isinstance(value, bool):
                met = "yes" if (value >= target if op == ">=" else value < target) else "**no**"
        print(f"| {stage} | {figure} | {fmt(value) if value is not None else '**missing**'} | {'; '.join(peer_text)} | {goal_text} | {met} |")
    print()


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
    headlines(new)
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

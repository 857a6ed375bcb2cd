"""Throughput of two checkouts of the project compared in one run: each tree's own
``benchmarks.throughput.paired_ratio`` (a solve's ray rate over Embree's raw rate, bracketed), the trees
alternating case by case in fresh processes, so both see the same machine load.

    git worktree add --detach /tmp/before <commit>
    python -m benchmarks.throughput_trees /tmp/before . 2     # two passes -> the ratios, printed
"""
import json, subprocess, sys
OLD, NEW, ROUNDS = sys.argv[1], sys.argv[2], int(sys.argv[3])
CASES = [("cornell", "finite", {}), ("cornell", "finite", {"method": "two_way"}),
         ("room_fig4", "finite", {}), ("room_fig4", "finite", {"method": "two_way"})]
CHILD = r'''
import json, sys
sys.path.insert(0, sys.argv[1])
from benchmarks.throughput import build_scene, paired_ratio
name, est, kw = sys.argv[2], sys.argv[3], json.loads(sys.argv[4])
m = paired_ratio(build_scene(name), est, 2, 1.5, rounds=3, max_rounds=4, **kw)
print("RESULT", json.dumps({k: float(m[k]) for k in ("raw", "solve", "ratio")}))
'''
py = sys.executable
out = {}
for r in range(ROUNDS):
    for case in CASES:
        for label, tree in (("before", OLD), ("after", NEW)):
            p = subprocess.run([py, "-c", CHILD, tree, case[0], case[1], json.dumps(case[2])], cwd=tree,
                               capture_output=True, text=True, env={"PYTHONPATH": tree, "PATH": "/usr/bin:/bin"})
            line = [l for l in p.stdout.splitlines() if l.startswith("RESULT")]
            if not line:
                print(p.stderr[-2000:]); continue
            m = json.loads(line[0][7:])
            key = f"{case[0]} {case[2].get('method', 'walk')}"
            out.setdefault(key, {}).setdefault(label, []).append(m["ratio"])
            print(r, key, label, m, flush=True)
print(json.dumps(out))

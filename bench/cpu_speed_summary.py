#!/usr/bin/env python3
"""Figures of bench/cpu_speed.sh from the files it kept in OUT: time to quality from perf
reconstruct's recon/log.jsonl (iteration events: solver seconds "elapsed", held-out "test_psnr"),
peak resident memory from /usr/bin/time -v, pass throughput from perf_bench_cpu --json, scores
from report.json. Prints one section (--pair, --sh, --passes) or writes them all (--json)."""
import argparse
import json
import os
import re
import sys


def events(path):
    with open(path) as f:
        return [json.loads(line) for line in f if line.strip()]


def iterations(path):
    return [e for e in events(path) if e.get("event") == "iteration"]


def peak_mib(path):
    try:
        with open(path) as f:
            m = re.search(r"Maximum resident set size \(kbytes\): (\d+)", f.read())
        return int(m.group(1)) / 1024.0 if m else None
    except OSError:
        return None


def stages_peak_mib(out, name):
    """The largest peak of a run's stages: NAME.time (reconstruct), NAME.export.time, NAME.eval.time."""
    peaks = [peak_mib(os.path.join(out, name + suffix)) for suffix in (".time", ".export.time", ".eval.time")]
    peaks = [p for p in peaks if p is not None]
    return max(peaks) if peaks else None


def time_to(rows, target):
    """Solver seconds at the first iteration whose held-out PSNR reaches target (None: never)."""
    for r in rows:
        if r.get("test_psnr") is not None and r["test_psnr"] >= target:
            return r["elapsed"]
    return None


def pair(out, a, b, tol):
    ra, rb = iterations(os.path.join(out, a + ".log.jsonl")), iterations(os.path.join(out, b + ".log.jsonl"))
    scored_a = [r for r in ra if "test_psnr" in r]
    scored_b = [r for r in rb if "test_psnr" in r]
    res = {"base": a, "new": b, "tol_db": tol,
           "solver_seconds": [ra[-1]["elapsed"], rb[-1]["elapsed"]],
           "peak_mib": [stages_peak_mib(out, a), stages_peak_mib(out, b)]}
    if scored_a and scored_b:
        target = scored_a[-1]["test_psnr"] - tol
        ta, tb = time_to(scored_a, target), time_to(scored_b, target)
        res.update({"final_psnr": [scored_a[-1]["test_psnr"], scored_b[-1]["test_psnr"]], "target_psnr": target,
                    "seconds_to_target": [ta, tb], "speedup": (ta / tb) if ta and tb else None})
    for side, name in ((0, a), (1, b)):
        rep = os.path.join(out, name + ".report.json")
        if os.path.exists(rep):
            m = json.load(open(rep))["mean"]
            res.setdefault("report_psnr", [None, None])[side] = m["psnr"]
            res.setdefault("report_psnr_masked", [None, None])[side] = m["psnr_masked"]
    return res


def show_pair(r):
    print(f"  {'':<22}{'base':>12}{'new':>12}{'ratio':>9}")
    s = r["solver_seconds"]
    print(f"  {'solver seconds':<22}{s[0]:>12.1f}{s[1]:>12.1f}{s[0] / s[1]:>8.2f}x")
    if "final_psnr" in r:
        f = r["final_psnr"]
        print(f"  {'final held-out dB':<22}{f[0]:>12.2f}{f[1]:>12.2f}")
        t = r["seconds_to_target"]
        fmt = lambda v: f"{v:>12.1f}" if v is not None else f"{'not reached':>12}"
        sp = f"{r['speedup']:>8.2f}x" if r["speedup"] else ""
        print(f"  {'s to %.2f dB' % r['target_psnr']:<22}{fmt(t[0])}{fmt(t[1])}{sp}")
    for key, label in (("report_psnr", "report held-out dB"), ("report_psnr_masked", "report in-mask dB")):
        if key in r:
            print(f"  {label:<22}{r[key][0]:>12.2f}{r[key][1]:>12.2f}")
    p = r["peak_mib"]
    if p[0] and p[1]:
        print(f"  {'peak MiB':<22}{p[0]:>12.0f}{p[1]:>12.0f}{p[1] / p[0]:>8.2f}x")


def sh(out):
    res = {}
    for side in ("base", "new"):
        t = []
        for d in (0, 1):
            path = os.path.join(out, f"sh{d}-{side}.log.jsonl")
            if not os.path.exists(path):
                break
            rows = iterations(path)
            # Without --eval-every the held-out PSNR is only in the "level" events.
            scored = [e for e in events(path) if e.get("test_psnr") is not None]
            t.append({"solver_seconds": rows[-1]["elapsed"], "final_psnr": scored[-1]["test_psnr"] if scored else None})
        if len(t) == 2:
            res[side] = {"degree0": t[0], "degree1": t[1],
                         "ratio": t[1]["solver_seconds"] / t[0]["solver_seconds"]}
    return res


def passes(out):
    res = {}
    for side in ("base", "new"):
        for mode in ("sparse", "dense"):
            path = os.path.join(out, f"passes-{side}-{mode}.json")
            if os.path.exists(path):
                res[f"{side}-{mode}"] = json.load(open(path))
    return res


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", required=True)
    ap.add_argument("--tol", type=float, default=0.05)
    ap.add_argument("--pair", nargs=2)
    ap.add_argument("--sh", action="store_true")
    ap.add_argument("--passes", action="store_true")
    ap.add_argument("--json")
    a = ap.parse_args()
    if a.pair:
        print(f"== {a.pair[0]} against {a.pair[1]}")
        show_pair(pair(a.out, a.pair[0], a.pair[1], a.tol))
    if a.sh:
        for side, r in sh(a.out).items():
            db = lambda d: f"{d['final_psnr']:.2f} dB" if d["final_psnr"] is not None else "no held-out PSNR"
            print(f"== sh {side}: degree 0 {r['degree0']['solver_seconds']:.1f} s ({db(r['degree0'])}), "
                  f"degree 1 {r['degree1']['solver_seconds']:.1f} s ({db(r['degree1'])}): {r['ratio']:.2f}x")
    if a.passes:
        for key, r in passes(a.out).items():
            print(f"== passes {key}: {json.dumps(r)[:400]}")
    if a.json:
        every = {"tol_db": a.tol, "sh": sh(a.out), "passes": passes(a.out)}
        for name in ("lego200", "lego50", "bonsai"):
            if os.path.exists(os.path.join(a.out, f"{name}-base.log.jsonl")) and \
                    os.path.exists(os.path.join(a.out, f"{name}-new.log.jsonl")):
                every[name] = pair(a.out, f"{name}-base", f"{name}-new", a.tol)
        if os.path.exists(os.path.join(a.out, "lego200-newsh.log.jsonl")):  # scenario lego200sh
            every["lego200_sh"] = pair(a.out, "lego200-base", "lego200-newsh", a.tol)
        tmp = a.json + ".tmp"
        with open(tmp, "w") as f:
            json.dump(every, f, indent=2)
        os.replace(tmp, a.json)
        print(f"wrote {a.json}")


if __name__ == "__main__":
    sys.exit(main())

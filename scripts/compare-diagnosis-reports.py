#!/usr/bin/env python3
"""Compares the diagnosis reports of two runs of the integration tests, before and after a change
that moves the numbers (issue 37: the same verdicts, each parameter within one standard error of
before, the discrepancies within theirs).

    cargo test --all-features --test integration -- --show-output > before.log
    (the change, then the same again)                               > after.log
    python3 scripts/compare-diagnosis-reports.py before.log after.log

It reads the lines `tests/common/independent.rs::report` prints, test by test: the verdicts, and
per round the discrepancy ± its SE, the verdict and its parameters ± their SEs. It prints every
difference in verdicts or rounds, and the changes in SEs of before, largest first. Exit 1 when a
verdict or the number of rounds differs, or a report is missing on one side.
"""
import json
import re
import sys

ROUND = re.compile(r"^\s+(\S+) ± (\S+) px -> (\S+) (\{.*?\}) ± (\{.*?\}) -> (.*)$")


def numbers(text):
    """A Rust `{:?}` of a map of names to floats, as a dict (NaN and infinities as None)."""
    return json.loads(re.sub(r"\bNaN\b|-?\binf\b", "null", text))


def parse(path):
    """{test: [report]}, a report {name, verdicts, rounds: [{d, se, verdict, params, stderr}]}."""
    tests, current = {}, None
    for line in open(path, errors="replace"):
        line = line.rstrip("\n")
        m = re.match(r"^---- (\S+) stdout ----", line)
        if m:
            current = tests.setdefault(m.group(1), [])
            continue
        if current is None:
            continue
        m = re.match(r"^== (.*): verdicts (.*)$", line)
        if m:
            current.append({"name": m.group(1), "verdicts": m.group(2), "rounds": []})
            continue
        m = ROUND.match(line)
        if m and current:
            current[-1]["rounds"].append({
                "d": float(m.group(1)), "se": float(m.group(2)), "verdict": m.group(3),
                "params": numbers(m.group(4)), "stderr": numbers(m.group(5)),
            })
    return tests


def in_ses(change, se):
    """`change` in standard errors; infinite when it moved without a stated SE, 0 when it did not move."""
    if change == 0:
        return 0.0
    return change / se if se else float("inf")


def main(before_path, after_path):
    before, after = parse(before_path), parse(after_path)
    changes, differences, reports, params = [], 0, 0, 0
    for test in sorted(set(before) | set(after)):
        b, a = before.get(test, []), after.get(test, [])
        if len(b) != len(a):
            print(f"{test}: {len(b)} reports before, {len(a)} after")
            differences += 1
        for x, y in zip(b, a):
            reports += 1
            tag = f"{test} [{x['name']}]"
            if x["verdicts"] != y["verdicts"]:
                print(f"verdicts differ, {tag}: {x['verdicts']} -> {y['verdicts']}")
                differences += 1
            if len(x["rounds"]) != len(y["rounds"]):
                print(f"rounds differ, {tag}: {len(x['rounds'])} -> {len(y['rounds'])}")
                differences += 1
            for k, (p, q) in enumerate(zip(x["rounds"], y["rounds"])):
                if p["verdict"] != q["verdict"]:
                    print(f"round {k} verdict differs, {tag}: {p['verdict']} -> {q['verdict']}")
                    differences += 1
                    continue
                z = in_ses(q["d"] - p["d"], p["se"])
                changes.append((abs(z), f"{tag} round {k} D {p['d']:.6g} -> {q['d']:.6g} (SE {p['se']:.3g}): {z:+.2f} SE"))
                for name, v in p["params"].items():
                    w, se = q["params"].get(name), p["stderr"].get(name)
                    if v is None or w is None:
                        continue
                    params += 1
                    z = in_ses(w - v, se)
                    shown = "none stated" if se is None else f"{se:.3g}"
                    changes.append((abs(z), f"{tag} round {k} {name} {v:.6g} -> {w:.6g} (SE {shown}): {z:+.2f} SE"))
    changes.sort(key=lambda c: -c[0])
    moved = [c for c in changes if c[0] > 0]
    unstated = sum(c[0] == float("inf") for c in moved)
    beyond = sum(1 < c[0] < float("inf") for c in moved)
    print(f"{reports} reports, {params} parameters; {differences} differences in verdicts or rounds; "
          f"{len(moved)} numbers moved, {beyond} by more than one SE, {unstated} without a stated SE")
    for z, text in moved:
        print(f"  {text}")
    return 1 if differences else 0


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    sys.exit(main(sys.argv[1], sys.argv[2]))

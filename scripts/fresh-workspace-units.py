#!/usr/bin/env python3
"""Which of the workspace's units a Cargo build found fresh, from its JSON messages.

scripts/test-all.sh builds every target with clippy-driver as the workspace's compiler, so each
member it compiles is linted as it compiles. Cargo does not count that wrapper in a unit's
fingerprint: a member compiled before the run (by a plain `cargo test` with the same settings)
is fresh and was not linted by this build. This lists those units and exits 1 when there is one
(the script then runs `cargo clippy` as well), 0 when the build compiled every member.

Usage: fresh-workspace-units.py MESSAGES.json (the build's `--message-format=json-…` stdout)
"""

import json
import os
import sys


def main() -> int:
    if len(sys.argv) != 2:
        print(__doc__.strip().splitlines()[-1], file=sys.stderr)
        return 2
    # A member's package id is its path: "path+file:///…/drivers/hw#ffdic-hw@0.1.0".
    workspace = "path+file://" + os.path.realpath(os.getcwd())
    fresh = []
    compiled = 0
    with open(sys.argv[1], encoding="utf-8") as messages:
        for line in messages:
            line = line.strip()
            if not line.startswith("{"):
                continue
            message = json.loads(line)
            if message.get("reason") != "compiler-artifact":
                continue
            package_id = message.get("package_id", "")
            if not (package_id == workspace or package_id.startswith(workspace + "/")
                    or package_id.startswith(workspace + "#")):
                continue
            if message.get("fresh"):
                target = message.get("target", {})
                fresh.append(f"{package_id.rsplit('#', 1)[-1]} {target.get('kind')} {target.get('name')}")
            else:
                compiled += 1
    print(f"the workspace's units: {compiled} compiled by this build, {len(fresh)} fresh")
    for unit in fresh:
        print(f"  fresh: {unit}")
    return 1 if fresh else 0


if __name__ == "__main__":
    sys.exit(main())

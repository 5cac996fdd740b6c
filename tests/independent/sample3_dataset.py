#!/usr/bin/env python3
"""Build an ffdic dataset (format ffdic-dataset/1) from the public DIC Challenge 1.0 Sample 3 images.

    python sample3_dataset.py OUT_DIR [--scale 10] [--source DIR] [--overwrite]

The images are looked up in <repo>/../shared/data/dic-challenge-1/sample3/ (the repository root is
two levels above this script), so it works in a fresh clone placed beside `shared`.

Sample 3 moves the image content by (0.1k, 0.1k) px in shift_k.tif (x right, y down). Runs:
shift_01..shift_05 are the deformed frames of reference.tif, shift_00 (no move, independent noise)
is the static repeat of the reference; the commanded stage move is dx_mm = dy_mm = 0.1k / scale.
The TIFFs are copied byte for byte (8-bit stays 8-bit). No pattern sizes: label "sample3" only.
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parents[1]
DEFAULT_SOURCE = REPO.parent / "shared" / "data" / "dic-challenge-1" / "sample3"
FILES = ["reference.tif"] + [f"shift_{k:02d}.tif" for k in range(6)]


def build(out_dir, scale: float = 10.0, source=DEFAULT_SOURCE, overwrite: bool = False) -> dict:
    out_dir, source = Path(out_dir), Path(source)
    if not (scale > 0):
        raise ValueError("scale must be positive")
    missing = [f for f in FILES if not (source / f).is_file()]
    if missing:
        raise FileNotFoundError(f"{source}: missing {', '.join(missing)}")
    if out_dir.exists() and any(out_dir.iterdir()) and not overwrite:
        raise FileExistsError(f"{out_dir} is not empty (pass --overwrite)")
    out_dir.mkdir(parents=True, exist_ok=True)
    for f in FILES:
        dst = out_dir / f
        if dst.exists():
            dst.unlink()
        shutil.copyfile(source / f, dst)
    runs = []
    truth_runs = []
    for k in range(1, 6):
        shift_px = round(0.1 * k, 10)
        runs.append({
            "id": f"sample3-s{k:02d}",
            "pattern": {"label": "sample3"},
            "reference": "reference.tif",
            "deformed": f"shift_{k:02d}.tif",
            "stage": {"dx_mm": shift_px / scale, "dy_mm": shift_px / scale},
            "repeat": ["shift_00.tif"],
        })
        truth_runs.append({"id": runs[-1]["id"], "actual_move_px": [shift_px, shift_px],
                           "actual_move_mm": [shift_px / scale, shift_px / scale]})
    manifest = {
        "format": "ffdic-dataset/1",
        "name": "dic-challenge-sample3",
        "scale_px_per_mm": scale,
        "camera": {"width": 512, "height": 512, "bit_depth": 8},
        "generator": {"name": "ffdic tests/independent/sample3_dataset.py",
                      "spec": {"source": "DIC Challenge 1.0 Sample 3 (Society for Experimental Mechanics)",
                               "scale_px_per_mm": scale,
                               "note": "content moved by (0.1k, 0.1k) px in shift_k; shift_00 is a second "
                                       "noisy copy of the reference (noise about 1.1 grey levels)"}},
        "runs": runs,
    }
    (out_dir / "dataset.json").write_text(json.dumps(manifest, indent=2) + "\n")
    truth = {"format": "ffdic-independent-truth/1", "name": manifest["name"], "scale_px_per_mm": scale,
             "runs": truth_runs,
             "conventions": {"coordinates": "x = column (right), y = row (down)",
                             "displacement": "content of shift_k = reference moved by +(0.1k, 0.1k) px"}}
    (out_dir / "truth.json").write_text(json.dumps(truth, indent=2) + "\n")
    return manifest


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out_dir")
    ap.add_argument("--scale", type=float, default=10.0, help="px per mm used to express the moves in mm")
    ap.add_argument("--source", default=str(DEFAULT_SOURCE), help="folder with reference.tif and shift_XX.tif")
    ap.add_argument("--overwrite", action="store_true")
    a = ap.parse_args(argv)
    try:
        build(a.out_dir, a.scale, a.source, a.overwrite)
    except (FileNotFoundError, FileExistsError, ValueError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())

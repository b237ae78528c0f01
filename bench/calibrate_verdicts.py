"""The calibration's verdicts on 54 frames, to check that a change of speed changed nothing.

The frames: 40 synthetic lenslet scenes (pitches 8-90 px; Keplerian, Galilean, multi-focus, and
traps periodic at 2 x and sqrt(3) x the pitch), 7 white images of 2048 x 2048 (pitch 6.3-95 px)
and the real frames of REALDATA/raytrix (compressed/ too, one entry each). A synthetic frame is
*right* (lattice kind, pitch within 0.1 %, angle within 0.02 deg, every lens within 0.1 pitch of
its true centre), *wrong* or *refused*; a real frame is reported as found (kind, pitch, angle)
or refused. With ``--baseline COMMIT`` the same frames go through that commit's code too (in a
fresh process) and every frame whose verdict, lattice or pitch (beyond 1e-4 relative) differs is
listed. Each side draws the synthetic frames with its own generator (``plenocli.synth``):
compare commits that draw them alike.

    PYTHONPATH=. .venv/bin/python bench/calibrate_verdicts.py [REALDATA] [--baseline COMMIT]
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

from bench.timing import ROOT, export_package, run_python

RUNNER = r"""
import json, sys
from pathlib import Path
import cv2
import numpy as np
from plenocli import calibration
from plenocli.errors import CalibrationError
from plenocli.model.lensgrid import LATTICES, LensGrid
from plenocli.synth.lenslet import lenslet_scene
from plenocli.synth.whiteimage import white_image


def found(image, true=None):
    try:
        grid, report = calibration.calibrate(image)
    except CalibrationError as err:
        return {"verdict": "refused", "why": str(err)[:120]}
    out = {"verdict": "found", "lattice": grid.lattice, "pitch": grid.pitch_px,
           "angle_deg": float(np.degrees(grid.angle_rad))}
    if true is not None:
        step = LATTICES[true.lattice]
        turn = (grid.angle_rad - true.angle_rad + step / 2) % step - step / 2
        _, centres = true.lens_centres()
        i, j = grid.nearest_index(centres[:, 0], centres[:, 1])
        miss = np.linalg.norm(grid.lattice_xy(i, j) - centres, axis=1).max()
        right = (grid.lattice == true.lattice and abs(grid.pitch_px / true.pitch_px - 1) <= 1e-3
                 and abs(np.degrees(turn)) <= 0.02 and miss <= 0.1 * true.pitch_px)
        out["verdict"] = "right" if right else "wrong"
    return out


results = {}
for pitch in [8.0, 12.0, 18.0, 23.2, 35.0, 45.5, 70.0, 90.0]:
    for kind in ["keplerian", "galilean", "multi", "double", "sqrt3"]:
        seed = int(pitch * 10) + len(kind)
        size = int(min(2048, max(512, 24 * pitch)))
        angle = float(np.random.default_rng(seed).uniform(0, np.pi))
        image, truth = lenslet_scene(
            (size, size), pitch_px=pitch, angle_rad=angle, galilean=kind == "galilean",
            multi_focus=kind == "multi", trap=kind if kind in ("double", "sqrt3") else None,
            seed=seed)
        true = LensGrid(pitch, angle, tuple(truth["offset_xy"]), "hex", image_shape=(size, size))
        results[f"{kind} {pitch}"] = found(image, true)
for k, (pitch, angle) in enumerate([(6.3, 0.3), (11.1, 1.0), (20.2, 0.05), (33.3, 0.7),
                                    (47.0, 0.2), (64.0, 1.3), (95.0, 0.4)]):
    white, _ = white_image((2048, 2048), pitch_px=pitch, angle_rad=angle,
                           offset_xy=(1000.3, 1010.6), seed=k)
    results[f"white {pitch}"] = found(white.astype(np.float32) - 64)
for path in sorted((Path(sys.argv[1]) / "raytrix").glob("*/*.png")):
    image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED).astype(np.float32)
    name = path.parent.name if path.parent.name != "compressed" else f"compressed/{path.stem}"
    results[name] = found(image.sum(-1) if image.ndim == 3 else image)
print(json.dumps(results))
"""


def _verdicts(root: Path, realdata: str) -> dict:
    return json.loads(run_python(RUNNER, realdata, root=root).splitlines()[-1])


def _differs(a: dict, b: dict) -> bool:
    if a["verdict"] != b["verdict"] or a.get("lattice") != b.get("lattice"):
        return True
    return "pitch" in a and abs(a["pitch"] / b["pitch"] - 1) > 1e-4


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("realdata", nargs="?", default="../shared/realdata")
    parser.add_argument("--baseline", help="a git commit whose verdicts to compare with")
    args = parser.parse_args()
    realdata = str(Path(args.realdata).resolve())
    start = time.perf_counter()
    ours = _verdicts(ROOT, realdata)
    counts = {v: sum(r["verdict"] == v for r in ours.values())
              for v in ("right", "wrong", "refused", "found")}
    print(f"this checkout: {len(ours)} frames in {time.perf_counter() - start:.0f} s: "
          + ", ".join(f"{n} {v}" for v, n in counts.items()))
    for name, r in ours.items():
        if r["verdict"] in ("wrong", "found"):
            print(f"  {name}: {r['verdict']} {r['lattice']} {r['pitch']:.4f} px "
                  f"{r['angle_deg']:.3f} deg")
    if args.baseline:
        with tempfile.TemporaryDirectory() as tmp:
            theirs = _verdicts(export_package(args.baseline, Path(tmp)), realdata)
        changed = [n for n in ours if n not in theirs or _differs(ours[n], theirs[n])]
        print(f"against {args.baseline}: {len(changed)} of {len(ours)} frames differ")
        for name in changed:
            print(f"  {name}: {theirs.get(name)} -> {ours[name]}")


if __name__ == "__main__":
    main()

"""Benchmark: plenocli.unmix vs a plain per-pixel ``np.linalg.solve`` in the same run.

Cases (the issue's targets): 2 views of 6880 x 4544 (a Canon DPRAW, RGGB, three colour planes,
M on 64-px tiles) <= 0.5 s, and 4 views of 1500 x 1500 (quad-pixel SAIs, one plane) <= 0.3 s.
The views are a known clean pair/quad mixed with a known smooth field, so the error of the
result is printed too.

Baseline: the textbook vectorised solution, per-pixel M interpolated with numpy (the same
bilinear field) and ``np.linalg.solve`` on the (pixels, V, V) stack. On the 2-view case it runs
on a band of rows (memory: M alone would be 1 GB) and its time is scaled to the full frame.
Times are the best of ``--repeat`` runs after one warm-up call (numba compiles once per
installation: the kernels are cached on disk).

    PYTHONPATH=. python bench/bench_unmix.py [--repeat 3] [--limits]

``--limits`` instead measures where the mixing model stops holding (docs/crosstalk.md): the
simulated dual-pixel chart (green, 576 x 384 views, r = 50 %) with the leaked light's image
shifted by delta px (defocus: the leak comes from another part of the pupil than the part's
centroid) or blurred by a Gaussian of sigma px (diffraction), unmixed with the exact M; printed
is the RMS error of the views relative to the signal, before and after unmix.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from bench.timing import best_time
from plenocli.unmix import MixingField, unmix

RGGB = np.array([[0, 1], [1, 2]])



def make_case(n_views: int, rows: int, cols: int, colours: tuple[str, ...], seed: int):
    """A smooth field on 64-px tile centres, clean views and the mixed views (float32)."""
    rng = np.random.default_rng(seed)
    node_rows = np.arange(-(-rows // 64)) * 64 + 31.5
    node_cols = np.arange(-(-cols // 64)) * 64 + 31.5
    r = 0.5 if n_views == 2 else 0.13
    u = node_cols[None, :] / cols - 0.5
    v = node_rows[:, None] / rows - 0.5
    nodes = np.zeros((len(colours), n_views, n_views, len(node_rows), len(node_cols)))
    for c in range(len(colours)):
        for k in range(n_views):
            for j in range(n_views):
                a, b = rng.uniform(-0.2, 0.2, 2)
                nodes[c, k, j] = 1.0 if k == j else r * (1 + a * u + b * v)
    field = MixingField(nodes, node_rows, node_cols, (rows, cols),
                        tuple(f"V{k}" for k in range(n_views)), colours)
    clean = rng.uniform(0.1, 1.0, (n_views, rows, cols)).astype(np.float32)
    pattern = RGGB if len(colours) == 3 else np.zeros((2, 2), np.int64)
    mixed = np.empty_like(clean)
    for y0 in range(0, rows, 512):  # per-pixel M in bands to bound memory
        m = _pixel_matrices(field, pattern, y0, min(rows, y0 + 512))
        mixed[:, y0:y0 + m.shape[0]] = np.moveaxis(
            (m @ np.moveaxis(clean[:, y0:y0 + m.shape[0]], 0, -1)[..., None])[..., 0], -1, 0)
    return field, pattern, clean, mixed


def _weights(nodes: np.ndarray, pos: np.ndarray):
    lo = np.clip(np.searchsorted(nodes, pos, side="right") - 1, 0, len(nodes) - 2)
    return lo, (pos - nodes[lo]) / (nodes[lo + 1] - nodes[lo])


def _pixel_matrices(field: MixingField, pattern, y0: int, y1: int) -> np.ndarray:
    """Per-pixel M (rows, cols, V, V) of rows y0..y1, bilinear with numpy (the baseline's
    first step)."""
    nodes = np.asarray(field.nodes, np.float64)
    ry, wy = _weights(np.asarray(field.node_rows), np.arange(y0, y1, dtype=np.float64))
    cx, wx = _weights(np.asarray(field.node_cols), np.arange(field.shape[1], dtype=np.float64))
    rows = nodes[..., ry, :] * (1 - wy)[:, None] + nodes[..., ry + 1, :] * wy[:, None]
    stack = rows[..., cx] * (1 - wx) + rows[..., cx + 1] * wx
    idx = np.tile(np.asarray(pattern), (-(-(y1 - y0) // 2) + 1, -(-field.shape[1] // 2)))[
        (y0 % 2):(y0 % 2) + (y1 - y0), :field.shape[1]]
    per_pixel = np.take_along_axis(stack, idx[None, None, None], axis=0)[0]
    return np.moveaxis(per_pixel, (0, 1), (-2, -1))


def baseline(field, pattern, mixed, y0: int, y1: int) -> tuple[np.ndarray, float]:
    """Clean views of rows y0..y1 and the time of the np.linalg.solve call alone."""
    m = _pixel_matrices(field, pattern, y0, y1)
    obs = np.moveaxis(mixed[:, y0:y1], 0, -1).astype(np.float64)[..., None]
    start = time.perf_counter()
    solved = np.linalg.solve(m, obs)
    return np.moveaxis(solved[..., 0], -1, 0), time.perf_counter() - start


def run_case(label: str, n_views: int, rows: int, cols: int, colours, target: float,
             band: int, repeat: int) -> None:
    field, pattern, clean, mixed = make_case(n_views, rows, cols, colours, seed=n_views)
    colour_pattern = pattern if len(colours) > 1 else None
    unmix(mixed[:, :64, :64].copy(), MixingField(field.nodes, field.node_rows,
                                                 field.node_cols, (64, 64), field.views,
                                                 field.colours),
          colour_pattern=colour_pattern)  # warm-up (loads the compiled kernels)
    t_ours, res = best_time(lambda: unmix(mixed, field, colour_pattern=colour_pattern), repeat)
    t_gain, _ = best_time(lambda: unmix(mixed, field, colour_pattern=colour_pattern,
                                        noise_gain=True), repeat)
    t_reg, _ = best_time(lambda: unmix(mixed, field, colour_pattern=colour_pattern,
                                       regularise=0.05), repeat)
    band = min(band, rows)
    t_band, (ref, t_solve) = best_time(lambda: baseline(field, pattern, mixed, 0, band), 1)
    t_base, t_solve = t_band * rows / band, t_solve * rows / band
    err = float(np.abs(res.views - clean).max())
    ref_err = float(np.abs(ref - clean[:, :band]).max())
    print(f"{label}: plenocli {t_ours:.3f} s (target <= {target} s: "
          f"{'ok' if t_ours <= target else 'MISSED'}), with noise gain {t_gain:.3f} s, "
          f"Tikhonov {t_reg:.3f} s; baseline np.linalg.solve {t_base:.2f} s"
          f"{' (scaled from ' + str(band) + ' rows)' if band < rows else ''}: "
          f"{t_base / t_ours:.1f}x faster (solve call alone {t_solve:.2f} s: "
          f"{t_solve / t_ours:.1f}x); max error {err:.2e} (baseline {ref_err:.2e})")


def model_limits() -> None:

    from plenocli.synth import prismcam
    from plenocli.synth.rig import make_scene

    a, b, _ = prismcam.render_dualpixel(pixels=576, prism=True)
    for name, clean in (("test chart (sharp edges)", np.stack([a[..., 1], b[..., 1]])),
                        ("textured scene (blur 1.5 px)", np.stack(
                            [make_scene((384, 576), seed=s) for s in (1, 2)]))):
        print(f"-- {name}")
        _limits_on(clean.astype(np.float64))


def _limits_on(clean: np.ndarray) -> None:
    from scipy import ndimage

    from plenocli.synth import mixing as sim_mixing

    field = sim_mixing.mixing_field(clean.shape[1:], n_views=2, r=0.5, seed=3)
    truth = MixingField(field[..., 2::4, 2::4], np.arange(2, clean.shape[1], 4.0),
                        np.arange(2, clean.shape[2], 4.0), clean.shape[1:], ("A", "B"), ("L",))
    signal = np.sqrt(np.mean(clean ** 2))

    def report(label, leaked):
        observed = clean + np.stack([field[0, 0, 1] * leaked[1], field[0, 1, 0] * leaked[0]])
        res = unmix(observed, truth).views
        inner = (slice(None), slice(8, -8), slice(8, -8))
        before = np.sqrt(np.mean((observed - clean)[inner] ** 2)) / signal
        after = np.sqrt(np.mean((res - clean)[inner] ** 2)) / signal
        print(f"{label:32s} error before {100 * before:6.2f} %, after unmix {100 * after:6.3f} %"
              f" ({before / max(after, 1e-12):.0f}x less)")

    report("in focus (the model)", clean)
    for delta in (0.25, 0.5, 1.0, 2.0):
        report(f"defocus: leak shifted {delta:g} px", np.stack(
            [ndimage.shift(clean[0], (0, -delta), order=3, mode="nearest"),
             ndimage.shift(clean[1], (0, delta), order=3, mode="nearest")]))
    for sigma in (0.5, 1.0, 2.0):
        report(f"diffraction: leak blurred {sigma:g} px", np.stack(
            [ndimage.gaussian_filter(v, sigma) for v in clean]))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--limits", action="store_true", help="measure the model's limits")
    args = parser.parse_args()
    if args.limits:
        model_limits()
        return
    run_case("2 views 6880 x 4544 RGGB", 2, 4544, 6880, ("R", "G", "B"), 0.5, 256, args.repeat)
    run_case("4 views 1500 x 1500", 4, 1500, 1500, ("L",), 0.3, 1500, args.repeat)


if __name__ == "__main__":
    main()

"""Dense stereo on the Middlebury 2014 motorcycle pair: mrfpe's loopy BP vs OpenCV.

The pair ships with scikit-image (``skimage.data.stereo_motorcycle()``, no
download): 741 x 500, already Middlebury's quarter size, with ground-truth
disparities 7.2-59.9 px. "Quarter" and "half" resolution below are that pair
downscaled by a further 4 and 2 (``cv2.INTER_AREA``):

========  =========  ==================  =================
level     size       GT disparity range  max_disparity
========  =========  ==================  =================
quarter   185 x 125  1.8 - 15.0 px       20 (covers all)
half      370 x 250  3.6 - 30.0 px       40 (covers all)
========  =========  ==================  =================

(At the pair's own size max_disparity=20 would cover only 29 % of the pixels.)
The ground truth is downscaled as the median of the finite values of each
s x s block divided by s; a block with fewer than half finite values has no
ground truth. Error: bad-1px = fraction of pixels with ground truth whose
|estimate - truth| > 1 px; pixels a method leaves unmatched count as bad.

Methods: ``mrfpe.brdf.stereo.disparity`` with the default settings and 10
iterations, accelerated (6.38-6.41) and parallel (6.33) schedules, the pixel
disparity being the argmax of the product of its four corner beliefs;
OpenCV StereoSGBM (block 5, P1 = 8*3*5^2, P2 = 32*3*5^2, uniqueness 10,
speckle 100/2, disp12MaxDiff 1) and StereoBM (block 9, grey). OpenCV needs
``numDisparities`` to be a multiple of 16 and leaves the leftmost
``numDisparities`` columns unmatched, so it gets the smallest multiple of 16
above the ground truth's largest disparity (16 at quarter, 32 at half
resolution) -- the choice most favourable to it; with a multiple of 16 that
covers ``max_disparity`` (32, 48) its unmatched band widens (SGBM: 0.258 and
0.242). The table also gives SGBM's error over the pixels it does match.

``--sensitivity`` measures why stereo geometry limits BRDF estimation
(docs/stereo.md, "Accuracy needed for BRDF estimation"):

(a) how far the ``pl`` maximiser (20^3 grid, unit cube) moves from the true
    Ward parameters when the node disparities carry Gaussian noise of s.d.
    sigma px (labels: 21 per node, 0.05 px apart, about the noisy disparity;
    smooth 16 x 16 surface, rectified pair with baseline/depth 0.5 and 1);
(b) the sub-pixel accuracy of window NCC (winner takes all over 0.01-px
    labels, no smoothing) on noise-free renderings of a textured plane turned
    by 0-30 degrees from fronto-parallel.

Usage::

    python -m benchmarks.bench_stereo                 # table + energy plot + RESULTS.md
    python -m benchmarks.bench_stereo --no-append --levels quarter
    python -m benchmarks.bench_stereo --sensitivity --no-append
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from benchmarks._common import HERE, append_results, command_line, machine

LEVELS = {"quarter": (4, 20), "half": (2, 40)}


def load(scale: int):
    """Downscaled (left, right, ground truth) of the motorcycle pair."""
    import cv2
    from skimage import data

    left, right, gt = data.stereo_motorcycle()
    H, W = (gt.shape[0] // scale) * scale, (gt.shape[1] // scale) * scale
    size = (W // scale, H // scale)
    small = [cv2.resize(im[:H, :W], size, interpolation=cv2.INTER_AREA) for im in (left, right)]
    blocks = gt[:H, :W].reshape(H // scale, scale, W // scale, scale).transpose(0, 2, 1, 3)
    blocks = blocks.reshape(H // scale, W // scale, scale * scale)
    finite = np.isfinite(blocks)
    enough = finite.sum(axis=2) * 2 >= scale * scale
    med = np.full(enough.shape, np.nan)
    vals = np.where(finite, blocks, np.nan)[enough]
    med[enough] = np.nanmedian(vals, axis=1) / scale
    return small[0], small[1], med


def bad1(est: np.ndarray, gt: np.ndarray, valid: np.ndarray | None = None) -> float:
    """bad-1px over pixels with ground truth; unmatched (``valid`` False) pixels count as bad."""
    has = np.isfinite(gt)
    wrong = np.abs(est - gt) > 1.0
    if valid is not None:
        wrong |= ~valid
    return float(np.mean(wrong[has]))


def run_mrfpe(left, right, dmax, schedule):
    from mrfpe.brdf.stereo import disparity

    t0 = time.perf_counter()
    res = disparity(left, right, dmax, schedule=schedule, iterations=10)
    return res.pixel_map(), None, time.perf_counter() - t0, res.energy


def run_sgbm(left, right, nd):
    import cv2

    bs = 5
    sgbm = cv2.StereoSGBM_create(minDisparity=0, numDisparities=nd, blockSize=bs,
                                 P1=8 * 3 * bs * bs, P2=32 * 3 * bs * bs, disp12MaxDiff=1,
                                 uniquenessRatio=10, speckleWindowSize=100, speckleRange=2)
    t0 = time.perf_counter()
    d = sgbm.compute(left, right).astype(np.float64) / 16.0
    return d, d >= 0, time.perf_counter() - t0, None


def run_bm(left, right, nd):
    import cv2

    bm = cv2.StereoBM_create(numDisparities=nd, blockSize=9)
    gl, gr = (cv2.cvtColor(im, cv2.COLOR_RGB2GRAY) for im in (left, right))
    t0 = time.perf_counter()
    d = bm.compute(gl, gr).astype(np.float64) / 16.0
    return d, d >= 0, time.perf_counter() - t0, None


def _rig(H, W, f, baseline, doffs=0.0):
    K = np.array([[f, 0, W / 2], [0, f, H / 2], [0, 0, 1.0]])
    K2 = K.copy()
    K2[0, 2] += doffs
    P1 = K @ np.hstack([np.eye(3), np.zeros((3, 1))])
    P2 = K2 @ np.hstack([np.eye(3), [[-baseline], [0.0], [0.0]]])
    return P1, P2


def _rays(P, xy):
    M = P[:, :3]
    C = -np.linalg.solve(M, P[:, 3])
    return C, np.concatenate([xy, np.ones((*xy.shape[:-1], 1))], -1) @ np.linalg.inv(M).T


def pl_vs_disparity_noise(ratio: float, sigmas=(0.0, 0.01, 0.02, 0.05), theta=(0.5, 0.3, 0.15)):
    """Distance of the ``pl`` grid maximiser from the truth against disparity noise."""
    import mrfpe
    from mrfpe.brdf.geometry import DirectionalLight, ProjectiveCamera, triangulate_linear
    from mrfpe.brdf.scene import Scene
    from mrfpe.brdf.synthetic import render

    H = W = 16
    f = 2.5 * W
    Z0, b = f, ratio * f
    P1, P2 = _rig(H, W, f, b, doffs=b - 4.0)
    r, c = np.meshgrid(np.arange(H + 1.0), np.arange(W + 1.0), indexing="ij")
    X, Y = (c - W / 2) / f, (r - H / 2) / f
    # smooth surface: depth as a function of the image position of the node
    Z = Z0 * (1 + 0.004 * (c - W / 2) - 0.006 * (r - H / 2) + 0.2 * np.exp(
        -((c - 9) ** 2 + (r - 7) ** 2) / 30.0))
    nodes = np.stack([X * Z, Y * Z, Z], -1)
    theta = np.asarray(theta)
    light = DirectionalLight([0.2, -0.3, -1.0])
    cam = ProjectiveCamera(P1, image_shape=(H, W))
    image = render("ward", theta, nodes, cam, light)
    d_true = f * b / Z - (b - 4.0)
    grid = np.stack(np.meshgrid(*[np.linspace(0.025, 0.975, 20)] * 3, indexing="ij"), -1)
    grid = grid.reshape(-1, 3)
    out = []
    for sigma in sigmas:
        dn = d_true + np.random.default_rng(5).normal(0.0, sigma, d_true.shape)
        dd = dn[..., None] + (np.arange(21) - 10) * 0.05
        x1 = np.broadcast_to(np.stack([c, r], -1)[:, :, None, :], (*dd.shape, 2))
        x2 = np.stack(np.broadcast_arrays(c[..., None] - dd, r[..., None] + 0 * dd), -1)
        pts = triangulate_linear(P1, P2, x1, x2)
        scene = Scene(image=image, camera=cam, light=light,
                      label_ranges=np.linalg.norm(pts, axis=-1),
                      observed_labels=np.full((H + 1, W + 1), 10), brdf="ward", true_theta=theta)
        target = mrfpe.targets.get("pl", scene)
        best = grid[np.argmax(target.log_prob(grid))]
        out.append(float(np.linalg.norm(best - target.to_unit(theta[None])[0])))
    return out


def _shoot(P, xy, plane):
    """Points where the rays of camera P through ``xy`` meet ``plane`` (origin, normal, ...)."""
    C, d = _rays(P, xy)
    t = ((plane[0] - C) @ plane[1]) / (d @ plane[1])
    return C + t[..., None] * d


def _plane_image(P, xy, plane, texture):
    """Pixel = mean over its sub-samples ``xy`` (H, W, s, s, 2) of the plane's texture."""
    X = _shoot(P, xy, plane) - plane[0]
    u, v = X @ plane[2], X @ plane[3]
    k, phase = texture
    s = np.sin(u[..., None] * k[:, 0] + v[..., None] * k[:, 1] + phase).sum(-1)
    return (0.5 + 0.4 * np.tanh(s / np.sqrt(len(phase)))).mean(axis=(2, 3))


def ncc_accuracy_on_slanted_planes(angles=(0, 10, 20, 30)):
    """Median |WTA disparity error| (px) of window NCC on a textured plane turned by each angle."""
    from mrfpe.brdf.stereo.match import match_measure

    H = W = 24
    f, b = 2.5 * W, 2.5 * W
    P1, P2 = _rig(H, W, f, b, doffs=b - 6.0)
    rng = np.random.default_rng(1)
    k = rng.normal(0, 1, (12, 2))
    k *= rng.uniform(2 * np.pi / 6, 2 * np.pi / 2.5, (12, 1)) / np.linalg.norm(k, axis=1)[:, None]
    phase = rng.uniform(0, 2 * np.pi, 12)
    ss = 5
    off = (np.arange(ss) + 0.5) / ss
    xs = np.arange(W)[None, :, None, None] + off[None, None, None, :]
    ys = np.arange(H)[:, None, None, None] + off[None, None, :, None]
    xy = np.stack(np.broadcast_arrays(xs, ys), -1)
    pc, pr = np.meshgrid(np.arange(W) + 0.5, np.arange(H) + 0.5)
    out = []
    for ang in angles:
        a = np.deg2rad(ang)
        n = np.array([np.sin(a) * 0.8, np.sin(a) * 0.6, -np.cos(a)])  # plane n.X = n.(0, 0, f)
        e1 = np.cross(n, [0.0, 1.0, 0.0])
        e1 /= np.linalg.norm(e1)
        plane = (np.array([0.0, 0.0, f]), n, e1, np.cross(n, e1))
        left, right = (_plane_image(P, xy, plane, (k, phase)) for P in (P1, P2))
        Xc = _shoot(P1, np.stack([pc, pr], -1), plane)
        xr = (P2 @ np.concatenate([Xc, np.ones((H, W, 1))], -1)[..., None])[..., 0]
        d_true = pc - xr[..., 0] / xr[..., 2]
        labels = np.arange(np.floor(d_true.min()) - 1, np.ceil(d_true.max()) + 1, 0.01)
        m, _ = match_measure(left, right, labels, window=3)
        err = labels[np.argmax(m, axis=2)] - d_true
        out.append(float(np.median(np.abs(err[3:-3, 3:-3]))))
    return out


def sensitivity() -> list[str]:
    lines = []
    for ratio in (0.5, 1.0):
        dist = pl_vs_disparity_noise(ratio)
        lines.append(f"pl maximiser distance to the truth, baseline/depth {ratio}: "
                     + ", ".join(f"sigma {s} px -> {d:.3f}"
                                 for s, d in zip((0.0, 0.01, 0.02, 0.05), dist, strict=True)))
        print(lines[-1])
    acc = ncc_accuracy_on_slanted_planes()
    lines.append("window-NCC median |disparity error| on noise-free slanted planes: "
                 + ", ".join(f"{a} deg -> {e:.3f} px"
                             for a, e in zip((0, 10, 20, 30), acc, strict=True)))
    print(lines[-1])
    return lines


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--levels", nargs="+", default=list(LEVELS), choices=list(LEVELS))
    p.add_argument("--no-append", action="store_true", help="do not append to RESULTS.md")
    p.add_argument("--plot", default=str(HERE / "stereo_energy.png"))
    p.add_argument("--sensitivity", action="store_true",
                   help="measure the accuracy stereo needs for BRDF estimation instead")
    args = p.parse_args(argv)
    info = machine()
    if args.sensitivity:
        title = "Stereo accuracy needed for BRDF estimation"
        body = [f"- {x}" for x in sensitivity()]
    else:
        title = "Stereo: Middlebury motorcycle, bad-1px"
        body = run(args.levels, args.plot)
    print("\n".join(body))
    if not args.no_append:
        append_results(title, command_line(argv, "benchmarks.bench_stereo"), info, body)
    return 0


def run(levels: list[str], plot: str | Path) -> list[str]:
    """mrfpe's BP (both schedules) and OpenCV on the motorcycle pair; markdown body lines."""
    from mrfpe.brdf.stereo import disparity

    # warm the numba kernels so that timings are run times, not compile times
    z = np.zeros((8, 12))
    disparity(z, z, 3, iterations=1, schedule="accelerated")
    disparity(z, z, 3, iterations=1, schedule="parallel")

    rows, energies, estimates = [], {}, {}
    for level in levels:
        scale, dmax = LEVELS[level]
        left, right, gt = load(scale)
        g = gt[np.isfinite(gt)]
        print(f"{level}: {left.shape[1]}x{left.shape[0]}, GT disparity {g.min():.2f}-{g.max():.2f}"
              f" px ({100 * np.mean(np.isfinite(gt)):.1f}% of pixels), max_disparity={dmax}")
        nd = 16 * int(np.ceil(g.max() / 16))  # OpenCV's numDisparities, see the docstring
        methods = [("mrfpe accelerated", run_mrfpe, (dmax, "accelerated")),
                   ("mrfpe parallel", run_mrfpe, (dmax, "parallel")),
                   ("OpenCV StereoSGBM", run_sgbm, (nd,)),
                   ("OpenCV StereoBM", run_bm, (nd,))]
        has = np.isfinite(gt)
        for name, run, extra in methods:
            est, valid, secs, energy = run(left, right, *extra)
            estimates[(level, name)] = (est, valid)
            matched = "" if valid is None else f"{np.mean(np.abs(est - gt)[has & valid] > 1):.4f}"
            rows.append((level, name, bad1(est, gt, valid), matched, secs))
            if energy is not None:
                energies[(level, name)] = energy
            print(f"  {name:18s} bad-1px {rows[-1][2]:.4f}  {secs:6.2f} s"
                  + (f"  (over the pixels it matches: {matched})" if matched else ""))

    checks = []
    for level in levels:
        ea, ep = energies[(level, "mrfpe accelerated")], energies[(level, "mrfpe parallel")]
        reach = next((t for t in range(len(ea)) if ea[t] <= ep[10]), None)
        checks.append(f"{level}: accelerated reaches the parallel schedule's 10-iteration energy "
                      f"{ep[10]:.1f} at iteration {reach} (energy {ea[reach]:.1f})")
        _, _, gt = load(LEVELS[level][0])
        ours = estimates[(level, "mrfpe accelerated")][0]
        _, sg_valid = estimates[(level, "OpenCV StereoSGBM")]
        sub = np.isfinite(gt) & sg_valid
        checks.append(f"{level}: on the pixels StereoSGBM matches, mrfpe accelerated bad-1px "
                      f"{np.mean(np.abs(ours - gt)[sub] > 1):.4f}")
        print("\n".join(checks[-2:]))

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(levels), figsize=(5 * len(levels), 3.6),
                             squeeze=False)
    for ax, level in zip(axes[0], levels, strict=True):
        for name, style in (("mrfpe accelerated", "o-"), ("mrfpe parallel", "s--")):
            e = energies[(level, name)]
            ax.plot(np.arange(len(e)), e, style, label=name.split()[1], ms=4)
        ax.set_title(f"motorcycle, {level} resolution")
        ax.set_xlabel("iteration (0 = winner takes all)")
        ax.set_ylabel("MRF energy of the MAP labelling")
        ax.legend()
    fig.tight_layout()
    fig.savefig(plot, dpi=120)
    print(f"energy plot -> {plot}")

    table = ["| resolution | method | bad-1px | bad-1px over matched pixels | time (s) |",
             "|---|---|---|---|---|"]
    table += [f"| {lv} | {nm} | {b:.4f} | {m or 'all matched'} | {s:.2f} |"
              for lv, nm, b, m, s in rows]
    return ["mrfpe defaults, 10 iterations; quarter = 185x125 (GT 1.8-15.0 px, max_disparity "
            "20), half = 370x250 (GT 3.6-30.0 px, max_disparity 40); OpenCV numDisparities 16 "
            "/ 32. Unmatched pixels count as bad.\n", *table, "",
            *(f"- {c}" for c in checks), f"- energy against iteration: `{Path(plot).name}`"]


if __name__ == "__main__":
    raise SystemExit(main())

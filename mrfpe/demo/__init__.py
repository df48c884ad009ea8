"""``mrfpe demo``: recover the reflectance of a synthetic surface from its image.

Renders a 100x100 Ward scene with 20 candidate depths (labels) per pixel and
random true parameters (thesis 7.2), builds its pseudolikelihood (PL) target
``pls`` (7.5–7.7) and samples it with population Monte Carlo: the thesis's
1000 particles x 20 iterations, each iteration weighted by the full PL (``k=1``;
the sampler's default of three sub-lattices leaves too few effective samples
after the final reweighting on about half of such scenes). It prints the truth,
the MAP, the posterior mean ± sd and 95 % intervals, whether the posterior is
reliable, a verdict in words, the thesis's figure for the same settings beside
this version's, and what to try next; it writes ``scene.nc``, ``posterior.nc``,
``posterior.png`` (:mod:`mrfpe.demo.figure`) and ``report.md``.

``quick`` uses a 40x40 scene with 10 labels and 1000 particles x 20 iterations:
seconds instead of a minute, and no thesis figure to compare with.
"""

from __future__ import annotations

import os
import textwrap
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mrfpe._terminal import WIDTH

__all__ = ["DEFAULT", "QUICK", "Settings", "main"]


@dataclass(frozen=True)
class Settings:
    """One demo configuration: the scene and the PMC run."""

    shape: tuple[int, int]
    n_labels: int
    n_samples: int
    n_iterations: int
    #: Sub-lattices PMC cycles through (1 weighs the whole image in every iteration).
    k: int
    #: The thesis's mean |MAP − truth| at these settings and this version's, or None.
    thesis: str | None = None


DEFAULT = Settings((100, 100), 20, 1000, 20, 1, thesis=(
    "thesis Table 7.1 (PMC, Ward, 20 labels, 1000 particles, 100x100 pixels): 0.104 "
    "on average over 100 scenes; this version, 20 scenes (--seed 0 to 19): mean 0.043 "
    "(sd 0.043), median 0.028, range 0.0002-0.150"))
QUICK = Settings((40, 40), 10, 1000, 20, 1)

#: Where the true parameters are drawn from, per unit-cube coordinate (thesis 7.1).
TRUTH_RANGE = (0.1, 0.9)
#: Central posterior interval reported per parameter.
INTERVAL = 0.95
#: A MAP whose log PL is within this of the truth's (or above) is the PL's own answer.
PL_TIE = 1.0


def _prepare(out_dir: str | Path) -> Path:
    """Create the output directory and prove it is writable, before any work."""
    out = Path(out_dir)
    try:
        out.mkdir(parents=True, exist_ok=True)
        probe = out / f".write-test-{os.getpid()}"
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as exc:
        raise ValueError(f"--out {out}: cannot write there ({exc.strerror or exc})") from None
    return out


def _verdict(dist: float, gap: float, inside: np.ndarray, names: list[str]) -> str:
    """The result in words: how far the MAP is, whose fault that is, and the intervals."""
    text = f"Result: the MAP lies {dist:.3f} from the truth in the unit cube. "
    if gap >= -PL_TIE:
        text += (f"The pseudolikelihood scores it {gap:+.2f} log units against the truth, so "
                 "PMC found the top of the PL: what distance is left is the PL's own, not "
                 "the sampler's. ")
    else:
        text += (f"The pseudolikelihood scores the truth {-gap:.2f} log units higher: PMC "
                 "has not reached the PL's top (try more iterations). ")
    missed = [n for n, ok in zip(names, inside) if not ok]
    text += (f"The truth lies inside the {INTERVAL:.0%} posterior interval of "
             f"{int(inside.sum())} of {len(names)} parameters"
             + (f" (not {', '.join(missed)})." if missed else "."))
    return text


def main(out_dir: str | Path = "mrfpe-demo", quick: bool = False, seed: int = 0) -> int:
    """Run the demo; returns the process exit code (0 on success)."""
    import mrfpe
    from mrfpe import posterior as P
    from mrfpe.brdf import get as get_brdf
    from mrfpe.brdf.synthetic import make_scene
    from mrfpe.demo.figure import CAPTION, posterior_figure
    from mrfpe.experiments.writeup import mean_sd
    from mrfpe.validation import check_seed

    if seed is None:
        raise ValueError("seed must be an integer in [0, 2**63 - 1]; got None")
    check_seed(seed)
    out = _prepare(out_dir)
    cfg = QUICK if quick else DEFAULT
    lines: list[str] = []

    def say(text: str = "") -> None:
        for line in textwrap.wrap(text, WIDTH, subsequent_indent="  ", break_on_hyphens=False,
                                  break_long_words=False) or [""]:
            print(line, flush=True)
            lines.append(line)

    t0 = time.perf_counter()
    model = get_brdf("ward")
    truth = np.random.default_rng(seed).uniform(*TRUTH_RANGE, 3)
    theta_nat = np.asarray(model.to_natural(truth), dtype=float).reshape(-1)
    scene = make_scene(brdf="ward", theta=theta_nat, shape=cfg.shape, n_labels=cfg.n_labels,
                       seed=seed)
    target = mrfpe.targets.get("pls", scene)  # first: a build over budget writes nothing
    scene.save(out / "scene.nc")
    names = list(target.param_names)
    say("mrfpe demo: estimate the reflectance of a synthetic surface from its image")
    say(f"scene: Ward reflectance, {cfg.shape[0]}x{cfg.shape[1]} pixels, {cfg.n_labels} "
        f"candidate depths per pixel -> {out / 'scene.nc'}")
    say("true parameters: " + "  ".join(f"{n}={v:.4f}" for n, v in zip(names, theta_nat))
        + " (natural units)")

    post = mrfpe.sample("pmc", target, seed=seed, progress=True, n_samples=cfg.n_samples,
                        n_iterations=cfg.n_iterations, k=cfg.k)
    P.save(post, out / "posterior.nc")
    m, m_lt = P.map_estimate(post)
    truth_lt = float(target.log_prob(truth[None])[0])
    mean = P.weighted_mean(post)
    sd = np.sqrt(np.clip(np.diag(P.weighted_cov(post)), 0, None))
    lo, hi = P.weighted_quantiles(post, [(1 - INTERVAL) / 2, (1 + INTERVAL) / 2])
    inside = (truth >= lo) & (truth <= hi)
    say(f"PMC: {cfg.n_samples} particles x {cfg.n_iterations} iterations in "
        f"{post.attrs['wall_time_s']:.1f} s, {post.attrs['n_target_evals']:.0f} evaluations "
        f"of the PL -> {out / 'posterior.nc'}")
    say("")
    say(f"{'unit cube':<10}{'truth':>8}{'MAP':>8}   {'posterior mean ± sd':<24}"
        f"{INTERVAL:.0%} interval")
    for n, t, mj, a, s, lj, hj in zip(names, truth, m, mean, sd, lo, hi):
        say(f"{n:<10}{t:>8.4f}{mj:>8.4f}   {mean_sd(a, s):<24}[{lj:.4f}, {hj:.4f}]")
    reliable = bool(post.attrs["diag_reliable"])
    say(f"effective sample size {post.attrs['diag_ess']:.0f} of {post.sizes['sample']} "
        f"particles: the posterior is {'reliable' if reliable else 'NOT reliable'} "
        "(mrfpe.posterior.diagnose)")
    if int(post.attrs.get("target_calibrated", -1)) == 0:
        say("It is a pseudo-posterior: exp(PL) normalised, as in the thesis; its spread is the "
            "PL's,\nnot a Bayesian posterior's (mrfpe.posterior.caveats).")
    say("")
    say(_verdict(float(np.linalg.norm(m - truth)), m_lt - truth_lt, inside, names))
    if cfg.thesis:
        say(f"For comparison, {cfg.thesis}.")
    posterior_figure(target, post, truth, out / "posterior.png", 30 if quick else 60)
    say(f"figure -> {out / 'posterior.png'}; total {time.perf_counter() - t0:.0f} s")
    say("Next: another scene with `mrfpe demo --seed 1`; each step explained: the tutorial "
        "\"From an image to BRDF parameters\" (docs/tutorials/02-image-to-brdf.md).")
    report = out / "report.md"
    report.write_text("# mrfpe demo\n\n```text\n" + "\n".join(lines) + "\n```\n\n"
                      "Files: [scene.nc](scene.nc), [posterior.nc](posterior.nc)\n\n"
                      "![The posterior of the demo's scene](posterior.png)\n\n"
                      f"*{CAPTION}*\n")
    print(f"report -> {report}")
    return 0

"""mrfpe's performance suite; run ``python -m benchmarks`` from the repository root.

Suites (``--only`` picks some):

* ``targets``  -- :mod:`benchmarks.bench_targets`: ``pls`` construction time and
  memory, ``log_prob`` throughput for batches of 1, 64 and 1000 (Ward and Phong,
  100x100, 10-40 labels; Ward also in float32), the comparison kernel, and PMC
  1000 x 20 wall time and peak memory beside the thesis's Table 8.12;
* ``samplers`` -- :mod:`benchmarks.bench_samplers`: evaluations and seconds for
  ``pmc``, ``emcee``, ``dw_r`` and ``lm_multiseed`` to bring the MAP within 0.05
  of the truth, as ratios to PMC measured in one run;
* ``stereo``   -- :mod:`benchmarks.bench_stereo`: loopy BP against OpenCV on the
  Middlebury motorcycle pair.

Each suite also runs alone (``python -m benchmarks.bench_targets --help``).
:mod:`benchmarks.bench_pmc` (PMC variants and softening powers against the PL
maximiser) is a study tool rather than a performance benchmark and is not part
of the default run.
"""

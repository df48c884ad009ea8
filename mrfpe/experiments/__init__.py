"""The thesis's experiments (chapters 7-8), each run as a study: one module per experiment.

Every experiment module defines ``STUDY = mrfpe.study.Study(...)`` and is
registered under the entry-point group ``mrfpe.studies`` in ``pyproject.toml``
(as the built-in samplers, models and distances are under theirs), which is
how :mod:`mrfpe.study` finds it: the machinery never imports this package, and
another distribution can ship studies the same way. They live inside the
package (not only in the repository's ``studies/`` folder) so that every
install -- editable or not -- can list and run them, and so that dask workers
import a study's trial function by name. Run them with ``mrfpe study run
NAME``; see :mod:`mrfpe.study` and ``docs/studies.md``.

Not experiments: the public helpers for writing a study,
:mod:`mrfpe.experiments.writeup` (numbers for tables, markdown tables, figures,
``report.md``) and :mod:`mrfpe.experiments.problems` (the synthetic-scene
settings the thesis's experiments share, and the problems they make), and the
private :mod:`mrfpe.experiments._thesis` (the thesis's reference numbers).
"""

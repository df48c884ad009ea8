"""The built-in studies: one module per experiment, each defining ``STUDY``.

They live inside the package (not only in the repository's ``studies/``
folder) so that every install -- editable or not -- can list and run them, and
so that dask workers import a study's trial function by name. Run them with
``mrfpe study run NAME``; see :mod:`mrfpe.study` and ``docs/studies.md``.

Not studies: the public helpers for writing one, :mod:`mrfpe.studies.report`
(tables, figures, ``report.md``) and :mod:`mrfpe.studies.synthetic` (shared
settings and synthetic problems), listed in :data:`HELPER_MODULES`, and the
private modules whose name starts with ``_``.
"""

#: Modules of this package that are helpers, not studies (discovery skips them).
HELPER_MODULES = frozenset({"report", "synthetic"})

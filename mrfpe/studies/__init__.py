"""The built-in studies: one module per experiment, each defining ``STUDY``.

They live inside the package (not only in the repository's ``studies/``
folder) so that every install -- editable or not -- can list and run them, and
so that dask workers import a study's trial function by name. Run them with
``mrfpe study run NAME``; see :mod:`mrfpe.study` and ``docs/studies.md``.
Modules whose name starts with ``_`` are helpers, not studies.
"""

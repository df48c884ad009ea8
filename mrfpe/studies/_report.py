"""Old name of :mod:`mrfpe.studies.report`, kept for ``benchmarks/``; use the public one."""

from mrfpe.studies.report import *  # noqa: F403
from mrfpe.studies.report import __all__  # noqa: F401

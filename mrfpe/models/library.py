"""Ready-made discrete models, each a few lines over :class:`mrfpe.models.MRF`.

=================  ===================================================  =======================
factory            log-potential (thesis 4.3-4.5, T = 1)                theta
=================  ===================================================  =======================
``potts``          ``J sum_<ij> [x_i = x_j] + sum_a h_a n_a(x)``        coupling, field_1, ...
``ising``          ``J sum_<ij> s_i s_j + h sum_i s_i``, s = +-1         coupling, field
``autologistic``   ``eta sum_<ij> x_i x_j + sum_i (a + z_i·b) x_i``     coupling, field, z...
=================  ===================================================  =======================

``potts(2)`` is the Ising model in the 0/1 coding, with coupling ``J`` and
field ``h`` equal to twice the spin-convention ones (``delta(x_i, x_j) = (1 +
s_i s_j)/2``): the critical coupling of the infinite square lattice is
``J = log(1 + sqrt 2) = 0.8814`` for ``potts(2)`` and ``0.4407`` for ``ising()``
(Onsager 1944). ``autologistic`` is Besag's (1972) auto-logistic model with
covariates, the logistic CRF of spatial statistics: ``logit p(x_i = 1 | x_N_i) =
field + z_i . beta + coupling * sum_{j ~ i} x_j``.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from mrfpe.models.discrete import MRF
from mrfpe.models.graph import as_graph_spec, lattice
from mrfpe.models.terms import Coupling, Field, NodeCovariate

__all__ = ["autologistic", "ising", "potts"]


def _graph(graph: Any, neighbourhood: Any, periodic: bool, directional: bool) -> Any:
    if graph is not None:
        return as_graph_spec(graph)
    return lattice(neighbourhood, periodic=periodic, directional=directional)


def potts(n_states: int = 2, neighbourhood: Any = 4, *, periodic: bool = False,
          directional: bool = False, graph: Any = None) -> MRF:
    """The q-state Potts model with one field per non-reference state.

    Parameters
    ----------
    n_states : int >= 2
    neighbourhood : 4, 8 or offsets
        Of the lattice (ignored when ``graph`` is given).
    periodic, directional : bool
        Torus boundary; one coupling per direction (``coupling_horizontal``, ...).
    graph : optional
        Any graph instead of a lattice (:func:`mrfpe.models.graph.as_graph_spec`).
    """
    return MRF(_graph(graph, neighbourhood, periodic, directional), n_states,
               [Coupling(by_type=directional), Field()], name="potts")


def ising(neighbourhood: Any = 4, *, periodic: bool = False, directional: bool = False,
          graph: Any = None) -> MRF:
    """The Ising model in spins: states 0, 1 stand for s = -1, +1; theta = (coupling, field)."""
    return MRF(_graph(graph, neighbourhood, periodic, directional), 2,
               [Coupling("product", by_type=directional), Field("value")],
               state_values=(-1.0, 1.0), name="ising")


def autologistic(covariates: Sequence[str] = (), neighbourhood: Any = 4, *,
                 periodic: bool = False, directional: bool = False, graph: Any = None) -> MRF:
    """Besag's auto-logistic model (0/1 states) with node covariates (a logistic CRF).

    Parameters
    ----------
    covariates : sequence of str
        Names of node covariates (each ``(H, W)`` or ``(H, W, k)``), passed to
        ``target``/``simulate`` as ``covariates={name: array}``.
    """
    if isinstance(covariates, str):
        covariates = (covariates,)
    terms = [Coupling("product", by_type=directional), Field("value")]
    terms += [NodeCovariate(str(c), kind="value") for c in covariates]
    return MRF(_graph(graph, neighbourhood, periodic, directional), 2, terms,
               name="autologistic")

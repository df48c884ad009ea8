"""What only chains need: chain-length and thinning checks."""

from __future__ import annotations

from typing import Any

from mrfpe.validation import check_positive_int

__all__ = ["check_chain_length"]


def check_chain_length(n_steps: Any, burn_in: Any, thin: Any) -> tuple[int, int, int]:
    """Validate ``n_steps`` >= 1, 0 <= ``burn_in`` < ``n_steps`` and ``thin`` >= 1."""
    n_steps = check_positive_int("n_steps", n_steps)
    burn_in_ = check_positive_int("burn_in", burn_in, minimum=0)
    if burn_in_ >= n_steps:
        raise ValueError(f"burn_in must be < n_steps ({n_steps}); got {burn_in}")
    return n_steps, burn_in_, check_positive_int("thin", thin)

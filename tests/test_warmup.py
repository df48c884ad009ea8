"""``mrfpe warmup`` fills numba's cache of the numerical kernels."""

from mrfpe.brdf.engine import compiled_kernels
from mrfpe.samplers.kit.warm import kernels_cached


def test_warmup_command_fills_the_cache(capsys):
    from mrfpe.cli import main

    assert main(["warmup"]) == 0
    assert "done in" in capsys.readouterr().out
    assert kernels_cached(compiled_kernels())

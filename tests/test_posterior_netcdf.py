"""A posterior writes with plain xarray (``to_netcdf``) and reads back with every attribute."""

import numpy as np
import pytest
import xarray as xr

from mrfpe import posterior as P


def _build(n: int, log_weight=None, **kw) -> xr.Dataset:
    rng = np.random.default_rng(0)
    theta = rng.uniform(0, 1, (n, 2))
    return P.build(theta, np.zeros(n), param_names=["a", "b"], log_weight=log_weight,
                   sampler="t", map_theta=theta[:1], map_log_target=[0.0], **kw)


def _reliable() -> xr.Dataset:
    return _build(400, log_evidence=-1.5, log_evidence_se=0.25)


def _unreliable() -> xr.Dataset:
    lw = np.zeros(40)
    lw[0] = 30.0  # one weight dominates: ESS ≈ 1 and a Pareto k̂ complaint
    with pytest.warns(P.PosteriorWarning):
        return _build(40, log_weight=lw, bias="a bias, in words")


@pytest.mark.parametrize("make", [_reliable, _unreliable])
def test_plain_to_netcdf_round_trips_every_attribute(make, tmp_path):
    post = make()
    path = tmp_path / "post.nc"
    post.to_netcdf(path)  # no mrfpe involved: what any xarray user calls
    with xr.open_dataset(path) as ds:
        back = ds.load()
    assert set(back.attrs) == set(post.attrs)
    for key, value in post.attrs.items():
        got = back.attrs[key]
        if isinstance(value, float) and np.isnan(value):
            assert np.isnan(got), key
        else:
            assert got == value, key
    np.testing.assert_array_equal(back["theta"].values, post["theta"].values)
    P.validate(back)
    assert bool(back.attrs["diag_reliable"]) is bool(post.attrs["diag_reliable"])
    assert P.stored_messages(back) == P.diagnose(post)["messages"]


def test_save_load_stay_exact(tmp_path):
    post = _unreliable()
    P.save(post, tmp_path / "p.nc")
    xr.testing.assert_identical(P.load(tmp_path / "p.nc"), post)
    assert type(P.load(tmp_path / "p.nc").attrs["diag_reliable"]) is int


def test_files_with_boolean_and_list_diagnostics_still_validate(tmp_path):
    """Posteriors saved before the attributes became netCDF types load and validate."""
    post = _unreliable()
    old = post.assign_attrs(diag_reliable=False,
                            diag_messages=P.diagnose(post)["messages"])
    P.save(old, tmp_path / "old.nc")
    back = P.load(tmp_path / "old.nc")
    P.validate(back)
    assert P.stored_messages(back) == P.diagnose(post)["messages"]
    assert "UNRELIABLE" in P.summary(back)

"""A posterior writes with plain xarray (``to_netcdf``) and reads back with every attribute;
:func:`~mrfpe.posterior.save` refuses paths it must not replace, :func:`~mrfpe.posterior.load`
files that hold no posterior."""

import os
import stat

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


# ---------------------------------------------------------------- paths save refuses

def _tree(d):
    """Every name under ``d`` with its kind and size: to show nothing was touched."""
    return sorted((str(p.relative_to(d)), stat.S_IFMT(os.lstat(p).st_mode),
                   os.lstat(p).st_size) for p in [d, *d.rglob("*")])


def test_save_refuses_a_named_pipe_touching_nothing(tmp_path):
    """The audit's case: the API replaced a FIFO with a regular file (the CLI refused)."""
    fifo = tmp_path / "pipe.nc"
    os.mkfifo(fifo)
    before = _tree(tmp_path)
    with pytest.raises(ValueError, match=rf"^{fifo}: posterior path is a named pipe, not a "
                                         "regular file; refusing to replace it$"):
        P.save(_reliable(), fifo)
    assert _tree(tmp_path) == before


def test_save_refuses_a_device_touching_nothing():
    """The audit's case: /dev/null (a character device) would have been replaced."""
    before = os.stat("/dev/null")
    with pytest.raises(ValueError, match=r"^/dev/null: posterior path is a character device, "
                                         "not a regular file; refusing to replace it$"):
        P.save(_reliable(), "/dev/null")
    after = os.stat("/dev/null")
    assert (after.st_mode, after.st_rdev, after.st_ino) == (before.st_mode, before.st_rdev,
                                                            before.st_ino)
    assert not [n for n in os.listdir("/dev") if n.startswith(".null.")]  # no probe left


def test_save_into_a_missing_directory_is_one_line_naming_it(tmp_path):
    """The audit's case: a PermissionError naming a temporary file."""
    target = tmp_path / "missing" / "p.nc"
    with pytest.raises(ValueError) as info:
        P.save(_reliable(), target)
    assert str(info.value) == (f"{target}: cannot write the posterior file: directory "
                               f"{tmp_path / 'missing'} does not exist")
    assert list(tmp_path.iterdir()) == []


def test_save_onto_a_directory_names_it_touching_nothing(tmp_path):
    """The audit's case: a raw IsADirectoryError naming a temporary file beside it."""
    (tmp_path / "d").mkdir()
    (tmp_path / "d" / "keep.txt").write_text("kept")
    before = _tree(tmp_path)
    with pytest.raises(ValueError, match=rf"^{tmp_path / 'd'}: posterior path is a directory; "
                                         "expected a file name$"):
        P.save(_reliable(), tmp_path / "d")
    assert _tree(tmp_path) == before


def test_load_refuses_a_scene_naming_what_it_holds(tmp_path):
    """The audit's case: a scene file loaded as a posterior without a word."""
    from mrfpe.brdf.synthetic import make_scene

    path = tmp_path / "scene.nc"
    make_scene(brdf="ward", theta=[0.3, 0.2, 0.1], shape=(6, 6), n_labels=3,
               seed=0).save(path)
    with pytest.raises(ValueError) as info:
        P.load(path)
    assert str(info.value) == (f"{path}: not a posterior file (written by mrfpe estimate / "
                               "posterior.save): it holds a scene (written by Scene.save / "
                               "mrfpe demo)")


@pytest.mark.parametrize(("attrs", "holds"), [
    ({}, "the variables x"),
    ({"sampler": "pmc"}, "no variable 'theta'"),
    ({"study": "s", "config_hash": "h"}, "a study trial's result"),
])
def test_load_refuses_other_netcdf_files_naming_what_they_hold(tmp_path, attrs, holds):
    path = tmp_path / "other.nc"
    xr.Dataset({"x": ("i", np.arange(3.0))}, attrs=attrs).to_netcdf(path)
    with pytest.raises(ValueError, match=rf"^{path}: not a posterior file .*: it holds "
                                         rf"{holds}"):
        P.load(path)

"""Reports from the trial files on disk (mrfpe.study.summarise_existing, `mrfpe study report`)."""

from __future__ import annotations

import pytest

from mrfpe import study as S
from mrfpe.cli import main
from mrfpe.experiments import importance_sampling as toy

SMALL = {"n_trials": 2, "n_samples": [10, 100]}


@pytest.fixture
def half_done(tmp_path):
    """Both cells run, then one trial of the n = 100 cell lost (as if still to come)."""
    cfg = S.resolve_config(toy.STUDY, overrides=SMALL)
    assert S.run(toy.STUDY, cfg, tmp_path, progress=False).ok
    lost = sorted((tmp_path / "trials").glob("n_samples=100,*.nc"))
    assert len(lost) == 2
    lost[0].unlink()
    (tmp_path / "report.md").unlink()
    return cfg, tmp_path


def test_complete_cells_only_by_default(half_done):
    cfg, out = half_done
    s = S.summarise_existing(toy.STUDY, cfg, out)
    assert s.cells == [{"n_samples": 10}] and s.n_trials == 2 and s.n_missing == 2
    report = (out / "report.md").read_text()
    assert "| 10 |" in s.table and "| 100 |" not in s.table
    assert report.strip()


def test_partial_takes_every_trial_found(half_done):
    cfg, out = half_done
    s = S.summarise_existing(toy.STUDY, cfg, out, partial=True)
    assert s.cells == [{"n_samples": 10}, {"n_samples": 100}] and s.n_trials == 3
    assert s.n_missing == 1 and "| 100 |" in s.table


def test_trials_of_another_config_do_not_count(half_done):
    cfg, out = half_done
    other = S.resolve_config(toy.STUDY, overrides={**SMALL, "seed": cfg["seed"] + 1})
    with pytest.raises(ValueError, match=r"no complete cells.*--partial"):
        S.summarise_existing(toy.STUDY, other, out)


def test_cli_report(half_done, capsys):
    _, out = half_done
    args = ["study", "report", "importance_sampling", "--set", "n_trials=2",
            "--set", "n_samples=[10, 100]", "--out", str(out)]
    assert main(args) == 0
    assert "summarised 2 trial(s) in 1 cell(s)" in capsys.readouterr().out
    assert main([*args[:2], "importance_sampling", "--out", str(out / "nothing")]) == 2
    assert "no complete cells" in capsys.readouterr().err


def test_summary_only_settings_re_summarise_the_same_trials(tmp_path):
    import dataclasses

    seen = []

    def summarise(results, config, out):
        seen.append(config["label"])
        return toy.STUDY.summarise(results, config, out)

    label = S.Setting("label", "a", "read by the summary alone", summary_only=True)
    study = dataclasses.replace(toy.STUDY, settings=[*toy.STUDY.settings, label],
                                summarise=summarise)
    assert study.summary_keys == {"label"}
    cfg = S.resolve_config(study, overrides=SMALL)
    assert S.run(study, cfg, tmp_path, progress=False).ok and seen == ["a"]
    assert all("label" not in t.config for t in S.tasks(study, cfg))
    other = S.resolve_config(study, overrides={**SMALL, "label": "b"})
    assert [t.hash for t in S.tasks(study, other)] == [t.hash for t in S.tasks(study, cfg)]
    s = S.summarise_existing(study, other, tmp_path)  # the same four files, summarised anew
    assert s.n_trials == 4 and s.n_missing == 0 and seen[-1] == "b"
    # a trial setting still separates configurations
    seed = S.resolve_config(study, overrides={**SMALL, "seed": cfg["seed"] + 1})
    assert S.tasks(study, seed)[0].hash != S.tasks(study, cfg)[0].hash

"""Smoke test of `python -m apps.standing`."""

import json

import pytest

from apps import standing as stand


def test_stand_app_runs_and_reports(tmp_path, capsys):
    status = stand.main(["--model", "all", "--duration", "1", "--no-meshcat",
                         "--out", str(tmp_path)])
    out = capsys.readouterr().out
    assert status == 0
    assert "standing simulation of the humanoids" in out
    for name in ("hrp4_like", "nao_like"):
        assert name in out
        row = json.loads((tmp_path / "stand" / f"{name}.json").read_text())
        assert row["fell"] is False
        assert row["feet_flat"] is True
        assert row["min_sphere_force_N"] > 0.0
        assert row["real_time_factor"] > 0.0
        assert not (tmp_path / "stand" / f"{name}.html").exists()  # no Meshcat, no replay


def test_stand_app_rejects_bad_arguments(tmp_path):
    with pytest.raises(SystemExit):
        stand.main(["--model", "atlas", "--no-meshcat", "--out", str(tmp_path)])
    with pytest.raises(SystemExit):
        stand.main(["--duration", "-1", "--no-meshcat", "--out", str(tmp_path)])

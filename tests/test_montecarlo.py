"""Monte Carlo consistency (`fgslam bench`, fgslam/montecarlo.py)."""

from __future__ import annotations

import concurrent.futures
import json

import numpy as np
import pytest

from fgslam.cli import main
from fgslam.compare import nees_band
from fgslam.montecarlo import dask_executor, monte_carlo, run_one
from slamio.errors import FgslamError


def test_average_nees_is_the_mean_of_the_runs_and_any_executor_works():
    with concurrent.futures.ThreadPoolExecutor(max_workers=2) as pool:
        result = monte_carlo("arena-square", 3, laps=1, first_seed=5, executor=pool)
    assert [r.seed for r in result.runs] == [5, 6, 7]
    one = run_one("arena-square", 6, ("ekf", "isam2"), laps=1)
    assert np.allclose(result.runs[1].nees["ekf"], one.nees["ekf"])  # seeded: the same run
    n = len(result.average_nees["ekf"])
    expected = np.mean([r.nees["ekf"][:n] for r in result.runs], axis=0)
    assert np.allclose(result.average_nees["ekf"], expected)
    assert result.band == nees_band(3, 3)
    inside = np.mean((expected >= result.band[0]) & (expected <= result.band[1]))
    assert result.share_inside("ekf") == pytest.approx(inside)


def test_fgslam_bench_prints_writes_and_uses_a_process_pool(tmp_path, capsys):
    out = tmp_path / "mc"
    assert main(["bench", "arena-octagon", "--runs", "4", "--jobs", "2", "--laps", "1", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "4 runs (seeds 0-3)" in text and "ekf" in text and "isam2" in text
    summary = json.loads((out / "montecarlo.json").read_text())
    assert summary["runs"] == 4 and summary["band"] == pytest.approx(list(nees_band(3, 4)))
    for name in ("ekf", "isam2"):
        s = summary["estimators"][name]
        assert len(s["ate_final_m"]) == 4 and len(s["average_nees"]) == summary["steps"]
        assert 0.0 <= s["share_inside_band"] <= 1.0
    assert (out / "nees.png").stat().st_size > 10_000 and (out / "ate.png").stat().st_size > 10_000


def test_dask_without_the_extra_says_how_to_install_it(monkeypatch):
    import builtins

    real_import = builtins.__import__

    def no_dask(name, *args, **kwargs):
        if name.startswith("dask"):
            raise ImportError("no dask here")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_dask)
    with pytest.raises(FgslamError, match=r"fgslam\[dask\]"):
        with dask_executor("tcp://127.0.0.1:8786"):
            pass


def test_an_estimator_without_covariance_is_refused():
    with pytest.raises(FgslamError, match="no covariance|unknown"):
        monte_carlo("arena-square", 1, estimators=("batch",), laps=1, jobs=1)


def test_fgslam_bench_on_a_real_dask_cluster(tmp_path, capsys):
    """``--dask ADDRESS`` through a real scheduler and worker on loopback TCP (a
    LocalCluster in this process); seeded runs give the same figures as the process pool."""
    distributed = pytest.importorskip("distributed", reason="the dask extra (in the dev extras) is missing")
    with distributed.LocalCluster(
        n_workers=1, threads_per_worker=2, processes=False, protocol="tcp", dashboard_address=None
    ) as cluster:
        address = cluster.scheduler_address
        assert address.startswith("tcp://")
        out = tmp_path / "mc"
        code = main(["bench", "arena-square", "--runs", "2", "--laps", "1", "--seed", "5", "--dask", address,
                     "--out", str(out)])
    assert code == 0
    assert "2 runs (seeds 5-6)" in capsys.readouterr().out
    summary = json.loads((out / "montecarlo.json").read_text())
    for seed, ate in zip((5, 6), summary["estimators"]["ekf"]["ate_final_m"]):
        assert ate == pytest.approx(run_one("arena-square", seed, ("ekf",), laps=1).ate_final_m["ekf"], rel=1e-12)


def test_dask_scheduler_that_is_not_there_is_a_clear_error():
    pytest.importorskip("distributed", reason="the dask extra (in the dev extras) is missing")
    with pytest.raises(FgslamError, match="cannot reach the Dask scheduler at tcp://127.0.0.1:9"):
        with dask_executor("tcp://127.0.0.1:9", timeout_s=1.0):
            pass

"""The fan-out seam (peano_bayes.app.fanout): outcomes in order, errors kept, one writer, schedulers; and, on a Dask
LocalCluster of two workers, two real units (a short fit and an SBC replicate) that survive the loss of a worker
and equal a serial run with the same seeds."""

import json
import os
import signal
import socket
import subprocess
import sys
import threading
import time

import numpy as np
import pytest

from peano_bayes.app.cli import main
from peano_bayes.app.fanout import Unit, log_name, make_executor, parse_scheduler, raise_failures, run_units
from peano_bayes.errors import PeanoBayesError, PeanoBayesInputError


def _square(x):
    return x * x


def _fails(x):
    raise ValueError(f"no square for {x}")


def _prints(x):
    print(f"working on {x}")
    return x


def test_serial_units_come_back_in_order_with_errors_kept_and_one_writer(tmp_path):
    units = [Unit("a", _square, (3,)), Unit("b", _fails, (4,)), Unit("c", _square, (5,))]
    seen, lines = [], []
    outcomes = run_units(units, None, on_result=lambda o: seen.append(o.key), log=lines.append)
    assert [o.key for o in outcomes] == ["a", "b", "c"] == seen
    assert [o.value for o in outcomes] == [9, None, 25]
    assert [o.ok for o in outcomes] == [True, False, True]
    assert outcomes[1].error == "ValueError: no square for 4" and "_fails" in outcomes[1].traceback
    assert outcomes[0].worker == f"{os.uname().nodename}:{os.getpid()}" and outcomes[0].seconds >= 0
    assert lines[-1].startswith("c: done in") and "2 done, 1 failed, 0 not finished" in lines[-1]
    with pytest.raises(PeanoBayesError, match=r"1 of 3 work unit\(s\) failed: b: ValueError: no square for 4"):
        raise_failures(outcomes)
    with pytest.raises(PeanoBayesInputError, match="distinct keys; repeated: a"):
        run_units([Unit("a", _square, (1,)), Unit("a", _square, (2,))])


def test_a_units_printed_output_is_kept_in_its_log_file(tmp_path, capsys):
    lines = []
    run_units([Unit("TP / spec 1", _prints, (7,)), Unit("b", _prints, (8,))], None, log_dir=tmp_path, log=lines.append)
    assert "1 done, 0 running, 0 failed, 1 not finished" in lines[0]  # b's log does not exist yet: not started
    text = (tmp_path / log_name("TP / spec 1")).read_text()
    assert log_name("TP / spec 1") == "TP_spec_1.log"
    assert "TP / spec 1: started on " in text and "working on 7" in text
    assert "working on 7" in capsys.readouterr().out  # still printed where it was


def test_scheduler_specifications():
    assert parse_scheduler(None) == ("processes", None) == parse_scheduler("  ")
    assert parse_scheduler("local:3") == ("local", 3)
    assert parse_scheduler("tcp://10.0.0.2:8786") == ("address", "tcp://10.0.0.2:8786")
    assert parse_scheduler("tls://head:8786") == ("address", "tls://head:8786")
    for bad in ("local:0", "local", "10.0.0.2:8786", "dask", "bogus://x", "http://head:8787"):
        with pytest.raises(PeanoBayesInputError, match="local:N|at least 1 worker"):
            parse_scheduler(bad)
    with pytest.raises(PeanoBayesInputError, match="jobs must be >= 1"):
        with make_executor(None, 0):
            pass
    with make_executor(None, 1) as (executor, info):
        assert executor is None and info.kind == "serial"


def test_a_scheduler_nothing_listens_at_is_reported_before_dask_tries(monkeypatch):
    """Dask retries a refused connection for its 30 s connect timeout; one probe says so before a client exists."""
    distributed = pytest.importorskip("distributed")

    def no_client(*args, **kwargs):
        raise AssertionError("a Dask client was made for a scheduler that cannot be reached")

    monkeypatch.setattr(distributed, "Client", no_client)
    with socket.socket() as s:  # a port that was free a moment ago: nothing listens there
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    with pytest.raises(PeanoBayesError, match=f"cannot reach the Dask scheduler at tcp://127.0.0.1:{port}"):
        with make_executor(f"tcp://127.0.0.1:{port}"):
            pass
    for bad in ("tcp://head", "tcp://head:70000", "tcp://head:0"):
        with pytest.raises(PeanoBayesInputError, match="expected tcp://HOST:PORT"):
            with make_executor(bad):
                pass


def test_a_scheduler_whose_host_name_lookup_hangs_is_reported_within_the_probe_time(monkeypatch):
    """A socket's timeout does not bound the host name's lookup; the probe as a whole does."""
    from peano_bayes.app import fanout

    def slow_lookup(*args, **kwargs):
        time.sleep(30)
        raise socket.gaierror("lookup gave up")

    monkeypatch.setattr(socket, "getaddrinfo", slow_lookup)
    start = time.perf_counter()
    with pytest.raises(PeanoBayesError, match=r"tcp://head.invalid:8786 \(no answer within 0.5 s\)"):
        fanout._check_reachable("tcp://head.invalid:8786", timeout_s=0.5)
    assert time.perf_counter() - start < 5


def test_two_jobs_share_two_worker_processes():
    """Two jobs: four units on two spawned workers, which serve them all (the pool keeps its workers)."""
    units = [Unit(k, _square, (i,)) for i, k in enumerate("abcd")]
    with make_executor(None, 2) as (executor, info):
        kept = run_units(units, executor, log=lambda m: None)
    assert info.kind == "processes" and [o.value for o in kept] == [0, 1, 4, 9] and len({o.worker for o in kept}) <= 2
    assert os.getpid() not in {int(o.worker.rsplit(":", 1)[1]) for o in kept}


def test_processes_run_one_jobs_units_in_one_worker_that_ends_with_the_block():
    """``processes=True`` with one job: the units run in one spawned worker, not here, and the next block gets a
    new worker (how the discovery benchmark recycles its workers every batch of runs)."""
    units = [Unit(k, _square, (i,)) for i, k in enumerate("abc")]
    workers = []
    for _ in range(2):
        with make_executor(None, 1, processes=True) as (executor, info):
            outcomes = run_units(units, executor, log=lambda m: None)
        assert info.kind == "processes" and [o.value for o in outcomes] == [0, 1, 4]
        workers.append({o.worker for o in outcomes})
    assert all(len(w) == 1 for w in workers) and workers[0] != workers[1]
    assert os.getpid() not in {int(w.rsplit(":", 1)[1]) for ws in workers for w in ws}


def test_worker_environment_adds_the_thread_flags_once(monkeypatch):
    """A worker started by a capped process gets the same XLA flags, not the one-thread flags twice (JAX's
    persistent cache keys on the flag list: a repeated flag would give the worker's programs other keys)."""
    from peano_bayes.app.fanout import ONE_THREAD_XLA_FLAGS, _one_thread_env

    monkeypatch.delenv("XLA_FLAGS", raising=False)
    assert _one_thread_env()["XLA_FLAGS"] == ONE_THREAD_XLA_FLAGS
    monkeypatch.setenv("XLA_FLAGS", f"--xla_dump_to=/tmp/x {ONE_THREAD_XLA_FLAGS}")
    assert _one_thread_env()["XLA_FLAGS"] == f"--xla_dump_to=/tmp/x {ONE_THREAD_XLA_FLAGS}"
    monkeypatch.setenv("XLA_FLAGS", "--xla_dump_to=/tmp/x")
    flags = _one_thread_env()["XLA_FLAGS"].split()
    assert flags == ["--xla_dump_to=/tmp/x", *ONE_THREAD_XLA_FLAGS.split()]
    assert _one_thread_env()["OMP_NUM_THREADS"] == "1"


def test_the_command_line_refuses_a_bad_scheduler_before_anything_runs(tmp_path):
    env = {**os.environ, "PEANO_BAYES_SCHEDULER": "somewhere"}
    out = tmp_path / "r"
    done = subprocess.run(
        [sys.executable, "-m", "peano_bayes", "run", "--out", str(out)], capture_output=True, text=True, env=env
    )
    assert done.returncode == 2 and "Traceback" not in done.stderr
    assert "scheduler 'somewhere' is not understood" in done.stderr and "$PEANO_BAYES_SCHEDULER" in done.stderr
    assert not out.exists()


# --- two real units on a Dask LocalCluster, one worker killed mid-unit -----------------------------------------

# The settings and data shapes of the walkthrough notebook's fast fit (two load cycles of one TP specimen, two
# least-squares starts, 18 walkers, the shape constants held, Table 3 metrics from 8 draws) and, in the SBC unit,
# of test_calibration's replicates: one xdist group runs the three in one worker one after another, so each
# program compiles once and the others read it from the persistent cache.
FIT = dict(
    tests=("load_cycle",), n_starts=2, n_walkers=18, n_ensembles=2, chunk=40, max_steps=120, warmup=80, seed=4,
    sample_all=False,
)  # fmt: skip


def _data(tmp_path):
    from peano_bayes.data import save
    from peano_bayes.rig import simulate_dataset

    data = tmp_path / "TP.csv"
    if not data.exists():
        save(simulate_dataset("TP", None, seed=5, specimens=1, repeats=1, tests=("load_cycle",)), data)
    return data


def _other_units():
    """A unit of another kind beside the fit: an SBC replicate (the seam does not care which function a unit runs;
    one of each kind that the studies send keeps the test's cost down: a discovery run adds 40 s per process)."""
    from peano_bayes.validation.sbc import replicate_unit

    return [Unit("sbc", replicate_unit, (3,), dict(seed=20261126, n_walkers=8, warmup=40, chunk=40, max_steps=80))]


def _fit_args(data, out, max_steps):
    """The command line of the same fit as :data:`FIT` (figures are drawn once, by report_results)."""
    return [
        "fit", str(data), "--out", str(out), "--tests", "load_cycle", "--starts", "2", "--walkers", "18",
        "--ensembles", "2", "--chunk", "40", "--max-steps", str(max_steps), "--warmup", "80", "--seed", "4",
        "--no-sample-all", "--no-progress", "--no-figures", "--json",
    ]  # fmt: skip


@pytest.mark.slow
@pytest.mark.xdist_group("short_tp_fits")
def test_units_on_a_dask_cluster_survive_a_killed_worker_and_equal_a_serial_run(tmp_path, capsys):
    """fit-many sends a short fit to a two-worker LocalCluster while an SBC replicate goes to the same cluster
    through the seam. The worker running the fit is killed after its first saved chunk: nothing is
    half-written, Dask re-runs the unit on another worker, and it resumes from that chunk. Everything
    completes, and every number equals a serial run with the same seeds in this process: the fit by the
    command line's ``main`` (which then continues with a larger step limit and feeds the main job's report),
    and the replicate. The workers read the programs the serial run compiled from the persistent cache: the
    suite's processes run with the workers' one-thread XLA flags (``tests/conftest.py``), which the cache keys
    on."""
    pytest.importorskip("distributed")
    import arviz as az

    from peano_bayes.app.batch import fit_many, report_results
    from peano_bayes.inference.sample import load_state

    data = _data(tmp_path)
    cluster_out, serial_out = tmp_path / "cluster", tmp_path / "serial"
    state = cluster_out / "TP" / "sampler_state.npz"
    found: dict = {}

    # The serial fit: the command line, uninterrupted. Exit 3: finished unconverged (2 ensembles never certify).
    # In this process (not a subprocess), so the resumed fit and the report below reuse its traced programs.
    capsys.readouterr()
    code = main(_fit_args(data, serial_out, 120))
    done = capsys.readouterr()
    assert code == 3, done.out[-2000:] + done.err[-2000:]
    report = json.loads(done.out)  # --json: stdout holds the JSON object alone, the log goes to stderr
    assert report["steps"] == 120 and not report["converged"]
    serial = run_units(_other_units(), None)  # the replicate, in this process
    assert all(o.ok for o in serial), [o.error for o in serial]

    with make_executor("local:2") as (executor, info):
        assert info.kind == "dask-local" and info.workers == 2
        quiet = dict(progress=False, figures=False, log=lambda m: None)
        threads = [
            threading.Thread(
                target=lambda: found.update(fit=fit_many([data], cluster_out, scheduler=info.address, **FIT, **quiet))
            ),
            threading.Thread(target=lambda: found.update(others=run_units(_other_units(), executor))),
        ]
        for thread in threads:
            thread.start()
        deadline = time.time() + 600
        while not state.exists() and threads[0].is_alive() and time.time() < deadline:
            time.sleep(0.2)
        assert state.exists(), "the fit never saved a chunk"
        unit_log = cluster_out / "logs" / "TP.log"
        pid = int(unit_log.read_text().splitlines()[0].rsplit(":", 1)[1])
        saved = load_state(state)[0].shape[0]  # steps the killed worker had saved (at least)
        os.kill(pid, signal.SIGKILL)  # the worker running the fit, mid-unit: its nanny starts a new one
        assert not (cluster_out / "TP" / "summary.json").exists() and not (cluster_out / "TP" / "posterior.nc").exists()
        for thread in threads:
            thread.join(timeout=900)
        assert not any(thread.is_alive() for thread in threads)
    assert [s["label"] for s in found["fit"]] == ["TP"]
    assert [o.key for o in found["others"]] == ["sbc"]
    assert all(o.ok for o in found["others"]), [o.error for o in found["others"]]
    started = [line for line in unit_log.read_text().splitlines() if ": started on " in line]
    assert len(started) == 2 and started[0] != started[1]  # run twice, on two worker processes
    summary = json.loads((cluster_out / "TP" / "summary.json").read_text())
    assert 0 < saved <= summary["resumed_from_step"] < 120 == summary["steps"]  # continued from its last chunk
    provenance = json.loads((cluster_out / "provenance.json").read_text())
    assert provenance["executor"]["kind"] == "dask" and provenance["executor"]["address"] == info.address
    assert provenance["units"]["TP"]["worker"] == started[1].rsplit(" ", 1)[1]  # the worker that finished it
    assert provenance["seed"] == 4 and provenance["packages"]["distributed"]

    cluster_draws = az.from_netcdf(cluster_out / "TP" / "posterior.nc").posterior
    serial_draws = az.from_netcdf(serial_out / "TP" / "posterior.nc").posterior
    assert set(cluster_draws.data_vars) == set(serial_draws.data_vars)
    for name in serial_draws.data_vars:
        np.testing.assert_allclose(cluster_draws[name], serial_draws[name], rtol=1e-9, atol=0, err_msg=name)

    # An unconverged run keeps its state, and a larger step limit continues the same chain.
    serial_state = serial_out / "TP" / "sampler_state.npz"
    assert serial_state.exists()
    code = main([*_fit_args(data, serial_out, 160), "--resume"])
    extended = capsys.readouterr()
    assert code in (0, 3), extended.out[-2000:] + extended.err[-2000:]
    assert json.loads(extended.out)["steps"] == 160
    assert f"resumed from {serial_state} at step 120" in extended.err
    summary = json.loads((serial_out / "TP" / "summary.json").read_text())
    assert summary["resumed_from_step"] == 120
    assert serial_state.exists() != summary["convergence"]["converged"]  # a converged run leaves none
    for test, q in summary["fit_quality_posterior_mean"].items():  # the fit's model discrepancy, beside its RMSE
        floor = q["noise_floor_rmse"]
        assert 0 < floor and q["excess_rmse"] == pytest.approx(np.sqrt(max(q["rmse"] ** 2 - floor**2, 0.0))), test
    # where each sampled parameter's posterior sits in its prior is recorded for every one of them
    assert set(summary["prior_z"]) == set(summary["contraction"]) and isinstance(summary["prior_conflicts"], list)
    # The result file: all six groups, provenance attrs, pointwise arrays aligned with the observed bins.
    idata = az.from_netcdf(serial_out / "TP" / "posterior.nc")
    for group in ("posterior", "sample_stats", "log_likelihood", "posterior_predictive", "observed_data", "prior"):
        assert group in idata.groups(), group
    attrs = idata.posterior.attrs
    assert attrs["seed"] == 4 and "emcee" in json.loads(attrs["package_versions"])
    assert "[parameters." in attrs["prior_text"] and "friction" in json.loads(attrs["model_config"])
    n_bins = idata.observed_data["y"].size
    assert idata.log_likelihood["y"].shape[-1] == n_bins == idata.posterior_predictive["y"].shape[-1]
    assert np.all(np.isfinite(idata.log_likelihood["y"].values))
    assert set(summary["timings_s"]) == {"least_squares_s", "compile_s", "sampling_s"}  # resumed: no mode search

    # The main job's report over the finished result: metrics, figures, ranking and index.md.
    ranking = report_results(serial_out, materials=("TP",), n_draws=8, log=lambda m: None)
    index = (serial_out / "index.md").read_text()
    assert "## TP" in index and "94 %" in index
    assert "Table 3 metrics" in index and "| hysteresis_loss |" in index
    for link in ("TP/figures/predictive.png", "TP/figures/corner.png", "figures/forest.png", "figures/ranking.png"):
        assert f"({link})" in index and (serial_out / link).exists(), link
    assert "## Ranking across materials" in index and ranking["materials"] == ["TP"]
    assert ("**Provisional for TP:**" in index) == (not summary["convergence"]["converged"])
    assert (serial_out / "TP" / "metrics.json").exists() and (serial_out / "ranking.json").exists()
    # The fit report puts the paper's reference models, fitted to the same load cycles, beside ours.
    reference = json.loads((serial_out / "TP" / "reference_models.json").read_text())
    assert "| Sarosi static, 12 coefficients |" in index and "| Veale force balance |" in index
    assert all(0.0 < reference[m]["quality"]["rmse"] < 50.0 for m in ("sarosi", "veale"))
    assert reference["veale"]["non_finite_bins"] == 0  # a non-finite bin would be scored as a force of 0 N

    # The replicate on the cluster equals the one in this process.
    rows = lambda outcomes: [{k: v for k, v in o.value.items() if k != "seconds"} for o in outcomes]  # noqa: E731
    assert rows(found["others"]) == rows(serial)

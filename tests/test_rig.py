"""The virtual rig: protocol, seeding, quirks, specimens, the file round trip and ``peano-bayes simulate``."""

import dataclasses
import json

import numpy as np
import pytest

from peano_bayes.app.cli import main
from peano_bayes.data import load, save
from peano_bayes.data.dataset import SIGNALS
from peano_bayes.errors import PeanoBayesInputError
from peano_bayes.materials import MATERIALS
from peano_bayes.physics import PARAMETERS, ModelConfig
from peano_bayes.rig import QUIRKS, RigNoise, apply_quirks, read_parameter_file, simulate_dataset

QUIET = RigNoise(0.0, 0.0, 0.0, 0.0, 0.0)
#: Parameters differing from the nominal ones, so that the test sees them used.
TRUE = {"tensile_ka_n_per_m": 3e4, "bending_k2_n": 12.0}


@pytest.fixture(scope="module")
def reduced():
    """FC, one specimen, one repeat of every test (the paper's protocol otherwise)."""
    return simulate_dataset("FC", TRUE, seed=7, specimens=1, repeats=1)


def assert_same_runs(a, b, rtol=0.0):
    assert [r.key for r in a.runs] == [r.key for r in b.runs]
    for ra, rb in zip(a.runs, b.runs, strict=True):
        for name in SIGNALS:
            va, vb = getattr(ra, name), getattr(rb, name)
            assert (va is None) == (vb is None), (ra.key, name)
            if va is not None:
                np.testing.assert_allclose(vb, va, rtol=rtol, atol=0.0, err_msg=f"{ra.key} {name}")


def by_key(dataset):
    return {r.key: r for r in dataset.runs}


def test_protocol_of_one_specimen(reduced):
    spec = MATERIALS["FC"]
    assert reduced.material.code == "FC" and reduced.conditions == spec.conditions()
    keys = [r.key for r in reduced.runs]
    assert keys == [("A", t, n) for t, n in (("load_cycle", 0), ("load_cycle", 1), ("blocking", 0), ("stroke", 0),
                                             ("step", 0))]  # fmt: skip
    runs = by_key(reduced)
    cycle_0, cycle_p = runs["A", "load_cycle", 0], runs["A", "load_cycle", 1]
    assert np.mean(cycle_0.pressure_pa) == pytest.approx(0.0, abs=100.0)  # 500 Pa noise over 801 samples
    assert np.mean(cycle_p.pressure_pa) == pytest.approx(spec.test_pressure_pa, abs=100.0)
    for run in (cycle_0, cycle_p, runs["A", "blocking", 0], runs["A", "stroke", 0]):
        np.testing.assert_allclose(np.diff(run.time_s), 0.05, rtol=1e-9)  # 20 Hz
    np.testing.assert_allclose(np.diff(runs["A", "step", 0].time_s), 1e-3, rtol=1e-9)  # 1 kHz
    assert cycle_p.duration_s == pytest.approx(40.0) and len(runs["A", "step", 0]) == 801
    # pressurized cycle: stretched to -1.5 % at mid-cycle; starts near the start tension (force noise 0.2 N)
    assert cycle_p.strain[400] == pytest.approx(-0.015, abs=1e-3)
    assert cycle_p.force_n[0] == pytest.approx(spec.start_tension_n, abs=1.0)
    step, stroke = runs["A", "step", 0], runs["A", "stroke", 0]
    assert np.all(np.isnan(step.force_n)) and np.all(np.isnan(stroke.force_n))
    assert np.all(step.load_n == spec.step_load_n) and np.all(stroke.load_n == 5.5)
    assert step.supply_pa[-1] == pytest.approx(spec.test_pressure_pa, abs=3e3)
    assert np.max(step.flow_m3_per_s) > 1e-6  # water flows in: more than 1 mL/s at the peak
    assert np.all(np.isnan(cycle_p.flow_m3_per_s)) and np.all(np.isnan(cycle_p.supply_pa))


def test_noise_free_protocol_is_the_physics():
    quiet = by_key(simulate_dataset("TP", seed=1, specimens=1, repeats=1, noise=QUIET, tests=["load_cycle"]))
    start = quiet["A", "load_cycle", 1]
    assert start.force_n[0] == pytest.approx(MATERIALS["TP"].start_tension_n, abs=1e-6)
    assert start.strain[400] == pytest.approx(-0.015, abs=1e-12)
    # back to its start to round-off (a few ulp, by compiler level and CPU: tests/conftest.py)
    assert start.strain[-1] == pytest.approx(start.strain[0], rel=4e-16, abs=0)
    assert np.all(start.pressure_pa == 30e3)


def test_save_load_round_trip(reduced, tmp_path):
    path = save(reduced, tmp_path / "FC.csv")
    back = load(path)
    assert_same_runs(reduced, back, rtol=1e-12)
    assert back.conditions == reduced.conditions and back.material == reduced.material
    assert dict(back.provenance) == dict(reduced.provenance)


def test_provenance_records_the_truth(reduced):
    prov = reduced.provenance
    assert prov["synthetic"] == "true" and prov["seed"] == "7" and prov["quirks"] == "none"
    params = json.loads(prov["parameters"])
    assert params["tensile_ka_n_per_m"] == 3e4 and params["length_fraction"] == PARAMETERS["length_fraction"].nominal
    assert "tensile_ka_n_per_m" not in prov["nominal_fallback"] and "length_fraction" in prov["nominal_fallback"]
    assert set(json.loads(prov["specimen_parameters"])) == {"A"}
    assert json.loads(prov["protocol"])["step_rate_hz"] == 1000.0
    assert prov["ignored_parameters"] == "none"
    unused = simulate_dataset("FC", {"mount_compliance_m_per_n": 1e-5}, specimens=1, repeats=1, tests=["blocking"])
    assert unused.provenance["ignored_parameters"] == "mount_compliance_m_per_n"  # the default config has no mount


def test_same_seed_same_bytes_other_seed_differs(reduced, tmp_path):
    again = simulate_dataset("FC", TRUE, seed=7, specimens=1, repeats=1)
    assert_same_runs(reduced, again)
    a, b = save(reduced, tmp_path / "a.csv"), save(again, tmp_path / "b.csv")
    assert a.read_bytes() == b.read_bytes()
    assert a.with_suffix(".toml").read_bytes() == b.with_suffix(".toml").read_bytes()
    other = simulate_dataset("FC", TRUE, seed=8, specimens=1, repeats=1)
    for ra, rb in zip(reduced.runs, other.runs, strict=True):
        assert not np.array_equal(ra.strain, rb.strain), ra.key


def test_repeats_differ_by_noise_only():
    noisy = simulate_dataset("FC", seed=3, specimens=1, repeats=2, tests=["blocking"])
    quiet = simulate_dataset("FC", seed=3, specimens=1, repeats=2, tests=["blocking"], noise=QUIET)
    r0, r1 = noisy.runs
    assert not np.array_equal(r0.force_n, r1.force_n)
    assert np.std(r0.force_n - r1.force_n) == pytest.approx(0.2 * np.sqrt(2), rel=0.15)  # two 0.2 N noises
    q0, q1 = quiet.runs
    np.testing.assert_array_equal(q0.force_n, q1.force_n)
    np.testing.assert_allclose(r0.force_n, q0.force_n, atol=1.0)  # the noise is 0.2 N
    # a smaller run reproduces the matching part of a larger one
    single = simulate_dataset("FC", seed=3, specimens=1, repeats=1, tests=["blocking"])
    np.testing.assert_array_equal(single.runs[0].force_n, r0.force_n)


def test_drift_grows_through_the_session():
    """With every other noise off, the drifted force minus the plain one is the drift rate times the time since
    the session began: each run's own time plus the durations of the runs before it (runs start at 0 s)."""
    rate = 0.002
    kwargs = dict(seed=3, specimens=1, repeats=2, tests=["blocking"])
    plain = simulate_dataset("FC", noise=QUIET, **kwargs)
    drifted = simulate_dataset("FC", drift=True, noise=dataclasses.replace(QUIET, force_drift_n_per_s=rate), **kwargs)
    offset_s = 0.0
    for p, d in zip(plain.runs, drifted.runs, strict=True):
        assert p.time_s[0] == 0.0
        np.testing.assert_allclose(d.force_n - p.force_n, rate * (offset_s + p.time_s), rtol=1e-12, atol=1e-9)
        offset_s += p.duration_s
    assert rate * offset_s > 0.05  # the drift over the session is large enough to be seen above atol
    assert drifted.provenance["drift"] == "true"


def test_specimens_differ():
    both = simulate_dataset("FC", seed=5, specimens=2, repeats=1, tests=["blocking"], noise=QUIET)
    a, b = both.runs
    assert (a.specimen, b.specimen) == ("A", "B")
    assert abs(a.force_n[-1] - b.force_n[-1]) > 0.5  # N, far above noise
    params = json.loads(both.provenance["specimen_parameters"])
    assert params["A"]["tensile_ka_n_per_m"] != params["B"]["tensile_ka_n_per_m"]
    assert params["A"]["length_fraction"] == params["B"]["length_fraction"]  # not stiffness-like
    same = simulate_dataset("FC", seed=5, specimens=2, repeats=1, tests=["blocking"], noise=QUIET, specimen_spread=0)
    np.testing.assert_array_equal(same.runs[0].force_n, same.runs[1].force_n)


def test_specimen_values_set_each_specimens_own_parameters():
    kwargs = dict(seed=5, specimens=2, repeats=1, tests=["blocking"], noise=QUIET, specimen_spread=0)
    own = simulate_dataset(
        "FC", {"tensile_ka_n_per_m": 3e4}, specimen_values=[{}, {"tensile_ka_n_per_m": 2e4}], **kwargs
    )
    params = json.loads(own.provenance["specimen_parameters"])
    assert (params["A"]["tensile_ka_n_per_m"], params["B"]["tensile_ka_n_per_m"]) == (3e4, 2e4)
    # specimen B is, signal for signal, a one-specimen session of its own value
    alone = simulate_dataset("FC", {"tensile_ka_n_per_m": 2e4}, **{**kwargs, "specimens": 1})
    np.testing.assert_array_equal(own.runs[1].force_n, alone.runs[0].force_n)
    assert not np.array_equal(own.runs[0].force_n, own.runs[1].force_n)
    with pytest.raises(PeanoBayesInputError, match=r"one mapping per specimen \(2\), got 1"):
        simulate_dataset("FC", specimen_values=[{}], **kwargs)
    with pytest.raises(PeanoBayesInputError, match=r"specimen_values\[1\]: parameter 'bending_k1_n'.*bounds"):
        simulate_dataset("FC", specimen_values=[{}, {"bending_k1_n": -1.0}], **kwargs)
    # the default model has no mount: a value for it would be silently unused
    with pytest.raises(PeanoBayesInputError, match=r"specimen_values\[0\]: .*does not read 'mount_compliance_m_per_n'"):
        simulate_dataset("FC", specimen_values=[{"mount_compliance_m_per_n": 1e-6}, {}], **kwargs)


def test_series_compliance_lowers_blocking_force():
    kwargs = dict(seed=2, specimens=1, repeats=1, tests=["blocking"])
    stiff = simulate_dataset("FC", **kwargs).runs[0]
    compliant = simulate_dataset("FC", {"mount_compliance_m_per_n": 2e-5}, quirks=["series_compliance"], **kwargs)
    assert compliant.provenance["quirks"] == "series_compliance"
    assert json.loads(compliant.provenance["config"])["mount"] is True
    final_stiff, final_compliant = np.mean(stiff.force_n[-20:]), np.mean(compliant.runs[0].force_n[-20:])
    assert final_compliant < 0.95 * final_stiff
    fallback = simulate_dataset("FC", quirks=["series_compliance"], **kwargs).provenance
    assert "mount_compliance_m_per_n" in fallback["nominal_fallback"].split(", ")
    nominal = PARAMETERS["mount_compliance_m_per_n"].nominal
    assert json.loads(fallback["parameters"])["mount_compliance_m_per_n"] == nominal


def test_quirks_switch_elements_and_fall_back_to_nominal():
    config = apply_quirks(ModelConfig(friction="none", extension=False), list(QUIRKS))
    assert config.mount and config.friction == "parallel" and config.parallel_maxwell == 1
    assert config.extension and config.threshold and config.damping
    with pytest.raises(PeanoBayesInputError, match=r"unknown quirk 'hysterisis' \(did you mean 'hysteresis'\?\)"):
        simulate_dataset("FC", quirks=["hysterisis"])
    with pytest.raises(PeanoBayesInputError, match=r"no such element yet\); known quirks: hysteresis, viscoelastic"):
        simulate_dataset("FC", quirks=["cyclic_softening"])


def test_bad_inputs_are_refused_before_simulating():
    with pytest.raises(PeanoBayesInputError, match=r"did you mean 'tensile_ka_n_per_m'"):
        simulate_dataset("FC", {"tensile_ka_n_per_mm": 1e4})
    with pytest.raises(PeanoBayesInputError, match="outside its physical bounds"):
        simulate_dataset("FC", {"tensile_ka_n_per_m": -1.0})
    with pytest.raises(PeanoBayesInputError, match="did you mean 'PC'"):
        simulate_dataset("PCX")
    with pytest.raises(PeanoBayesInputError, match="repeats"):
        simulate_dataset("FC", repeats=0)
    with pytest.raises(PeanoBayesInputError, match="did you mean 'stroke'"):
        simulate_dataset("FC", tests=["strok"])


def test_parameter_file(tmp_path):
    path = tmp_path / "p.toml"
    path.write_text("[parameters]\ntensile_ka_n_per_m = 3e4\nbending_k2_n = 12\n[config]\nmount = true\n")
    params, config = read_parameter_file(path)
    assert params == {"tensile_ka_n_per_m": 3e4, "bending_k2_n": 12.0} and config.mount
    path.write_text('[config]\nfriction = "dahl"\n')
    with pytest.raises(PeanoBayesInputError, match="friction"):
        read_parameter_file(path)
    path.write_text("[paramaters]\nx = 1\n")
    with pytest.raises(PeanoBayesInputError, match=r"did you mean \[parameters\]"):
        read_parameter_file(path)


# --- the command line -----------------------------------------------------------------------------------------


def test_cli_simulate_writes_a_dataset(tmp_path, capsys, reduced):
    params = tmp_path / "params.toml"
    params.write_text("[parameters]\ntensile_ka_n_per_m = 3e4\nbending_k2_n = 12.0\n")
    out = tmp_path / "sim" / "FC.csv"
    argv = ["simulate", "--material", "FC", "--params", str(params), "--out", str(out), "--seed", "7"]
    assert main([*argv, "--specimens", "1", "--repeats", "1", "--json"]) == 0
    captured = capsys.readouterr()
    summary = json.loads(captured.out)  # stdout holds the JSON object alone; progress goes to stderr
    assert summary["csv"] == str(out) and summary["runs"] == 5 and summary["seed"] == 7
    assert "simulated A: step" in captured.err
    assert_same_runs(reduced, load(out), rtol=1e-12)  # the CLI is simulate_dataset + save


@pytest.mark.parametrize(
    ("extra", "params_text", "message"),
    [
        (["--quirk", "series_complience"], "", "did you mean 'series_compliance'"),
        (["--material", "FCC"], "", "unknown material code 'FCC'"),
        ([], "[parameters]\ntensile_k = 1e4\n", "unknown parameter 'tensile_k'"),
        ([], "", "exists"),
    ],
)
def test_cli_simulate_bad_input(tmp_path, capsys, extra, params_text, message):
    params = tmp_path / "params.toml"
    params.write_text(params_text)
    out = tmp_path / "out" / "FC.csv"
    if message == "exists":  # an existing dataset is not replaced without --force
        out.parent.mkdir()
        out.with_suffix(".toml").write_text("kept")
    argv = ["simulate", "--material", "FC", "--params", str(params), "--out", str(out), *extra]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err and err.startswith("peano-bayes simulate: error:")
    assert not out.exists() and out.with_suffix(".toml").exists() == (message == "exists")
    if message == "exists":
        assert out.with_suffix(".toml").read_text() == "kept"


# --- the same protocol on Veale's force-balance model ----------------------------------------------------------


def test_veale_rig_runs_the_protocol_on_the_other_physics(tmp_path):
    """Noise-free, one specimen: each load cycle starts at the start tension and stretches to the protocol's
    strain, the stroke strain is where the muscle carries the hanging load, and the blocking force ends at
    Veale's blocking force at the test pressure; the file round trip keeps everything."""
    import jax

    from peano_bayes.physics.reference import VEALE_TABLE2, veale_force
    from peano_bayes.rig import DEFAULT_PROTOCOL, simulate_veale_dataset

    force = jax.jit(veale_force)  # one compiled program, not an op-by-op root find per call

    spec = MATERIALS["TP"]
    quiet = simulate_veale_dataset("TP", seed=1, noise=QUIET, specimen_spread=0.0, specimens=1, repeats=1)
    assert quiet.tests == ("load_cycle", "blocking", "stroke") and "Veale" in quiet.provenance["source"]
    runs = by_key(quiet)
    for number in (0, 1):
        cycle = runs[("A", "load_cycle", number)]
        assert cycle.force_n[0] == pytest.approx(spec.start_tension_n, abs=1e-6)
        assert cycle.strain.min() == pytest.approx(DEFAULT_PROTOCOL.stretch_strain, abs=1e-12)
        assert np.all(np.diff(cycle.force_n[: len(cycle) // 2]) > 0)  # stretching raises the force
    stroke = runs[("A", "stroke", 0)]
    carried = np.asarray(force(stroke.pressure_pa, stroke.strain, VEALE_TABLE2))
    np.testing.assert_allclose(carried, DEFAULT_PROTOCOL.stroke_load_n, rtol=0, atol=1e-6)
    assert np.all(np.diff(stroke.strain) > 0)  # more pressure, more contraction under the same load
    blocking = runs[("A", "blocking", 0)]
    assert blocking.force_n[-1] == pytest.approx(float(force(spec.test_pressure_pa, 0.0, VEALE_TABLE2)), rel=1e-12)

    noisy = simulate_veale_dataset("TP", seed=2, specimens=2, repeats=2)
    assert_same_runs(noisy, load(save(noisy, tmp_path / "veale")), rtol=1e-12)
    specimens = json.loads(noisy.provenance["specimen_parameters"])
    assert specimens["A"]["tensile_ka_n_per_m"] != specimens["B"]["tensile_ka_n_per_m"]
    assert specimens["A"]["linkage_m"] == specimens["B"]["linkage_m"] == float(VEALE_TABLE2.linkage_m)


def test_veale_rig_refuses_a_step_test_before_simulating():
    from peano_bayes.rig import simulate_veale_dataset

    with pytest.raises(PeanoBayesInputError, match="static and cannot run a step test"):
        simulate_veale_dataset("TP", tests=("load_cycle", "step"))
    with pytest.raises(PeanoBayesInputError, match="specimen_spread"):
        simulate_veale_dataset("TP", specimen_spread=2.0)


def test_veale_rig_runs_load_cycles_at_the_pressures_asked_and_refuses_others():
    from peano_bayes.rig import simulate_veale_dataset

    pressures = (100e3, 300e3, 500e3)
    data = simulate_veale_dataset("TPC", seed=3, noise=QUIET, specimens=1, repeats=2, tests=("load_cycle",),
                                  cycle_pressures_pa=pressures)  # fmt: skip
    runs = by_key(data)
    assert sorted(n for (_, _, n) in runs) == [0, 1, 2, 3, 4, 5]  # two repeats of each of three conditions
    for condition, p in enumerate(pressures):
        assert np.median(runs[("A", "load_cycle", 2 * condition)].pressure_pa) == pytest.approx(p, abs=1.0)
    assert "runs 4-5 at 500 kPa" in data.provenance["runs"]
    # more pressure, more force at the same start of the cycle (the muscle pulls harder)
    peaks = [runs[("A", "load_cycle", 2 * c)].force_n.max() for c in range(3)]
    assert peaks[0] < peaks[1] < peaks[2]
    for bad in ((), (-1.0,), (2e6,), (float("nan"),)):
        with pytest.raises(PeanoBayesInputError, match="cycle_pressures_pa must be one or more pressures"):
            simulate_veale_dataset("TPC", tests=("load_cycle",), cycle_pressures_pa=bad)

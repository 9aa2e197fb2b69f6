"""Design recommendation: parameter scaling with geometry is exact where it must be, the spec reader refuses
bad and impossible requirements with the key named, and candidates are scored monotonically."""

import json
import math
import shutil
from types import SimpleNamespace

import arviz as az
import jax.numpy as jnp
import numpy as np
import pytest

from peano_bayes.analysis.recommend import (
    limit_violations,
    load_spec,
    material_limits,
    new_specimen_draws,
    recommend,
    recommendation_markdown,
    thickness_m,
    wall_thickness_m,
)
from peano_bayes.app.cli import main
from peano_bayes.errors import PeanoBayesInputError
from peano_bayes.physics import DEFAULT_CONFIG, PAPER_GEOMETRY, Geometry, scale_parameters, static_force, static_strain

from .helpers import minimal_summary

# One xdist worker runs this group, so the session fixture `recovered` (a fit and a sampling run) is built once.
pytestmark = pytest.mark.xdist_group("recovered")

NOMINAL = {k: jnp.asarray(v) for k, v in DEFAULT_CONFIG.nominal_parameters().items()}


def test_static_force_inverts_static_strain():
    strain = static_strain(NOMINAL, 2e5, 40.0)
    assert float(static_force(NOMINAL, 2e5, strain)) == pytest.approx(40.0, rel=1e-9)


@pytest.mark.parametrize("strain", [0.0, 0.05, 0.12])
def test_force_scales_with_tube_length_and_not_with_tube_count(strain):
    base = float(static_force(NOMINAL, 2e5, strain))
    longer = Geometry(tube_length_m=2 * PAPER_GEOMETRY.tube_length_m)
    more = Geometry(n_tubes=7)
    f_long = static_force(scale_parameters(NOMINAL, PAPER_GEOMETRY, longer), 2e5, strain, geometry=longer)
    f_more = static_force(scale_parameters(NOMINAL, PAPER_GEOMETRY, more), 2e5, strain, geometry=more)
    assert float(f_long) == pytest.approx(2 * base, rel=1e-9)
    assert float(f_more) == pytest.approx(base, rel=1e-9)


def test_scaling_to_the_same_geometry_is_the_identity():
    assert scale_parameters(NOMINAL, PAPER_GEOMETRY, Geometry()) == NOMINAL


def _spec(tmp_path, requirement: str, candidates: str = "", name="spec.toml"):
    path = tmp_path / name
    path.write_text(f"[requirement]\n{requirement}\n" + (f"[candidates]\n{candidates}\n" if candidates else ""))
    return path


GOOD = "force_n = 10.0\ncontraction = 0.05\nmax_pressure_kpa = 30\n"  # TP was tested at 30 kPa


@pytest.mark.parametrize(
    ("requirement", "expected"),
    [
        ("contraction = 0.05\nmax_pressure_kpa = 100", "missing 'force_n'"),
        (GOOD + "force_nn = 3", "unknown key 'force_nn' (did you mean 'force_n'?)"),
        (GOOD.replace("0.05", "0.4"), "contraction: impossible: 0.4 asked"),
        (GOOD.replace("10.0", "-1"), "force_n: expected a positive number, got -1"),
        (GOOD.replace("10.0", '"ten"'), "force_n: expected a finite number, got 'ten'"),
        (GOOD + "max_hysteresis = 2", "max_hysteresis: expected a fraction in (0, 1], got 2"),
        (GOOD + "max_response_time_s = 0", "max_response_time_s: expected a positive number, got 0"),
        (GOOD.replace("= 30", "= 5000"), "expected at most 1000 kPa"),
    ],
)
def test_bad_requirements_are_refused_with_the_key_named(tmp_path, requirement, expected):
    with pytest.raises(PeanoBayesInputError, match="spec.toml") as err:
        load_spec(_spec(tmp_path, requirement))
    assert expected in str(err.value)


def test_bad_candidates_are_refused(tmp_path):
    with pytest.raises(PeanoBayesInputError, match=r"n_tubes: expected whole numbers of tubes >= 1, got 0"):
        load_spec(_spec(tmp_path, GOOD, "n_tubes = [4, 0]"))
    with pytest.raises(PeanoBayesInputError, match="unknown key 'tube_widths_mm'"):
        load_spec(_spec(tmp_path, GOOD, "tube_widths_mm = [15]"))
    bad_dir = tmp_path / "dir.toml"
    bad_dir.write_text(f"[requirement]\n{GOOD}[results]\ndir = 5\n")
    with pytest.raises(PeanoBayesInputError, match=r"dir.toml \[results\] dir: expected a folder path"):
        load_spec(bad_dir)
    with pytest.raises(PeanoBayesInputError, match=r"none.toml: no such spec file; expected a design spec TOML"):
        load_spec(tmp_path / "none.toml")


@pytest.fixture(scope="module")
def results(result_dir, tmp_path_factory):
    root = tmp_path_factory.mktemp("results")
    shutil.copytree(result_dir, root / "TP")
    return root


def test_more_force_or_less_room_never_raises_the_probability(results, tmp_path):
    grid = "n_tubes = [4]\ntube_width_mm = [15]\ntube_length_mm = [30, 49.5, 80]\n"
    easy = recommend(_spec(tmp_path, GOOD, grid, "easy.toml"), results, log=lambda m: None)
    hard = recommend(_spec(tmp_path, GOOD.replace("10.0", "60.0"), grid, "hard.toml"), results, log=lambda m: None)
    tight = recommend(_spec(tmp_path, GOOD + "max_width_mm = 50\n", grid, "tight.toml"), results, log=lambda m: None)
    p = lambda report: {c["tube_length_mm"]: c["probability"] for c in report["candidates"]}  # noqa: E731
    for length in (30.0, 49.5, 80.0):
        assert p(hard)[length] <= p(easy)[length]
    assert p(tight)[80.0] == 0.0 and p(tight)[30.0] == p(easy)[30.0]
    assert next(c for c in tight["candidates"] if c["tube_length_mm"] == 80.0)["binding"] == "width"
    # longer tubes give more force at the same strain, so under the hard requirement they rank first
    assert hard["candidates"][0]["tube_length_mm"] == 80.0
    assert hard["candidates"][0]["force_median_n"] > hard["candidates"][-1]["force_median_n"]
    assert hard["explanation"].startswith("TP with 4 tubes of 15 x 80 mm meets every requirement")
    for report in (easy, hard):  # the advice to relax the requirement comes exactly when the best is unlikely
        assert ("No candidate of the grid" in report["explanation"]) == (report["candidates"][0]["probability"] < 0.5)


def test_recommend_command_writes_outputs_and_refuses_a_bad_spec(results, tmp_path, capsys):
    spec = _spec(tmp_path, GOOD, "n_tubes = [3, 4]\n")
    assert main(["recommend", "--spec", str(spec), "--results", str(results), "--json"]) == 0
    report = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert len(report["candidates"]) == 2
    for ext in ("json", "md", "png", "pdf"):
        assert (tmp_path / f"spec_recommendation.{ext}").stat().st_size > 0
    bad = _spec(tmp_path, GOOD.replace("0.05", "0.5"), name="bad.toml")
    out = tmp_path / "never"
    assert main(["recommend", "--spec", str(bad), "--results", str(results), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "impossible" in err and "Traceback" not in err and not out.exists()


def test_response_time_is_contraction_over_step_speed_and_flagged_when_from_the_prior(results, tmp_path):
    root = tmp_path / "with_metrics"
    shutil.copytree(results, root)
    n = 40
    # Speeds of 0.03 m/s in half the draws and 0.01 m/s in the other half; l0 of the result's geometry.
    speed = [0.03] * (n // 2) + [0.01] * (n // 2)
    metrics = {"material": "TP", "draw_values": {"speed": speed}, "summary": {"speed": {"from_prior": True}}}
    (root / "TP" / "metrics.json").write_text(json.dumps(metrics))
    from peano_bayes.analysis.recommend import _result_geometry
    from peano_bayes.inference.results import load_result

    l0 = float(_result_geometry(load_result(root / "TP")).flat_length_m)
    fast, slow = 0.05 * l0 / 0.03, 0.05 * l0 / 0.01  # response times [s] at contraction 0.05
    grid = "n_tubes = [4]\ntube_width_mm = [15]\ntube_length_mm = [80]\n"
    easy = GOOD.replace("10.0", "1.0")
    for bound, expected in ((1.01 * slow, 1.0), (0.5 * (fast + slow), 0.5), (0.99 * fast, 0.0)):
        spec = _spec(tmp_path, easy + f"max_response_time_s = {bound}\n", grid, f"r{expected}.toml")
        report = recommend(spec, root, log=lambda m: None)
        top = report["candidates"][0]
        assert top["p_each"]["response_time"] == pytest.approx(expected)
        assert "rests on the prior" in report["notes"][0] and "Note: response time" in recommendation_markdown(report)
    assert top["binding"] == "response_time"


def test_an_unconverged_material_makes_the_recommendation_provisional(results, tmp_path):
    root = tmp_path / "unconverged"
    shutil.copytree(results, root)
    spec = _spec(tmp_path, GOOD, "n_tubes = [4]\n")
    nc = root / "TP" / "posterior.nc"
    for converged in (1, 0):
        idata = az.from_netcdf(str(nc))
        idata.load()  # read everything before the file it came from is overwritten
        idata.posterior.attrs["converged"] = converged
        idata.to_netcdf(str(nc.with_suffix(".tmp")))
        nc.with_suffix(".tmp").replace(nc)
        notes = recommend(spec, root, log=lambda m: None)["notes"]
        assert any("the chains of TP did not converge" in n for n in notes) == (not converged)


def test_a_material_whose_model_misfits_says_so_in_the_recommendation(results, tmp_path):
    root = tmp_path / "misfit"
    shutil.copytree(results, root)
    spec = _spec(tmp_path, GOOD, "n_tubes = [4]\n")
    structured = {"consistent_with_noise": False, "likelihood_lag1": None}
    widths = {}
    for excess, expected in ((2.0, True), (0.0, False)):
        summary = minimal_summary(
            fit_quality_posterior_mean={"blocking": {"excess_rmse": excess}},
            residual_correlation={"blocking": structured},
        )
        (root / "TP" / "summary.json").write_text(json.dumps(summary))
        report = recommend(spec, root, log=lambda m: None)
        assert any("the model misfits TP's blocking test" in n for n in report["notes"]) == expected
        (top,) = report["candidates"]  # the result's own geometry at its tested pressure: the misfit as measured
        assert top["force_discrepancy_sd_n"] == (pytest.approx(2.0, rel=1e-12) if expected else None)
        widths[excess] = top["force_interval_n"][1] - top["force_interval_n"][0]
    # the 94 % interval widens by about the misfit's own 94 % (2 x 1.88 x 2 N), added in quadrature
    assert widths[2.0] > np.hypot(widths[0.0], 0.8 * 7.5)


def test_thickness_model_is_within_10_percent_of_the_papers_table_5_measurement():
    # Table 5: the fiberglass composite (FC) muscle, 4 tubes of 15 mm, is at most 13 mm thick.
    assert thickness_m(PAPER_GEOMETRY, "FC") == pytest.approx(0.013, rel=0.10)
    # The round-tube bound of thin walls (2w/pi = 9.5 mm) is 27 % short of it: the walls and the core's height count.
    assert thickness_m(PAPER_GEOMETRY) < 0.8 * 0.013
    # Sealed films have no internal height and thin walls; the composites' 3 mm core makes them thicker.
    assert thickness_m(PAPER_GEOMETRY, "TP") < thickness_m(PAPER_GEOMETRY, "P") < thickness_m(PAPER_GEOMETRY, "TFC")
    assert wall_thickness_m("VM") is None


def test_125_um_ldpe_is_refused_above_its_burst_pressure_and_materials_beyond_their_tested_pressure():
    reasons = limit_violations("P", 200e3)
    assert any("burst pressure of 100 kPa" in r for r in reasons)
    assert any("tested at" in r and "extrapolate" in r for r in reasons)
    assert limit_violations("FC", 200e3) == [] and limit_violations("P", 30e3) == []
    assert any("tested at" in r for r in limit_violations("FC", 250e3))
    # a material of one's own: limited by the test pressure of its result's data, refused where none is known
    assert "none is known" in limit_violations("VM", 100e3)[0]
    mine = SimpleNamespace(posterior=SimpleNamespace(attrs={"conditions": json.dumps({"test_pressure_pa": 1.5e5})}))
    assert limit_violations("VM", 150e3, mine) == []
    (reason,) = limit_violations("VM", 900e3, mine)
    assert "above the 150 kPa VM was tested at" in reason and "extrapolate" in reason


def test_a_spec_can_state_a_burst_pressure_and_the_lower_one_applies(tmp_path):
    """``[limits.CODE] burst_kpa`` in a spec: a user's material tested at 150 kPa and stated to burst at 120 kPa
    is refused at 130 kPa for the burst alone; P's stated 150 kPa does not lift the paper's 100 kPa."""
    path = _spec(tmp_path, GOOD, "[limits.VM]\nburst_kpa = 120\n[limits.P]\nburst_kpa = 150\n")
    spec = load_spec(path)
    assert spec.burst_kpa == {"VM": 120.0, "P": 150.0}
    mine = SimpleNamespace(posterior=SimpleNamespace(attrs={"conditions": json.dumps({"test_pressure_pa": 1.5e5})}))
    (reason,) = limit_violations("VM", 130e3, mine, spec.burst_kpa["VM"], str(path))
    assert f"above VM's burst pressure of 120 kPa (stated in {path})" in reason
    assert material_limits("VM", mine, 120.0, str(path))["max_tested_kpa"] == 150.0
    assert material_limits("P", None, 150.0)["burst_kpa"] == 100.0  # the paper's, lower
    for bad, message in (("[limits]\nVM = 3\n", "one table per material"),
                         ("[limits.VM]\nburst = 3\n", "unknown key 'burst'"),
                         ("[limits.VM]\nburst_kpa = -3\n", "burst_kpa: expected a positive number")):  # fmt: skip
        with pytest.raises(PeanoBayesInputError, match=message):
            load_spec(_spec(tmp_path, GOOD, bad, name="bad.toml"))


def test_a_candidate_beyond_its_materials_limit_is_infeasible_with_the_reason(results, tmp_path):
    spec = _spec(tmp_path, GOOD.replace("= 30", "= 100"), "n_tubes = [4]\ntube_width_mm = [15]\n")
    report = recommend(spec, results, log=lambda m: None)
    (top,) = report["candidates"]
    assert top["probability"] == 0.0 and "tested at" in top["infeasible"][0]
    assert "is infeasible" in report["explanation"]
    assert "Infeasible: TP:" in recommendation_markdown(report)


def test_a_users_material_above_the_pressure_its_data_were_tested_at_is_refused_and_its_limit_shown(results, tmp_path):
    """A material of one's own (no bundled limits): its limit is the test pressure of the data its result was
    fitted to; a spec above it gets no probability, the reason, and the limit in the report's ``limits``."""
    root = tmp_path / "mine"
    shutil.copytree(results / "TP", root / "VM")
    idata = az.from_netcdf(root / "VM" / "posterior.nc")
    idata.posterior.attrs["conditions"] = json.dumps({"test_pressure_pa": 20e3})
    idata.to_netcdf(str(root / "VM" / "posterior.nc.new"))
    (root / "VM" / "posterior.nc.new").replace(root / "VM" / "posterior.nc")
    spec = _spec(tmp_path, GOOD, "materials = ['VM']\nn_tubes = [4]\ntube_width_mm = [15]\n")
    report = recommend(spec, root, log=lambda m: None)
    assert report["limits"]["VM"]["max_tested_kpa"] == 20.0
    (top,) = report["candidates"]
    assert top["probability"] == 0.0 and "above the 20 kPa VM was tested at" in top["infeasible"][0]


def test_new_specimens_carry_the_between_specimen_spread_on_the_wall_stiffnesses_only():
    n = 4000
    sd = 0.2
    idata = az.from_dict(posterior={"specimen_log_sd": np.full((1, n), sd)})
    sets = [{"tensile_ka_n_per_m": 1000.0, "friction_force_n": 2.0}] * n
    drawn = new_specimen_draws(idata, sets, seed=3)
    log_factor = np.log(drawn["tensile_ka_n_per_m"] / 1000.0)
    assert abs(log_factor.mean()) < 4 * sd / np.sqrt(n) and log_factor.std() == pytest.approx(sd, rel=0.05)
    assert np.all(drawn["friction_force_n"] == 2.0)
    one = az.from_dict(posterior={"tensile_ka_n_per_m": np.ones((1, n))})  # a one-specimen fit has no spread
    assert np.all(new_specimen_draws(one, sets)["tensile_ka_n_per_m"] == 1000.0)


#: The ideal Peano muscle alone: no walls' stiffness, friction or viscosity.
IDEAL_MUSCLE = dict(bending=False, tensile=False, extension=False, mount=False, parallel_maxwell=0, series_kelvin=0,
                    friction="none", threshold=False, flow="orifice", damping=False)  # fmt: skip


def _ideal_muscle_result(root, length_fraction: np.ndarray) -> None:
    """``root/TP/posterior.nc``: a result of :data:`IDEAL_MUSCLE` whose draws are ``length_fraction`` (n,)."""
    n = len(length_fraction)
    idata = az.from_dict(posterior={"length_fraction": length_fraction[None], "orifice_area_m2": np.full((1, n), 5e-6)})
    attrs = dict(material="TP", model_config=json.dumps(IDEAL_MUSCLE), fixed_parameters="{}", converged=1)
    idata.posterior.attrs.update(attrs)
    (root / "TP").mkdir()
    idata.to_netcdf(str(root / "TP" / "posterior.nc"))


def _niiyama_force_n(pressure_pa: float, width_m: float, length_m, contraction: float):
    """Niiyama's virtual-work force of the ideal muscle, p w l cos(theta) / theta, theta solving
    1 - sin(theta) / theta = contraction, by bisection in plain Python [N]."""
    low, high = 1e-6, math.pi / 2  # 1 - sin(t)/t rises from 0 to 1 - 2/pi on (0, pi/2]
    for _ in range(200):
        mid = 0.5 * (low + high)
        low, high = (mid, high) if 1.0 - math.sin(mid) / mid < contraction else (low, mid)
    theta = 0.5 * (low + high)
    return pressure_pa * width_m * length_m * math.cos(theta) / theta


def test_the_operating_force_is_the_hand_solved_ideal_muscle_force_when_nothing_dissipates(tmp_path):
    """A result whose model is the ideal Peano muscle alone: its operating force at contraction e and pressure p
    is Niiyama's virtual-work force p w (f l) cos(theta)/theta, theta solving 1 - sin(theta)/theta = e, f the
    posterior's length fraction. The recommendation's median force over 200 draws of f equals it at the median
    f."""
    n = 200
    fraction = np.linspace(0.6, 0.75, n)  # median 0.675, away from the nominal 0.8
    _ideal_muscle_result(tmp_path, fraction)
    requirement = "force_n = 10.0\ncontraction = 0.12\nmax_pressure_kpa = 30\n"
    grid = "n_tubes = [4]\ntube_width_mm = [15, 20]\ntube_length_mm = [49.5]\n"
    path = _spec(tmp_path, requirement, grid + f"[results]\nn_draws = {n}\n")
    report = recommend(path, tmp_path, log=lambda m: None)
    for c in report["candidates"]:
        forces = _niiyama_force_n(30e3, 1e-3 * c["tube_width_mm"], fraction * 49.5e-3, 0.12)  # (n,) [N]
        assert c["force_median_n"] == pytest.approx(np.median(forces), rel=1e-6), c["tube_width_mm"]
        assert c["draws"] == n and c["probability"] == np.mean(forces >= 10.0)
        assert c["p_force_with_margin"] == np.mean(forces >= 10.5)  # 10 N with the 5 % margin to spare
    assert [c["probability"] for c in report["candidates"]] == [1.0, 1.0]  # 15 mm: 10.0-12.5 N, 20 mm: 13.4-16.7 N
    assert 0.0 < report["candidates"][1]["p_force_with_margin"] < 1.0
    assert report["draws"] == {"TP": n} and report["margin"] == 0.05


def test_with_every_parameter_draw_alike_the_force_interval_is_the_misfits_own_normal(tmp_path):
    """The ideal muscle of the test above with one length fraction in every draw: the operating force has no
    spread of its own, so with the blocking test's structured misfit of 2 N (excess RMSE) its 94 % interval is
    that of a normal of sd 2 N, 2 x 1.881 x 2 = 7.52 N wide (within the sampling error of 4000 draws' HDI),
    centred on the hand-solved force: the misfit is added once, at its own size."""
    n = 4000
    _ideal_muscle_result(tmp_path, np.full(n, 0.7))
    summary = minimal_summary(
        fit_quality_posterior_mean={"blocking": {"excess_rmse": 2.0}},
        residual_correlation={"blocking": {"consistent_with_noise": False, "likelihood_lag1": None}},
    )
    (tmp_path / "TP" / "summary.json").write_text(json.dumps(summary))
    requirement = "force_n = 10.0\ncontraction = 0.12\nmax_pressure_kpa = 30\n"
    grid = "n_tubes = [4]\ntube_width_mm = [15]\ntube_length_mm = [49.5]\n"  # the result's own geometry
    report = recommend(_spec(tmp_path, requirement, grid + f"[results]\nn_draws = {n}\n"), tmp_path, log=lambda m: None)
    (c,) = report["candidates"]
    force = _niiyama_force_n(30e3, 15e-3, 0.7 * 49.5e-3, 0.12)
    assert c["force_discrepancy_sd_n"] == pytest.approx(2.0, rel=1e-9)
    assert c["force_interval_n"][1] - c["force_interval_n"][0] == pytest.approx(2 * 1.881 * 2.0, rel=0.06)
    assert np.mean(c["force_interval_n"]) == pytest.approx(force, abs=0.15)
    assert c["force_median_n"] == pytest.approx(force, abs=0.1)


def test_the_top_candidate_is_recommended_only_when_it_clears_the_next_by_two_standard_errors():
    from peano_bayes.analysis.recommend import recommended

    def cand(p, se, infeasible=()):
        return {"probability": p, "probability_se": se, "infeasible": list(infeasible)}

    # 0.95 +- 0.007 against 0.90 +- 0.009: a difference of 0.05 against 2 x 0.0114
    assert recommended([cand(0.95, 0.007), cand(0.90, 0.009)]) == {"verdict": "recommended", "candidates": [0]}
    # 0.95 against 0.94 (+- 0.0075): within two standard errors of the difference, tied
    assert recommended([cand(0.95, 0.007), cand(0.94, 0.0075), cand(0.5, 0.016)]) == {
        "verdict": "tied", "candidates": [0, 1]
    }
    # an infeasible candidate is never in the comparison; nothing meeting the requirement recommends nothing
    assert recommended([cand(0.0, 0.0, ["above"]), cand(0.6, 0.015)])["candidates"] == [1]
    assert recommended([cand(0.0, 0.0), cand(0.0, 0.0)]) == {"verdict": "none", "candidates": []}

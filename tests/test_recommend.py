"""Design recommendation: parameter scaling with geometry is exact where it must be, the spec reader refuses
bad and impossible requirements with the key named, and candidates are scored monotonically."""

import json
import shutil

import arviz as az
import jax.numpy as jnp
import pytest

from peano_bayes.cli import main
from peano_bayes.errors import PeanoBayesInputError
from peano_bayes.physics import DEFAULT_CONFIG, PAPER_GEOMETRY, Geometry, scale_parameters, static_force, static_strain
from peano_bayes.recommend import load_spec, recommend, recommendation_markdown

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


GOOD = "force_n = 10.0\ncontraction = 0.05\nmax_pressure_kpa = 100\n"


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
        (GOOD.replace("100", "5000"), "expected at most 1000 kPa"),
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
    metrics = {"material": "TP", "draws": {"speed": speed}, "summary": {"speed": {"from_prior": True}}}
    (root / "TP" / "metrics.json").write_text(json.dumps(metrics))
    from peano_bayes.inference.results import load_result
    from peano_bayes.recommend import _result_geometry

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

"""Priors as data: every bundled prior file loads, covers the model, respects the physics, and is a correct density."""

from __future__ import annotations

import dataclasses
import math
import warnings
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import stats

from peano_bayes.errors import PeanoBayesInputError
from peano_bayes.inference import (
    ALL_PARAMETERS,
    LIKELIHOOD_PARAMETERS,
    Prior,
    load_prior,
    parse_entry,
    prior_files,
    prior_for,
)
from peano_bayes.materials import MATERIALS
from peano_bayes.physics.model import PARAMETERS

MALFORMED = Path(__file__).parent / "malformed_priors"
CODES = tuple(MATERIALS)


def _prior_of(code: str, cache={}) -> Prior:  # noqa: B006  (module-level memo: loading is cheap, jit is not)
    if code not in cache:
        cache[code] = load_prior(code)
    return cache[code]


def _entry(**fields) -> dict:
    return {"unit": "N", "provenance": "test", **fields}


# ------------------------------------------------------------------------------------------ files load


def test_priors_directory_has_files():
    names = {p.name for p in prior_files()}
    assert "default.toml" in names and len(names) >= 3


@pytest.mark.parametrize("path", prior_files(), ids=lambda p: p.name)
def test_every_prior_file_loads(path):
    prior = load_prior(path)
    assert prior.ndim == len(ALL_PARAMETERS)  # each file extends default.toml, which covers every name
    assert prior.files[0].name == "default.toml" and prior.files[-1] == path
    for file in prior.files:
        assert f"# ==> {file} <==" in prior.text
        assert file.read_text(encoding="utf-8") in prior.text


def test_default_covers_every_parameter_and_noise_scale():
    prior = load_prior(Path(prior_files()[0]).parent / "default.toml")
    assert set(prior.names) == set(PARAMETERS) | set(LIKELIHOOD_PARAMETERS)
    assert prior.names == tuple(ALL_PARAMETERS)  # fixed order: physics first, then likelihood
    assert set(LIKELIHOOD_PARAMETERS) == {
        "noise_load_cycle_force_n",
        "noise_blocking_force_n",
        "noise_stroke_strain",
        "noise_step_strain",
        "specimen_log_sd",
    }


@pytest.mark.parametrize("code", CODES)
def test_every_material_resolves(code):
    prior = _prior_of(code)
    assert prior.files[0].name == "default.toml" and len(prior.files) >= 2
    model = prior_for(code)
    assert model.names == prior.config.parameter_names() + tuple(LIKELIHOOD_PARAMETERS)
    assert load_prior(code.lower()).files == prior.files  # codes are case-insensitive


def test_material_overrides_and_config():
    assert _prior_of("FC").config.mount and _prior_of("PC").config.mount
    assert not _prior_of("TFC").config.mount and not _prior_of("TP").config.mount
    assert "mount_compliance_m_per_n" in prior_for("FC").names
    assert "mount_compliance_m_per_n" not in prior_for("TP").names
    assert [f.name for f in _prior_of("PR").files] == ["default.toml", "plastic_film.toml", "PR.toml"]
    # a child replaces its parent's whole entry: PR is stiffer in extension than the plastic family
    assert _prior_of("PR").median()["extension_k_n_per_m"] > _prior_of("P").median()["extension_k_n_per_m"]
    assert _prior_of("PCS").marginals["tensile_ka_n_per_m"].high < _prior_of("PC").marginals["tensile_ka_n_per_m"].high
    assert "PR.toml" in _prior_of("PR").provenance["extension_k_n_per_m"]


@pytest.mark.parametrize("code", CODES)
def test_support_inside_physical_bounds_and_units_match(code):
    prior = _prior_of(code)
    for name in prior.names:
        m, spec = prior.marginals[name], ALL_PARAMETERS[name]
        assert m.unit == spec.unit, name
        assert spec.bounds[0] <= m.low < m.high <= spec.bounds[1], name
        assert m.provenance.strip(), name
        assert m.low <= m.median() <= m.high, name


def test_prior_is_immutable():
    prior = _prior_of("FC")
    with pytest.raises(dataclasses.FrozenInstanceError):
        prior.names = ()
    with pytest.raises(TypeError):
        prior.marginals["noise_load_cycle_force_n"] = None
    with pytest.raises(TypeError):
        prior.config_overrides["mount"] = False


# ------------------------------------------------------------------------------------------ density


@pytest.mark.parametrize("code", CODES)
def test_log_prob_finite_at_median_and_draws(code):
    prior = _prior_of(code)
    assert np.isfinite(float(prior.log_prob(prior.median_unconstrained())))
    draws = prior.sample(np.random.default_rng(7), 64)
    assert draws.shape == (64, prior.ndim) and draws.dtype == np.float64
    lp = np.asarray(jax.jit(jax.vmap(prior.log_prob))(draws))
    assert lp.dtype == np.float64 and np.all(np.isfinite(lp))
    values = prior.from_unconstrained(draws)
    for name in prior.names:
        m = prior.marginals[name]
        assert np.all((np.asarray(values[name]) >= m.low) & (np.asarray(values[name]) <= m.high)), name


def test_minus_inf_not_nan_outside_support():
    prior = _prior_of("FC")
    u = np.asarray(prior.median_unconstrained())
    log_prob, log_density = jax.jit(prior.log_prob), jax.jit(prior.log_density)
    for i in range(prior.ndim):
        for bad in (np.nan, np.inf, -np.inf, 1e4, -1e4):
            v = u.copy()
            v[i] = bad
            lp = float(log_prob(v))
            if np.isfinite(bad):  # far tail of u: x rounds onto a bound; the density of u is ~exp(-|u|) or -inf
                assert not np.isnan(lp) and lp < -1e3, (bad, prior.names[i], lp)
            else:
                assert lp == -np.inf, (bad, prior.names[i])
    median = prior.median()
    for name in prior.names:
        m = prior.marginals[name]
        for x in (m.low - 1.0 - abs(m.low), m.high * 2.0 + 1.0, np.nan):
            lp = float(log_density({**median, name: x}))
            assert lp == -np.inf, (name, x)
        assert not np.isnan(np.asarray(jax.grad(m.log_density)(m.high * 2.0 + 1.0)))


def test_round_trip_and_jacobian_at_median():
    prior = _prior_of("PCS")
    params = prior.median()
    back = prior.from_unconstrained(prior.to_unconstrained(params))
    for name in prior.names:
        assert float(back[name]) == pytest.approx(params[name], rel=1e-12, abs=0.0)


_ROUND_TRIP_MARGINALS = [
    m for code in ("FC", "PR", "PCS") for m in (load_prior(code).marginals[n] for n in load_prior(code).names)
]


@given(data=st.data())
def test_from_unconstrained_inverts_to_unconstrained(data):
    m = data.draw(st.sampled_from(_ROUND_TRIP_MARGINALS), label="marginal")
    high = min(m.high, 1e12 * max(m.median(), 1e-300))  # keep exp(u) finite for half-infinite supports
    x = data.draw(
        st.floats(
            min_value=max(m.low, 1e-300),
            max_value=high,
            exclude_min=True,
            exclude_max=True,
            allow_subnormal=False,
        ),
        label="x",
    )
    u = m.to_unconstrained(x)
    assert np.isfinite(float(u))
    back, log_jac = m.from_unconstrained(u)
    assert abs(float(back) - x) <= 1e-12 * abs(x), (m.name, m.transform, x, float(back))
    assert np.isfinite(float(log_jac))


@settings(deadline=None)  # JAX compiles its side once per transform on first use
@given(data=st.data())
def test_numpy_values_are_transformed_in_numpy_as_jax_transforms_them(data):
    """Prior draws and stored posterior draws (NumPy) are transformed by NumPy, arrays by JAX: the same values
    (to 1e-12 relative), NumPy out for NumPy in, and no floating-point warning where JAX gives an infinity."""
    m = data.draw(st.sampled_from(_ROUND_TRIP_MARGINALS), label="marginal")
    u = np.asarray(data.draw(st.lists(st.floats(-40.0, 40.0), min_size=5, max_size=5), label="u"))
    x_np, jac_np = m.from_unconstrained(u)
    x_jax, jac_jax = (np.asarray(a) for a in m.from_unconstrained(jnp.asarray(u)))
    assert isinstance(x_np, np.ndarray) and not isinstance(x_np, jax.Array)
    np.testing.assert_allclose(x_np, x_jax, rtol=1e-12, atol=0.0)
    np.testing.assert_allclose(jac_np, jac_jax, rtol=1e-12, atol=1e-12)
    # Back to u only away from the bounds: there x -> u amplifies the last bit of x (either library's).
    inner = x_np[np.abs(u) <= 10.0]
    back_np, back_jax = m.to_unconstrained(inner), np.asarray(m.to_unconstrained(jnp.asarray(inner)))
    np.testing.assert_allclose(back_np, back_jax, rtol=1e-9, atol=1e-9)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        on_bounds = m.to_unconstrained(np.array([m.low, m.high]))
    if m.transform in ("logit", "loglogit"):  # the bounds map to the ends of the line (XLA may give NaN)
        np.testing.assert_array_equal(on_bounds, [-np.inf, np.inf])


def _central_difference(fn, u, i, h=1e-3):
    """d fn / d u_i by a fourth-order central difference."""

    def at(d):
        v = np.array(u, dtype=float)
        v[i] += d
        return float(fn(v))

    return (8.0 * (at(h) - at(-h)) - (at(2.0 * h) - at(-2.0 * h))) / (12.0 * h)


@pytest.mark.parametrize("code", ["FC", "TP"])
def test_log_prob_gradient_matches_finite_difference(code):
    prior = prior_for(code)
    u = prior.sample(np.random.default_rng(11), 1)[0]
    grad = np.asarray(jax.jit(jax.grad(prior.log_prob))(u))
    log_prob = jax.jit(prior.log_prob)
    numeric = np.array([_central_difference(log_prob, u, i) for i in range(prior.ndim)])
    np.testing.assert_allclose(grad, numeric, rtol=1e-6, atol=1e-8)


@pytest.mark.parametrize(
    "entry",
    [
        _entry(distribution="lognormal", median=0.5, sigma_log=1.5, high=50.0),
        _entry(distribution="loguniform", low=1e-2, high=40.0),
        _entry(distribution="truncnormal", mean=3.0, sd=10.0, low=0.0, high=20.0),
        _entry(distribution="uniform", low=0.0, high=50.0),
        _entry(distribution="halfnormal", scale=5.0, high=10.0),
    ],
    ids=lambda e: e["distribution"],
)
def test_density_of_u_integrates_to_one(entry):
    """The Jacobian is right: exp(log p(u)) integrates to 1 over u, for every distribution and transform."""
    m = parse_entry("test.toml", "friction_force_n", entry)
    u = np.linspace(-80.0, 80.0, 160_001)
    x, log_jac = m.from_unconstrained(u)
    p = np.exp(np.asarray(m.log_density(x) + log_jac))
    assert np.trapezoid(p, u) == pytest.approx(1.0, abs=1e-6)


# ------------------------------------------------------------------------------------------ sampling


def _truncated(dist, low, high):
    """CDF of ``dist`` (a frozen scipy distribution) truncated to [low, high]."""
    c_low, c_high = dist.cdf(low), dist.cdf(high)
    return lambda x: (dist.cdf(x) - c_low) / (c_high - c_low)


@pytest.mark.parametrize(
    ("entry", "reference"),
    [
        (
            _entry(distribution="lognormal", median=0.5, sigma_log=1.5, high=50.0),
            _truncated(stats.lognorm(s=1.5, scale=0.5), 0.0, 50.0),
        ),
        (_entry(distribution="loguniform", low=1e-2, high=40.0), stats.loguniform(1e-2, 40.0).cdf),
        (
            _entry(distribution="truncnormal", mean=3.0, sd=10.0, low=0.0, high=20.0),
            stats.truncnorm(-0.3, 1.7, loc=3.0, scale=10.0).cdf,
        ),
        (_entry(distribution="uniform", low=0.0, high=50.0), stats.uniform(0.0, 50.0).cdf),
        (_entry(distribution="halfnormal", scale=5.0, high=10.0), _truncated(stats.halfnorm(scale=5.0), 0.0, 10.0)),
    ],
    ids=lambda v: v["distribution"] if isinstance(v, dict) else "",
)
def test_samples_follow_the_declared_distribution(entry, reference):
    m = parse_entry("test.toml", "friction_force_n", entry)
    prior = Prior(("friction_force_n",), {"friction_force_n": m}, {}, (), "", "test")
    x = np.asarray(prior.sample_params(np.random.default_rng(2016), 4000)["friction_force_n"])
    assert stats.kstest(x, reference).pvalue > 1e-3
    # and the density is normalized: it matches the reference CDF's derivative
    grid = m.quantile(np.array([0.1, 0.5, 0.9]))
    h = 1e-6 * (m.high - m.low)
    pdf = (reference(grid + h) - reference(grid - h)) / (2 * h)
    np.testing.assert_allclose(np.exp(np.asarray(m.log_density(grid))), pdf, rtol=1e-5)


def test_lognormal_median_and_quantiles_within_standard_errors():
    sigma, median, n = 1.2, 2e3, 10_000
    m = parse_entry(
        "test.toml",
        "extension_k_n_per_m",
        _entry(distribution="lognormal", median=median, sigma_log=sigma, high=1e5, unit="N/m"),
    )
    prior = Prior(("extension_k_n_per_m",), {"extension_k_n_per_m": m}, {}, (), "", "test")
    log_x = np.log(prior.sample_params(np.random.default_rng(5), n)["extension_k_n_per_m"])
    for q, z in ((0.5, 0.0), (0.16, -0.994458), (0.84, 0.994458)):
        se = sigma * math.sqrt(q * (1 - q) / n) / stats.norm.pdf(z)  # SE of a sample quantile (log space)
        assert abs(np.quantile(log_x, q) - (math.log(median) + sigma * z)) < 4.0 * se, q


def test_sample_accepts_int_seed_and_is_reproducible():
    prior = prior_for("P")
    np.testing.assert_array_equal(prior.sample(3, 5), prior.sample(np.random.default_rng(3), 5))


# ------------------------------------------------------------------------------------------ errors


def _malformed():
    cases = []
    for path in sorted(MALFORMED.glob("*.toml")):
        parameter, text = (
            part.strip() for part in path.read_text().splitlines()[0].removeprefix("# expect:").split("|")
        )
        cases.append(pytest.param(path, parameter, text, id=path.stem))
    return cases


def test_enough_malformed_files():
    stems = {p.stem for p in MALFORMED.glob("*.toml")}
    assert {"unknown_name", "unit_mismatch", "support_outside_bounds", "unknown_distribution", "missing_field"} <= stems


@pytest.mark.parametrize(("path", "parameter", "text"), _malformed())
def test_malformed_prior_files_raise_named_errors(path, parameter, text):
    with pytest.raises(PeanoBayesInputError) as err:
        load_prior(path)
    message = str(err.value)
    assert str(path) in message
    assert text in message
    if parameter != "-":
        assert f"parameter '{parameter}'" in message
        lines = [line.strip() for line in path.read_text().splitlines()]
        if f"[parameters.{parameter}]" in lines:  # the error points at the parameter's table
            assert f"{path}, line {lines.index(f'[parameters.{parameter}]') + 1}: parameter" in message


def test_unknown_material_code_suggests_a_near_one():
    with pytest.raises(PeanoBayesInputError, match=r"did you mean 'FC'"):
        load_prior("FCC")
    with pytest.raises(PeanoBayesInputError, match="prior file not found"):
        load_prior("no_such_prior.toml")


def test_extends_cycle_and_invalid_toml(tmp_path):
    (tmp_path / "a.toml").write_text('[meta]\nextends = "b.toml"\n')
    (tmp_path / "b.toml").write_text('[meta]\nextends = "a.toml"\n')
    with pytest.raises(PeanoBayesInputError, match="cycle"):
        load_prior(tmp_path / "a.toml")
    (tmp_path / "c.toml").write_text("[meta\n")
    with pytest.raises(PeanoBayesInputError, match="not valid TOML"):
        load_prior(tmp_path / "c.toml")


def test_priors_dir_argument(tmp_path):
    """A user's own directory: a material file there wins, and 'extends' falls back to it."""
    default = next(p for p in prior_files() if p.name == "default.toml")
    (tmp_path / "default.toml").write_text(default.read_text())
    (tmp_path / "FC.toml").write_text(
        '[meta]\nmaterial = "FC"\nextends = "default.toml"\n[config]\nseries_kelvin = 1\n'
        '[parameters.noise_load_cycle_force_n]\ndistribution = "lognormal"\nmedian = 3.0\nsigma_log = 0.5\n'
        'unit = "N"\nprovenance = "my load cell"\n'
    )
    prior = load_prior("FC", priors_dir=tmp_path)
    assert prior.config.series_kelvin == 1
    assert prior.marginals["noise_load_cycle_force_n"].distribution == "lognormal"
    assert jnp.isfinite(prior.log_prob(prior.median_unconstrained()))

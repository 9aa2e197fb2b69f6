"""The paper's two reference models fitted to the same load cycles, for the fit report.

- **Sarosi** (static, empirical): ``F = (a1 p + a2) exp(a3 eps) + a4 p eps + a5 p + a6`` per branch of the
  hysteresis loop. Each branch (strain rising, strain falling) is fitted on its own bins: for a grid of
  ``a3`` the other five enter linearly (solved exactly, numpy least squares), then the best grid point is
  polished by optimistix Levenberg-Marquardt over all six.
- **Veale** (force balance, Table 2): the tube geometry scaled from Table 2's 15 x 46 mm tube to the
  dataset's tube width (linkage) and length (areas), and the four wall stiffnesses (``ka``, ``kb``, bending
  quartic and linear) fitted in log space from Table 2's values (scipy's trust-region least squares with a
  finite-difference Jacobian: see :func:`fit_veale`). One curve serves
  both branches: the model has no hysteresis.

Both are scored like our model (:func:`~peano_bayes.inference.fit.fit_quality`): RMSE, max |error| and R^2
of the binned load-cycle force. The paper's figures for them (on its own four-tube muscle, not these data)
are in ``paper/model_benchmarks.csv``.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from scipy import optimize

from ..physics.reference import VEALE_TABLE2, VealeParameters, veale_force
from .reduce import Observations

#: Table 2's tube (the geometry ``VEALE_TABLE2`` is written for) [m].
TABLE2_TUBE_WIDTH_M = 0.015
TABLE2_TUBE_LENGTH_M = 0.046
A3_GRID = np.linspace(-200.0, 50.0, 251)


def load_cycle_bins(observations: Observations) -> dict[str, np.ndarray]:
    """Every measured load-cycle bin: ``pressure_pa``, ``strain``, ``force_n`` (bin means) and ``rising``
    (strain increasing through the bin), flattened over runs."""
    cols = {"pressure_pa": [], "strain": [], "force_n": [], "rising": []}
    for group in observations.groups:
        if group.test != "load_cycle":
            continue
        strain = group.per_bin(np.asarray(group.strain)).mean(axis=-1)[group.shared]
        pressure = group.per_bin(np.asarray(group.pressure_pa)).mean(axis=-1)[group.shared]
        rising = np.gradient(strain, axis=1) > 0
        ok = np.isfinite(group.observed)
        cols["pressure_pa"].append(pressure[ok])
        cols["strain"].append(strain[ok])
        cols["force_n"].append(np.asarray(group.observed)[ok])
        cols["rising"].append(rising[ok])
    if not cols["force_n"]:
        raise ValueError("the data have no load cycles to fit the reference models to")
    return {k: np.concatenate(v) for k, v in cols.items()}


def quality(observed: np.ndarray, predicted: np.ndarray) -> dict:
    error = observed - predicted
    return {
        "unit": "N",
        "rmse": float(np.sqrt(np.mean(error**2))),
        "max_error": float(np.max(np.abs(error))),
        "r2": float(1.0 - np.sum(error**2) / np.sum((observed - observed.mean()) ** 2)),
        "bins": int(error.size),
    }


def _sarosi_kpa(a, p_kpa, eps):
    return (a[0] * p_kpa + a[1]) * jnp.exp(a[2] * eps) + a[3] * p_kpa * eps + a[4] * p_kpa + a[5]


def fit_sarosi_branch(pressure_pa, strain, force_n) -> np.ndarray:
    """Six coefficients (SI: p in Pa) of Sarosi's law fitted to one branch."""
    p = pressure_pa / 1e3  # kPa inside: coefficients of similar size
    best = None
    for a3 in A3_GRID:
        e = np.exp(a3 * strain)
        design = np.column_stack([p * e, e, p * strain, p, np.ones_like(p)])
        coef, *_ = np.linalg.lstsq(design, force_n, rcond=None)
        cost = float(np.sum((design @ coef - force_n) ** 2))
        if best is None or cost < best[0]:
            best = (cost, np.array([coef[0], coef[1], a3, coef[2], coef[3], coef[4]]))
    data = (jnp.asarray(p), jnp.asarray(strain), jnp.asarray(force_n))
    sol = optx.least_squares(
        lambda a, d: _sarosi_kpa(a, d[0], d[1]) - d[2],
        optx.LevenbergMarquardt(rtol=1e-10, atol=1e-10),
        jnp.asarray(best[1]),
        args=data,
        max_steps=200,
        throw=False,
    )
    a = np.asarray(sol.value)
    polished = float(np.sum((np.asarray(_sarosi_kpa(a, *data[:2])) - force_n) ** 2))
    a = a if np.isfinite(polished) and polished <= best[0] else best[1]
    return a * np.array([1e-3, 1.0, 1.0, 1e-3, 1e-3, 1.0])  # per kPa -> per Pa


def sarosi_predict(coefficients: np.ndarray, pressure_pa, strain) -> np.ndarray:
    a = coefficients
    return (a[0] * pressure_pa + a[1]) * np.exp(a[2] * strain) + a[3] * pressure_pa * strain + a[4] * pressure_pa + a[5]


def scaled_veale_geometry(tube_width_m: float, tube_length_m: float) -> VealeParameters:
    """Table 2's parameters with the linkage scaled by tube width and both areas by tube length."""
    w, length = tube_width_m / TABLE2_TUBE_WIDTH_M, tube_length_m / TABLE2_TUBE_LENGTH_M
    t = VEALE_TABLE2
    return dataclasses.replace(
        t, width_m=t.width_m * w, linkage_m=t.linkage_m * w, area1_m2=t.area1_m2 * length, area2_m2=t.area2_m2 * length
    )


_STIFFNESS = ("tensile_ka_n_per_m", "tensile_kb_n_per_m2", "bending_quartic_n_per_m5", "bending_linear_n_per_m2")


def _with_stiffness(geometry: VealeParameters, log_k) -> VealeParameters:
    return dataclasses.replace(geometry, **dict(zip(_STIFFNESS, jnp.exp(log_k), strict=True)))


#: Veale's force is not differentiable at p = 0 for eps >= 0 (it grows like p^(2/3)): bins of a slack muscle
#: below this pressure are left out of its fit (its Jacobian there is non-finite), not out of its score.
VEALE_CORNER_PA = 1e3


def fit_veale(pressure_pa, strain, force_n, tube_width_m: float, tube_length_m: float) -> VealeParameters:
    """Veale's model with scaled geometry and its four stiffnesses fitted (log space, from Table 2), on
    the bins away from its non-differentiable corner (:data:`VEALE_CORNER_PA`)."""
    geometry = scaled_veale_geometry(tube_width_m, tube_length_m)
    keep = (pressure_pa >= VEALE_CORNER_PA) | (strain < 0.0)
    p = jnp.asarray(np.maximum(pressure_pa[keep], 0.0))
    eps, f = jnp.asarray(strain[keep]), np.asarray(force_n[keep])
    scale = float(np.std(force_n)) or 1.0

    # The bins are arguments, not constants of the compiled program (constants make XLA's compile slow).
    force = jax.jit(lambda log_k, p, eps: veale_force(p, eps, _with_stiffness(geometry, log_k)))

    def residual(log_k):
        predicted = np.asarray(force(jnp.asarray(log_k), p, eps))
        return np.where(np.isfinite(predicted), (predicted - f) / scale, 1e3)

    start = np.log([float(getattr(VEALE_TABLE2, k)) for k in _STIFFNESS])
    # Finite-difference Jacobian (scipy): the implicit derivative of Veale's root-find blows up near its
    # corner and stops optimistix's linear solves with a hard error; differences of the force do not.
    found = optimize.least_squares(residual, start, method="trf", diff_step=1e-4, max_nfev=400)
    return _with_stiffness(geometry, jnp.asarray(found.x if np.all(np.isfinite(found.x)) else start))


def reference_comparison(observations: Observations) -> dict:
    """Fitted Sarosi and Veale models on the load cycles of ``observations``: their coefficients and
    :func:`quality` (``{"sarosi": {...}, "veale": {...}}``)."""
    bins = load_cycle_bins(observations)
    p, eps, f, rising = bins["pressure_pa"], bins["strain"], bins["force_n"], bins["rising"]
    predicted = np.empty_like(f)
    coefficients = {}
    for name, mask in (("strain_rising", rising), ("strain_falling", ~rising)):
        a = fit_sarosi_branch(p[mask], eps[mask], f[mask])
        coefficients[name] = a.tolist()
        predicted[mask] = sarosi_predict(a, p[mask], eps[mask])
    g = observations.geometry
    veale = fit_veale(p, eps, f, float(g.tube_width_m), float(g.tube_length_m))
    veale_predicted = np.asarray(veale_force(np.maximum(p, 0.0), eps, veale))
    return {
        "sarosi": {"coefficients_si": coefficients, "quality": quality(f, predicted)},
        "veale": {
            "stiffness": {k: float(getattr(veale, k)) for k in _STIFFNESS},
            "quality": quality(f, np.where(np.isfinite(veale_predicted), veale_predicted, 0.0)),
            "non_finite_bins": int(np.sum(~np.isfinite(veale_predicted))),
        },
    }


__all__ = ["fit_sarosi_branch", "fit_veale", "load_cycle_bins", "reference_comparison", "sarosi_predict"]

"""Sampler coordinates: the vector the ensemble moves, and its map to the posterior's theta.

:class:`~peano_bayes.inference.posterior.Posterior` is written in theta (each prior parameter in its
unconstrained space). Where the tests determine a nonlinear function of two parameters better than either,
the posterior in theta is a curved ridge, which both the differential-evolution moves and the multivariate-t
independence proposal (:mod:`.sample`) cross slowly. A :class:`Coordinates` object gives the sampler other
coordinates ``z`` in which the posterior is closer to elliptical; the sampler's density is
``ln p(theta(z)) + ln|det d theta / d z|`` and every draw is mapped back to theta before it is reported, so
nothing downstream of the sampler sees ``z``.

**Contract:** ``to_sampler(theta (n, D)) -> z (n, D)``; ``to_theta(z (n, D)) -> (theta (n, D), ln|det d theta
/ d z| (n,))``, with ``-inf`` where ``z`` maps outside the parameters' support; ``describe()`` a JSON-ready
description (a resumed run refuses a state written in other coordinates). NumPy only: the compiled log
posterior is shared unchanged.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..defaults import COORDINATE_KINDS
from ..physics.elements import tensile_stretch
from .priors import Marginal

KA, KB = "tensile_ka_n_per_m", "tensile_kb_n_per_m2"
#: Forces [N] of the tensile element's stretches in :class:`TensileStretch`. The load cycles and blocking tests
#: span about 0-60 N; on PR's posterior the choice between four pairs in 0.5-40 N changed the t proposal's fit
#: (``experiments/diagnose_mixing.py``) by under 1 %.
STRETCH_FORCES_N = (1.0, 20.0)


class Identity:
    """The sampler moves theta itself."""

    def to_sampler(self, theta: np.ndarray) -> np.ndarray:
        return np.array(theta, dtype=float)

    def to_theta(self, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        z = np.atleast_2d(np.asarray(z, dtype=float))
        return z.copy(), np.zeros(z.shape[0])

    def describe(self) -> dict:
        return {"kind": "theta"}


@dataclass(frozen=True)
class TensileStretch:
    """The series tensile element ``F = ka d + kb d^2`` sampled as the log of its stretch at two forces,
    ``z_i = ln d(F_i)`` (``forces`` F_1 < F_2 [N]), in place of theta's entries ``index`` = (i_ka, i_kb).

    The load cycles and blocking tests measure how far the element stretches at the forces they reach; ``ka``
    and ``kb`` each trade against the other along a curved ridge (on PR the t proposal's log importance
    weights had sd 1.53 in theta and 1.01 in these coordinates, ``experiments/diagnose_mixing.py``). Inverse:
    ``ka d_i + kb d_i^2 = F_i`` is linear in (ka, kb). The support ka > 0, kb >= 0 is the wedge
    ``sqrt(F_2/F_1) < d_2/d_1 <= F_2/F_1``; ``z`` outside it, or outside the priors' bounds, has density 0.
    """

    index: tuple[int, int]
    marginals: tuple[Marginal, Marginal]
    forces: tuple[float, float] = STRETCH_FORCES_N

    def to_sampler(self, theta: np.ndarray) -> np.ndarray:
        theta = np.array(theta, dtype=float)
        (i, j), (m_ka, m_kb) = self.index, self.marginals
        ka, _ = m_ka.from_unconstrained(theta[..., i])
        kb, _ = m_kb.from_unconstrained(theta[..., j])
        theta[..., i] = np.log(np.asarray(tensile_stretch(self.forces[0], ka, kb)))
        theta[..., j] = np.log(np.asarray(tensile_stretch(self.forces[1], ka, kb)))
        return theta

    def to_theta(self, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        z = np.array(np.atleast_2d(z), dtype=float)
        (i, j), (m_ka, m_kb) = self.index, self.marginals
        f1, f2 = self.forces
        d1, d2 = np.exp(z[:, i]), np.exp(z[:, j])
        det = d1 * d2 * (d2 - d1)
        with np.errstate(all="ignore"):
            ka = (f1 * d2**2 - f2 * d1**2) / det
            kb = (f2 * d1 - f1 * d2) / det
            ok = np.isfinite(ka) & np.isfinite(kb) & (ka > 0) & (kb >= 0)
            ok &= np.asarray(m_ka.inside(ka)) & np.asarray(m_kb.inside(kb))
            u_ka, u_kb = m_ka.to_unconstrained(ka), m_kb.to_unconstrained(kb)
            # ln|det d theta / d z| = ln|d u / d k| + ln|d k / d d| + ln|d d / d z|
            _, dx_du_ka = m_ka.from_unconstrained(u_ka)
            _, dx_du_kb = m_kb.from_unconstrained(u_kb)
            log_jac = (
                -dx_du_ka
                - dx_du_kb
                + np.log((ka + 2.0 * kb * d1) * (ka + 2.0 * kb * d2))
                - np.log(np.abs(det))
                + z[:, i]
                + z[:, j]
            )
        ok &= np.isfinite(u_ka) & np.isfinite(u_kb) & np.isfinite(log_jac)
        theta = z.copy()
        theta[:, i], theta[:, j] = np.where(ok, u_ka, 0.0), np.where(ok, u_kb, 0.0)
        return theta, np.where(ok, log_jac, -np.inf)

    def describe(self) -> dict:
        return {"kind": "tensile_stretch", "forces_n": list(self.forces)}


def sampler_coordinates(posterior, kind: str = "theta"):
    """The coordinates ``kind`` (``"theta"`` or ``"tensile_stretch"``) for ``posterior``: tensile stretches only
    where both ``tensile_ka`` and ``tensile_kb`` are sampled (with ``ka`` alone the log stretch is affine in
    its log and changes nothing), else theta itself."""
    if kind == "theta":
        return Identity()
    if kind not in COORDINATE_KINDS:
        raise ValueError(f"unknown sampler coordinates {kind!r}; expected 'theta' or 'tensile_stretch'")
    names = posterior.prior.names
    if KA not in names or KB not in names:
        return Identity()
    marginals = posterior.prior.marginals
    return TensileStretch((names.index(KA), names.index(KB)), (marginals[KA], marginals[KB]))


__all__ = ["COORDINATE_KINDS", "STRETCH_FORCES_N", "Identity", "TensileStretch", "sampler_coordinates"]

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
from .posterior import SPECIMEN_SD
from .priors import Marginal

KA, KB = "tensile_ka_n_per_m", "tensile_kb_n_per_m2"
#: Forces [N] of the tensile element's stretches in :class:`TensileStretch`. The load cycles and blocking tests
#: span about 0-60 N; on PR's posterior the choice between four pairs in 0.5-40 N changed the t proposal's fit
#: (measured by a mixing probe that git history keeps) by under 1 %.
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
    weights had sd 1.53 in theta and 1.01 in these coordinates, measured by a probe git history keeps). Inverse:
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


@dataclass(frozen=True)
class NonCentredContrasts:
    """Specimen contrasts sampled as ``z_k = c_k / tau`` where ``noncentred[k]`` (``tau`` the between-specimen
    spread ``specimen_log_sd``, entry ``index`` of theta's first ``d``; ``marginal`` its prior marginal, whose
    transform gives ``tau``), the others as they are.

    Why: with few specimens the data say little about a contrast beyond its prior ``N(0, tau)``; the spread and
    that contrast then form a funnel (``c`` must shrink as ``tau`` does), which the ensemble moves cross only
    slowly, and the spread's autocorrelation time sets the run's length. In ``z`` the prior is ``N(0, 1)``
    whatever ``tau``, so the funnel is gone; where the data do pin a contrast, the centred form is the better
    one (non-centring it would make the funnel in ``z``), hence the choice per contrast
    (:func:`choose_noncentred`). ``ln|det d theta / d z| = (number non-centred) ln tau``."""

    d: int
    index: int
    marginal: Marginal
    noncentred: tuple[bool, ...]

    def _tau(self, x: np.ndarray) -> np.ndarray:
        return np.asarray(self.marginal.from_unconstrained(np.asarray(x)[..., self.index])[0], dtype=float)

    def _scale(self, x: np.ndarray) -> np.ndarray:
        """(n, v) factor from z to c per contrast: tau where non-centred, 1 elsewhere."""
        return np.where(np.array(self.noncentred), self._tau(x)[:, None], 1.0)

    def to_sampler(self, theta: np.ndarray) -> np.ndarray:
        theta = np.array(np.atleast_2d(theta), dtype=float)
        theta[:, self.d :] = theta[:, self.d :] / self._scale(theta)
        return theta

    def to_theta(self, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        z = np.array(np.atleast_2d(z), dtype=float)
        with np.errstate(divide="ignore"):
            log_jac = sum(self.noncentred) * np.log(self._tau(z))
        z[:, self.d :] = z[:, self.d :] * self._scale(z)
        return z, np.where(np.isfinite(log_jac), log_jac, -np.inf)

    def describe(self) -> dict:
        return {"kind": "noncentred_contrasts", "noncentred": list(self.noncentred)}


@dataclass(frozen=True)
class Composed:
    """``outer`` applied to theta first, then ``inner``: ``z = inner.to_sampler(outer.to_sampler(theta))``, the
    log Jacobians added. Both must act on disjoint entries (the tensile stretches on population values, the
    contrasts on the contrasts), so the order does not matter."""

    outer: object
    inner: object

    def to_sampler(self, theta: np.ndarray) -> np.ndarray:
        return self.inner.to_sampler(self.outer.to_sampler(theta))

    def to_theta(self, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        y, inner_jac = self.inner.to_theta(z)
        theta, outer_jac = self.outer.to_theta(y)
        return theta, outer_jac + inner_jac

    def describe(self) -> dict:
        return {"kind": "composed", "parts": [self.outer.describe(), self.inner.describe()]}


#: A contrast is sampled non-centred where its Laplace sd at the mode is at least this fraction of the spread
#: there: the data then pin it little more than its prior ``N(0, tau)`` does.
NONCENTRE_RATIO = 0.5


def choose_noncentred(posterior, mode: np.ndarray, covariance: np.ndarray) -> tuple[bool, ...]:
    """Per contrast of ``posterior``, whether to sample it non-centred: its sd in the Laplace approximation
    (``mode`` (D,), ``covariance`` (D, D), theta) is at least :data:`NONCENTRE_RATIO` times the spread at the
    mode. Empty without contrasts."""
    n = getattr(posterior, "n_contrasts", 0)
    if not n:
        return ()
    names = posterior.prior.names
    spread = posterior.prior.marginals[SPECIMEN_SD]
    tau = float(spread.from_unconstrained(np.asarray(mode)[names.index(SPECIMEN_SD)])[0])
    sd = np.sqrt(np.diag(np.asarray(covariance))[len(names) :])
    return tuple(bool(s >= NONCENTRE_RATIO * tau) for s in sd)


def contrast_flags(choice: str, posterior, mode: np.ndarray, covariance: np.ndarray) -> tuple[bool, ...]:
    """Per contrast of ``posterior``, whether to sample it non-centred under the ``--contrasts`` ``choice``:
    ``"auto"`` by :func:`choose_noncentred` at the Laplace approximation (``mode`` (D,), ``covariance`` (D, D),
    theta), ``"centred"`` none, ``"noncentred"`` all. ``auto`` looks at the spread at its mode only: with two
    specimens the spread's posterior can reach far below its mode, into the neck of the funnel that centred
    contrasts make; ``noncentred`` is the other coordinate system for such a fit, not a cure where the data pin
    the contrasts about as tightly as the spread ranges (docs/validation.md, recovery with drawn constants)."""
    if choice == "auto":
        return choose_noncentred(posterior, mode, covariance)
    if choice == "centred":
        return ()
    if choice == "noncentred":
        return (True,) * getattr(posterior, "n_contrasts", 0)
    raise ValueError(f"unknown contrasts choice {choice!r}; expected 'auto', 'centred' or 'noncentred'")


def sampler_coordinates(posterior, kind: str = "theta", noncentred: tuple[bool, ...] = ()):
    """The coordinates ``kind`` (``"theta"`` or ``"tensile_stretch"``) for ``posterior``: tensile stretches only
    where both ``tensile_ka`` and ``tensile_kb`` are sampled (with ``ka`` alone the log stretch is affine in
    its log and changes nothing), else theta itself; with any ``noncentred`` contrast (one flag per contrast,
    :func:`choose_noncentred`), composed with :class:`NonCentredContrasts`."""
    if kind not in COORDINATE_KINDS:
        raise ValueError(f"unknown sampler coordinates {kind!r}; expected 'theta' or 'tensile_stretch'")
    names = posterior.prior.names
    base = Identity()
    if kind == "tensile_stretch" and KA in names and KB in names:
        marginals = posterior.prior.marginals
        base = TensileStretch((names.index(KA), names.index(KB)), (marginals[KA], marginals[KB]))
    if not any(noncentred):
        return base
    if len(noncentred) != posterior.n_contrasts:
        raise ValueError(f"{len(noncentred)} non-centring flags for {posterior.n_contrasts} contrasts")
    contrasts = NonCentredContrasts(
        len(names), names.index(SPECIMEN_SD), posterior.prior.marginals[SPECIMEN_SD], tuple(noncentred)
    )
    return contrasts if isinstance(base, Identity) else Composed(base, contrasts)


__all__ = [
    "COORDINATE_KINDS",
    "NONCENTRE_RATIO",
    "STRETCH_FORCES_N",
    "Composed",
    "Identity",
    "NonCentredContrasts",
    "TensileStretch",
    "choose_noncentred",
    "contrast_flags",
    "sampler_coordinates",
]

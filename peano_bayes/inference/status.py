"""How each stage of a fit ended, as enums whose members carry a message (in the manner of optimistix's
``RESULTS``): :class:`FitStatus` (multi-start least squares), :class:`ModeStatus` (the posterior mode and its
Laplace approximation), :class:`SampleStatus` (the sampler against its convergence rule).

A member is a ``str`` whose value is a short code, the form ``fit.json`` and ``summary.json`` record;
``message`` says what it means; ``ok`` whether the stage reached what it aimed at.
"""

from __future__ import annotations

import enum


class Status(enum.StrEnum):
    """Base of the stage enums: value (a short code) and ``message``."""

    def __new__(cls, value: str, message: str):
        member = str.__new__(cls, value)
        member._value_ = value
        member.message = message
        return member

    @property
    def ok(self) -> bool:
        """Whether the stage reached its aim (the first member of every enum is that outcome)."""
        return self is next(iter(type(self)))

    def __str__(self) -> str:
        return self.value


class FitStatus(Status):
    """How the multi-start least squares (:func:`~peano_bayes.inference.fit.fit`) ended."""

    SUCCESSFUL = ("successful", "the best start met the solver's tolerance")
    STEP_LIMIT = ("step_limit", "the best start had not met the solver's tolerance after its last round of steps")


class ModeStatus(Status):
    """How the posterior mode (:mod:`~peano_bayes.inference.laplace`) ended; ``Laplace.detail`` holds the
    optimiser's own message where it has one."""

    SUCCESSFUL = ("successful", "BFGS met its gradient tolerance (or stopped at a flat optimum within 1e-2)")
    STOPPED = ("stopped", "BFGS stopped before its gradient tolerance; the point it reached is kept")
    START_NOT_FINITE = ("start_not_finite", "the start's log posterior or its gradient is not finite")
    BELOW_START = ("below_start", "BFGS ended below its start; the start is kept")
    HESSIAN_NOT_FINITE = ("hessian_not_finite", "a point of the Hessian is not finite; the start's covariance is kept")


class SampleStatus(Status):
    """How sampling (:func:`~peano_bayes.inference.sample.sample`) ended."""

    CONVERGED = ("converged", "every target of the convergence rule holds")
    STEP_LIMIT = ("step_limit", "the step limit came before the convergence rule certified the chains")


__all__ = ["FitStatus", "ModeStatus", "SampleStatus", "Status"]

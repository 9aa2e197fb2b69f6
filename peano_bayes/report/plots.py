"""Plot functions: each takes prepared data (NumPy arrays, plain dicts) and matplotlib axes, draws, and
computes nothing; :mod:`peano_bayes.report.figures` prepares the data from results and saves the figures.

One look for every figure (:data:`STYLE`, used with ``matplotlib.rc_context``); axis labels carry units.
"""

from __future__ import annotations

import matplotlib.ticker
import numpy as np

#: rcParams shared by every figure.
STYLE = {
    "figure.dpi": 110,
    "savefig.dpi": 150,
    "font.size": 9,
    "axes.titlesize": 10,
    "axes.labelsize": 9,
    "legend.fontsize": 8,
    "axes.spines.top": False,
    "axes.spines.right": False,
    "axes.grid": True,
    "grid.alpha": 0.25,
}
DATA_COLOUR = "0.15"
MODEL_COLOUR = "#1f77b4"
PUBLISHED_COLOUR = "#d62728"


def predictive_band(
    ax,
    time_s,
    observed,
    low,
    median,
    high,
    *,
    ylabel: str,
    title: str = "",
    label_data="data",
    label_band="94 % predictive interval",
    label_median="predictive median",
):
    """Observed bin means (points) over the posterior predictive median (line) and its interval (band), for
    one run; all arrays (n,) against ``time_s`` [s]."""
    ax.fill_between(time_s, low, high, color=MODEL_COLOUR, alpha=0.3, lw=0, label=label_band)
    ax.plot(time_s, median, color=MODEL_COLOUR, lw=1.0, label=label_median)
    ax.plot(time_s, observed, ".", color=DATA_COLOUR, ms=1.5, label=label_data)
    ax.set_xlabel("time [s]")
    ax.set_ylabel(ylabel)
    if title:
        ax.set_title(title)


def forest(ax, labels, centre, low, high, *, xlabel: str, log: bool = False, title: str = ""):
    """One row per label: ``centre`` with the interval ``low``-``high`` (all (k,)), top to bottom."""
    y = np.arange(len(labels))[::-1]
    ax.errorbar(
        centre,
        y,
        xerr=[np.subtract(centre, low), np.subtract(high, centre)],
        fmt="o",
        color=MODEL_COLOUR,
        ms=4,
        capsize=2,
        lw=1.2,
    )
    ax.set_yticks(y, labels)
    ax.set_xlabel(xlabel)
    ax.grid(axis="y", visible=False)
    if log:
        ax.set_xscale("log")
        ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    else:
        ax.xaxis.set_major_locator(matplotlib.ticker.MaxNLocator(4))  # no overlapping tick labels
    if title:
        ax.set_title(title)


def published_versus_posterior(ax, labels, centre, low, high, published, *, xlabel: str, title: str = ""):
    """Posterior median and interval per label (as :func:`forest`) with the published value as a red cross
    (NaN where the paper gives none)."""
    forest(ax, labels, centre, low, high, xlabel=xlabel, title=title)
    y = np.arange(len(labels))[::-1]
    ax.plot(published, y, "x", color=PUBLISHED_COLOUR, ms=6, mew=1.5, label="published")


def probability_heatmap(ax, matrix, row_labels, column_labels, *, title: str = "", colorbar_label: str = "probability"):
    """A (rows, columns) probability matrix in [0, 1] with its values written in the cells."""
    image = ax.imshow(matrix, vmin=0.0, vmax=1.0, cmap="viridis", aspect="auto")
    ax.set_xticks(range(len(column_labels)), column_labels, rotation=30, ha="right")
    ax.set_yticks(range(len(row_labels)), row_labels)
    ax.grid(False)
    for i in range(len(row_labels)):
        for j in range(len(column_labels)):
            value = matrix[i][j]
            if np.isfinite(value):
                ax.text(
                    j,
                    i,
                    f"{value:.2f}",
                    ha="center",
                    va="center",
                    fontsize=7,
                    color="white" if value < 0.6 else "black",
                )
    ax.figure.colorbar(image, ax=ax, label=colorbar_label, shrink=0.8)
    if title:
        ax.set_title(title)


def force_margins(ax, labels, median, low, high, probability, *, title: str = ""):
    """One row per candidate design, best on top: its force margin over the requirement [%] at the median
    (point) with its 94 % interval (bar), the requirement at 0, and its probability of meeting every
    requirement written at the right (``median``, ``low``, ``high`` fractions (k,); ``probability`` (k,), NaN
    for an infeasible candidate, whose row is drawn grey and says so)."""
    y = np.arange(len(labels))[::-1]
    median, low, high, probability = (np.asarray(a, dtype=float) for a in (median, low, high, probability))
    feasible = np.isfinite(probability)
    for mask, colour in ((feasible, MODEL_COLOUR), (~feasible, "0.6")):
        if mask.any():
            ax.errorbar(
                100 * median[mask],
                y[mask],
                xerr=100 * np.abs(np.stack([median[mask] - low[mask], high[mask] - median[mask]])),
                fmt="o",
                color=colour,
                ms=4,
                capsize=2,
            )
    ax.axvline(0.0, color=PUBLISHED_COLOUR, lw=1.0, label="requirement")
    ax.set_yticks(y, labels)
    ax.set_xlabel("force margin over the requirement [%] (94 % interval)")
    ax.grid(axis="y", visible=False)
    for yi, p in zip(y, probability, strict=True):
        text = "infeasible" if not np.isfinite(p) else f"P = {p:.2f}"
        ax.annotate(text, (1.0, yi), xycoords=("axes fraction", "data"), xytext=(4, 0), textcoords="offset points",
                    va="center", fontsize=8)
    if title:
        ax.set_title(title)


def ensemble_traces(axes, draw, series: dict, units: dict):
    """One axis per parameter: each ensemble's walker mean (one line per ensemble) against ``draw`` (k,) the
    kept draw's step; ``series``: name -> (n_ensembles, k); ``units``: name -> unit text."""
    for ax, (name, values) in zip(axes, series.items(), strict=True):
        for e, row in enumerate(np.asarray(values)):
            ax.plot(draw, row, lw=0.7, alpha=0.8, label=f"ensemble {e + 1}")
        unit = units.get(name, "")
        ax.set_ylabel(f"[{unit}]" if unit else "[-]")
        ax.set_title(name, fontsize=8, loc="left")
        ax.yaxis.set_major_locator(matplotlib.ticker.MaxNLocator(3))
    axes[-1].set_xlabel("step")


def _monotone_pieces(x) -> list[slice]:
    """Slices of ``x`` (n,) over which it runs one way (a load cycle's loading and unloading branches)."""
    x = np.asarray(x, dtype=float)
    if x.size < 3:
        return [slice(0, x.size)]
    direction = np.sign(np.diff(x))
    turns = np.flatnonzero((direction[1:] != direction[:-1]) & (direction[1:] != 0) & (direction[:-1] != 0)) + 1
    bounds = [0, *turns.tolist(), x.size - 1]
    return [slice(a, b + 1) for a, b in zip(bounds[:-1], bounds[1:], strict=True)]


def response_with_residuals(
    ax, ax_residual, x, observed, low, median, high, *, xlabel: str, ylabel: str, title: str = ""
):
    """One run against its driving input ``x`` (n,) (a load cycle's force against strain, a blocking force or
    stroke against pressure): the 94 % predictive band and median over the data on ``ax``; under it on
    ``ax_residual`` the data minus the median, with the band around the median shifted the same way. A loop is
    banded branch by branch (:func:`_monotone_pieces`)."""
    x, observed, low, median, high = (np.asarray(a, dtype=float) for a in (x, observed, low, median, high))
    for i, piece in enumerate(_monotone_pieces(x)):
        ax.fill_between(x[piece], low[piece], high[piece], color=MODEL_COLOUR, alpha=0.3, lw=0,
                        label="94 % predictive interval" if i == 0 else None)
        ax_residual.fill_between(x[piece], (low - median)[piece], (high - median)[piece], color=MODEL_COLOUR,
                                 alpha=0.3, lw=0)
    ax.plot(x, median, color=MODEL_COLOUR, lw=1.0, label="predictive median")
    ax.plot(x, observed, ".", color=DATA_COLOUR, ms=1.5, label="data")
    ax_residual.plot(x, observed - median, ".", color=DATA_COLOUR, ms=1.5)
    ax_residual.axhline(0.0, color=MODEL_COLOUR, lw=0.8)
    ax.set_ylabel(ylabel)
    ax.tick_params(labelbottom=False)
    ax_residual.set_xlabel(xlabel)
    unit = ylabel[ylabel.find("[") :] if "[" in ylabel else ""
    ax_residual.set_ylabel(f"residual {unit}".strip())
    ax_residual.yaxis.set_major_locator(matplotlib.ticker.MaxNLocator(3))
    ax_residual.xaxis.set_major_locator(matplotlib.ticker.MaxNLocator(4))
    if title:
        ax.set_title(title)


__all__ = [
    "STYLE",
    "forest",
    "predictive_band",
    "probability_heatmap",
    "published_versus_posterior",
    "ensemble_traces",
    "force_margins",
    "response_with_residuals",
]


def residuals_against(ax, x, before, after, *, xlabel: str, title: str = ""):
    """Standardized residuals (in noise sd) of the base and the final model against one covariate ``x``:
    ``before`` and ``after`` are ``(residuals (n,), (bin centres, bin means))``; points and binned means."""
    r_before, (cb, mb) = before
    r_after, (ca, ma) = after
    ax.set_xlabel(xlabel)
    finite = np.asarray(x, dtype=float)[np.isfinite(x)]
    if finite.size == 0:
        ax.text(0.5, 0.5, "no data for this covariate", ha="center", va="center", transform=ax.transAxes)
        ax.set_xticks([])
        ax.set_yticks([])
        return
    ax.scatter(x, r_before, s=3, alpha=0.25, color=PUBLISHED_COLOUR, label="base model", rasterized=True)
    ax.scatter(x, r_after, s=3, alpha=0.25, color=MODEL_COLOUR, label="final model", rasterized=True)
    style = {"marker": "o", "ls": "none", "ms": 6} if np.unique(finite).size <= 5 else {"lw": 1.8}
    ax.plot(cb, mb, color=PUBLISHED_COLOUR, **style)
    ax.plot(ca, ma, color=MODEL_COLOUR, **style)
    ax.axhline(0.0, color=DATA_COLOUR, lw=0.8)
    # Linear within +-3 sd, logarithmic beyond: a base misfit of hundreds of sd and a final model at the noise
    # level stay legible on one axis.
    ax.set_yscale("symlog", linthresh=3.0)
    ax.set_ylabel("residual / noise sd [-] (symlog)")
    if title:
        ax.set_title(title)

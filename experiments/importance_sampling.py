"""Could importance sampling from the mode replace most of the MCMC run? A measurement on a certified result.

The main job's time goes to the sampler (about 50 autocorrelation times of four ensembles of about 2D walkers).
Draws from a multivariate t around the Laplace approximation, weighted by ``p / q`` and Pareto-smoothed (PSIS,
Vehtari et al. 2024, ``arviz.psislw``), would cost their draws alone: no chain, no burn-in. PSIS says when they
cannot be trusted: the Pareto shape ``k`` of the weights' tail (reliable below 0.7). Measured on FC:
``docs/validation.md``, *Main-job snapshot*.

The script rebuilds a certified result's posterior as ``peano-bayes fit`` did (dataset, tests, prior, model,
the least-squares point of its ``fit.json``, the mode on the exact-input and then the full likelihood), draws
``--draws`` points from a t (``--df``) around the Laplace approximation in the non-centred coordinates of the
mode search, and adapts it for ``--rounds`` rounds (each round's t refitted, without regularisation, to the
previous round's weighted draws). Per round it prints ``k``, the importance-sampling ESS, the seconds of
log-posterior evaluation and the coordinate whose excursions lose most weight (``widest``). It does not compare
the weighted draws with the MCMC run's: that is worth doing only once ``k`` is below 0.7.

    .venv/bin/python experiments/importance_sampling.py RESULT/FC [--draws 8000] [--rounds 3] [--df 7]

``RESULT/FC``: a converged ``peano-bayes fit`` or ``run`` folder of a bundled material with several specimens,
made without discovery. Last line: one JSON object.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import arviz as az
import numpy as np

from peano_bayes import enable_compilation_cache
from peano_bayes.app.pipeline import prior_of, select_tests
from peano_bayes.bundled import dataset_path
from peano_bayes.data import load
from peano_bayes.inference.driver import posterior_at_mode, walker_start
from peano_bayes.inference.fit import FitResult
from peano_bayes.inference.laplace import NonCentred, covariance_in_eta
from peano_bayes.inference.posterior import DEFAULT_HELD, build_posterior
from peano_bayes.inference.reduce import prepare
from peano_bayes.inference.sample import IndependenceProposal


def t_draws(rng, proposal: IndependenceProposal, n: int):
    """(n, D) draws of the sampler's multivariate-t proposal (drawn with ``rng``) and their log density."""
    x = proposal.draw(n, rng)
    return x, proposal.log_density(x)


def rebuild(result: Path):
    """The posterior the certified run sampled (inputs' error linearised and AR(1) lags as ``infer`` set them),
    its Laplace approximation on the full likelihood, and the non-centred map."""
    summary = json.loads((result / "summary.json").read_text())
    fitted = FitResult.from_json(json.loads((result / "fit.json").read_text()), where=str(result / "fit.json"))
    dataset = select_tests(load(dataset_path(summary["material"])), summary["tests"])
    whole_prior = prior_of(dataset, None)
    config = whole_prior.config
    if summary.get("model", {}).get("added"):
        raise SystemExit(f"{result}: made with discovery's additions; this script rebuilds the configured model only")
    prior = whole_prior.for_config(config)
    posterior = build_posterior(prepare(dataset), prior, config=config, held=DEFAULT_HELD)
    nc = NonCentred.of(posterior)
    if nc is None:
        raise SystemExit(f"{result}: one specimen; this script measures the non-centred posterior of several")
    if list(posterior.names) != list(summary["convergence"]["rhat"]):
        raise SystemExit(f"{result}: its sampled parameters differ from the rebuilt posterior's")
    centre, covariance = walker_start(posterior, fitted)
    start = posterior_at_mode(posterior.with_batch_rows(max(1, summary["n_walkers"] // 2)), centre, covariance)
    return summary, start.posterior, start.laplace, nc


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("result", type=Path)
    p.add_argument("--draws", type=int, default=8000, help="draws per round (default 8000)")
    p.add_argument("--rounds", type=int, default=3, help="adaptation rounds (default 3)")
    p.add_argument("--df", type=float, default=7.0, help="degrees of freedom of the t proposal (default 7)")
    p.add_argument(
        "--inflate",
        type=float,
        default=1.2,
        help="the first round's t scale matrix is inflate^2 x the Laplace covariance; each refit's covariance is "
        "inflate^2 x the weighted draws' (default 1.2)",
    )
    p.add_argument("--seed", type=int, default=0)
    args = p.parse_args(argv)
    if args.df <= 2:
        p.error(f"--df must exceed 2 (the t's covariance is df / (df - 2) times its scale), got {args.df}")
    enable_compilation_cache()

    t0 = time.perf_counter()
    summary, posterior, laplace, nc = rebuild(args.result)  # refuses a posterior without specimen contrasts
    setup_s = time.perf_counter() - t0
    print(f"posterior rebuilt, mode found in {setup_s:.0f} s (log posterior {laplace.log_prob:.1f})", flush=True)

    def log_target(eta):
        theta = nc.to_theta(eta)
        lp = np.asarray(posterior.batched(theta), dtype=float)
        return np.where(np.isfinite(lp), lp + nc.log_jacobian(eta), -np.inf)

    eta_mode = nc.to_eta(laplace.mode)
    mean, scale = eta_mode, args.inflate**2 * covariance_in_eta(nc.jacobian(eta_mode), laplace.covariance)
    rng = np.random.default_rng(args.seed)
    rounds = []
    for r in range(args.rounds):
        x, log_q = t_draws(rng, IndependenceProposal(mean, scale, args.df), args.draws)
        t1 = time.perf_counter()
        log_p = log_target(x)
        eval_s = time.perf_counter() - t1
        log_w = log_p - log_q
        finite = np.isfinite(log_w)
        lw, k = az.psislw(np.where(finite, log_w, -1e300)[None, :])
        lw, k = np.asarray(lw)[0], float(np.asarray(k).ravel()[0])
        w = np.exp(lw - lw.max())
        w /= w.sum()
        ess = float(1.0 / np.sum(w**2))
        rounds.append(
            {
                "round": r,
                "draws": args.draws,
                "pareto_k": k,
                "ess": ess,
                "eval_s": eval_s,
                "outside_support": int((~finite).sum()),
                "log_w_sd": float(np.std(log_w[finite])),
            }
        )
        # Which coordinate's excursions cost most: rank correlation of its squared standardized deviation
        # with -log w (the proposal too wide there when high); a contrast's entry is its non-centred z.
        dev = ((x - mean) ** 2 / np.diag(scale))[finite]
        corr = [
            float(np.corrcoef(np.argsort(np.argsort(dev[:, j])), np.argsort(np.argsort(-log_w[finite])))[0, 1])
            for j in range(x.shape[1])
        ]
        j = int(np.argmax(corr))
        rounds[-1]["widest"] = {"parameter": posterior.names[j], "rank_corr": corr[j]}
        print(json.dumps(rounds[-1]), flush=True)
        # The refit, unregularised: mean and covariance of the smoothed-weighted draws (a t's covariance is
        # df / (df - 2) times its scale matrix).
        mean = np.sum(w[:, None] * x, axis=0)
        centred = x - mean
        scale = (centred * w[:, None]).T @ centred * (args.df - 2) / args.df * args.inflate**2

    out = {"result": str(args.result), "material": summary["material"], "setup_s": setup_s, "rounds": rounds}
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Does holding the fitted inputs' error Jacobian fixed change the posterior? ``fit`` computes ``J`` once, at the
exact-input posterior mode (``Posterior.with_input_error_at``), instead of at every evaluation.

For a bundled material's default tests: least squares, the exact-input mode and its Laplace approximation as
``fit`` finds them; then at draws of that approximation (``--draws``, at 1 and at 3 times its sd) the log
posterior with ``J`` recomputed at each draw (live) and with ``J`` held at the mode. A fixed ``J`` changes the
posterior by importance weights ``exp(live - fixed)``: what matters is their spread over the draws, printed beside
the spread of the log posterior itself. Also printed: milliseconds per evaluation of each (batched, compilation
excluded). The last line printed is one JSON object.

    python experiments/input_error_linearisation.py [CODE] [--draws 38] [--starts 4]
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from peano_bayes import bundled, enable_compilation_cache
from peano_bayes.app.pipeline import prior_of, select_tests
from peano_bayes.data import load
from peano_bayes.defaults import DEFAULT_TESTS
from peano_bayes.inference.driver import least_squares, walker_start
from peano_bayes.inference.laplace import posterior_mode
from peano_bayes.inference.posterior import DEFAULT_HELD, build_posterior
from peano_bayes.inference.reduce import prepare


def per_evaluation_ms(f, thetas: np.ndarray, repeats: int = 3) -> float:
    f(thetas)  # compiles
    t0 = time.perf_counter()
    for _ in range(repeats):
        f(thetas)
    return 1e3 * (time.perf_counter() - t0) / repeats / len(thetas)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("code", nargs="?", default="TP")
    parser.add_argument("--draws", type=int, default=38)
    parser.add_argument("--starts", type=int, default=4, help="least-squares starts")
    args = parser.parse_args()
    enable_compilation_cache()
    dataset = select_tests(load(bundled.dataset_path(args.code)), DEFAULT_TESTS)
    whole = prior_of(dataset, None)
    prior = whole.for_config(whole.config)
    posterior = build_posterior(prepare(dataset), prior, config=whole.config, held=DEFAULT_HELD)
    centre, covariance = walker_start(posterior, least_squares(posterior, prior, n_starts=args.starts, seed=0))
    posterior = posterior.with_batch_rows(args.draws // 2)
    mode = posterior_mode(posterior, centre, covariance)
    fixed = posterior.with_input_error_at(mode.mode)
    rng = np.random.default_rng(3)
    chol = np.linalg.cholesky(mode.covariance)
    out = {"material": args.code, "draws": args.draws, "mode_status": mode.status or "converged"}
    for scale in (1.0, 3.0):
        draws = mode.mode + scale * rng.standard_normal((args.draws, mode.mode.size)) @ chol.T
        live, held = posterior.batched(draws), fixed.batched(draws)
        weight = live - held
        out[f"at_{scale:g}_sd"] = {
            "log_weight_sd": float(np.std(weight)),
            "log_weight_max_deviation": float(np.max(np.abs(weight - weight.mean()))),
            "log_posterior_sd": float(np.std(live)),
        }
        print(f"{args.code} at {scale:g} sd: {out[f'at_{scale:g}_sd']}", flush=True)
    draws = mode.mode + rng.standard_normal((args.draws // 2, mode.mode.size)) @ chol.T
    out["live_ms_per_evaluation"] = per_evaluation_ms(posterior.batched, draws)
    out["fixed_ms_per_evaluation"] = per_evaluation_ms(fixed.batched, draws)
    out["cost_ratio_fixed_over_live"] = out["fixed_ms_per_evaluation"] / out["live_ms_per_evaluation"]
    print(json.dumps(out))


if __name__ == "__main__":
    main()

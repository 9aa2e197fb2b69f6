"""Would a better-fitted independence proposal make a run mix faster? Two arms from the same place.

From the last step of a saved run (``<result>/sampler_state.npz`` of ``peano-bayes run`` on a bundled
material, its default tests), every ensemble runs ``--steps`` more steps with the package's moves
(:func:`~peano_bayes.inference.sample.moves_for`), once with the proposal the run froze at the end of its
warm-up (``frozen``) and once with one fitted to the run's whole kept chain (``refit``, what a warm-up long
enough to settle would give; see ``experiments/diagnose_mixing.py`` for how far apart the two are). Same
starting walkers and random seeds in both arms. Reported per arm and ensemble: the largest integrated
autocorrelation time over the parameters (on chains of equal length, so comparable between arms though
short chains under-estimate it) and the acceptance fraction. The last line printed is one JSON object.

    python experiments/proposal_refit.py RESULT_DIR [--material PR] [--steps 500]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time
from pathlib import Path

import emcee
import numpy as np

from peano_bayes import bundled, enable_compilation_cache
from peano_bayes.data import load
from peano_bayes.inference import build_posterior, prepare, prior_for
from peano_bayes.inference.posterior import DEFAULT_HELD
from peano_bayes.inference.sample import IndependenceProposal, load_state, moves_for, proposal_at
from peano_bayes.pipeline import DEFAULT_TESTS


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("result", type=Path, help="a result folder of a bundled material with sampler_state.npz")
    parser.add_argument("--material", help="bundled material code (default: the folder's name)")
    parser.add_argument("--steps", type=int, default=500)
    parser.add_argument("--seed", type=int, default=100)
    args = parser.parse_args()
    enable_compilation_cache()
    code = args.material or args.result.name
    chain, _, _, meta = load_state(args.result / "sampler_state.npz")
    kind = meta.get("coordinates", {"kind": "theta"})["kind"]
    if kind != "theta":  # the analysis reads the chain as theta (the parameters in their prior's coordinates)
        raise SystemExit(f"{args.result}: sampler state in {kind} coordinates; rerun with --coordinates theta")
    per, warmup = int(meta["n_walkers"]), int(meta["warmup"])
    dataset = load(bundled.dataset_path(code))
    dataset = dataclasses.replace(dataset, runs=tuple(r for r in dataset.runs if r.test in DEFAULT_TESTS))
    prior = prior_for(code)
    posterior = build_posterior(prepare(dataset), prior, config=prior.config, held=DEFAULT_HELD)
    if list(posterior.names) != list(meta["names"]):
        raise SystemExit(f"{args.result}: the saved run samples other parameters than {code}'s default model")
    posterior = posterior.with_batch_rows(per // 2)
    arms = {}
    for arm in ("frozen", "refit"):
        start, taus, acceptance = time.perf_counter(), [], []
        for e in range(chain.shape[1] // per):
            own = chain[:, e * per : (e + 1) * per]
            if arm == "frozen":
                proposal = proposal_at(own, warmup, warmup)
            else:
                proposal = IndependenceProposal.fit(own[warmup:].reshape(-1, own.shape[-1]))
            sampler = emcee.EnsembleSampler(
                per, own.shape[-1], posterior.batched, vectorize=True, moves=moves_for(proposal)
            )
            sampler.random_state = np.random.RandomState(args.seed + e).get_state()
            sampler.run_mcmc(own[-1], args.steps, progress=False)
            taus.append(float(emcee.autocorr.integrated_time(sampler.get_chain(), quiet=True).max()))
            acceptance.append(float(sampler.acceptance_fraction.mean()))
        arms[arm] = {"tau_max": taus, "acceptance": acceptance, "seconds": time.perf_counter() - start}
        print(
            f"{arm}: tau_max {', '.join(f'{t:.1f}' for t in taus)} (mean {np.mean(taus):.1f}); acceptance "
            f"{', '.join(f'{a:.3f}' for a in acceptance)}",
            flush=True,
        )
    ratio = float(np.mean(arms["frozen"]["tau_max"]) / np.mean(arms["refit"]["tau_max"]))
    print(f"mean tau_max frozen / refit: {ratio:.2f}")
    print(json.dumps({"result": str(args.result), "steps": args.steps, "arms": arms, "tau_ratio": ratio}))


if __name__ == "__main__":
    main()

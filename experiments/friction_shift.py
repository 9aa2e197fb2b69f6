"""Where the likelihood puts a bundled material's friction pair on virtual-rig copies of its session.

Everything is held at each specimen's generating values except ``friction_force_n`` and
``friction_pressure_fraction``; the conditional Newton step of the load-cycle and blocking log-likelihood from
the truth, in units of the pair's conditional sd, shows a systematic pull (a likelihood that is the process
that made the data gives shifts of order one, either way, from noise alone). ``--noise`` picks which sensors
are noisy: ``none``, ``force``, ``strain`` or ``all`` (the rig's defaults). Found the friction-pair bias of the
main job (strain noise: +0.9 to +3.6 / -1.1 to -4.1 sd on PR, seeds 11-14, with the old path samples).

    python experiments/friction_shift.py PR --seeds 11 12 --noise strain

The last line printed is one JSON object.
"""

from __future__ import annotations

import argparse
import dataclasses
import json

import jax
import jax.numpy as jnp
import numpy as np
from make_datasets import read_truth

from peano_bayes.inference.likelihood import group_log_likelihood
from peano_bayes.inference.posterior import build_posterior
from peano_bayes.inference.prior_files import prior_for
from peano_bayes.inference.reduce import prepare
from peano_bayes.rig import RigNoise, simulate_dataset

PAIR = ("friction_force_n", "friction_pressure_fraction")


def _noise(which: str) -> RigNoise:
    d = RigNoise()
    return {
        "none": RigNoise(0.0, 0.0, 0.0, 0.0, 0.0),
        "force": RigNoise(d.force_sd_n, 0.0, 0.0, 0.0, 0.0),
        "strain": RigNoise(0.0, d.strain_sd, 0.0, 0.0, 0.0),
        "all": d,
    }[which]


def friction_shift(code: str, dataset) -> dict:
    """Newton shift of the friction pair from the truth, its conditional sd, and their ratio."""
    quasi_static = tuple(r for r in dataset.runs if r.test in ("load_cycle", "blocking"))
    dataset = dataclasses.replace(dataset, runs=quasi_static)
    obs = prepare(dataset)
    config = build_posterior(obs, prior_for(code)).config
    own = json.loads(dataset.provenance["specimen_parameters"])
    noise = RigNoise()
    specimens = list(obs.specimens)
    base = {k: jnp.asarray([own[s][k] for s in specimens]) for k in own[specimens[0]]}
    base |= {name: jnp.asarray(noise.force_sd_n) for name in ("noise_load_cycle_force_n", "noise_blocking_force_n")}

    def loglik(x):
        p = dict(base)
        for i, name in enumerate(PAIR):
            p[name] = jnp.full(len(specimens), x[i])
        return sum(jnp.nansum(group_log_likelihood(p, g, config=config, geometry=obs.geometry)[2]) for g in obs.groups)

    x0 = jnp.asarray([float(base[n][0]) for n in PAIR])
    cov = np.linalg.inv(-np.asarray(jax.hessian(loglik)(x0)))
    shift = cov @ np.asarray(jax.grad(loglik)(x0))
    sd = np.sqrt(np.diag(cov))
    ratio = (shift / sd).tolist()
    return {"truth": np.asarray(x0).tolist(), "shift": shift.tolist(), "sd": sd.tolist(), "shift_over_sd": ratio}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("code")
    parser.add_argument("--seeds", type=int, nargs="+", default=[11, 12, 13, 14])
    parser.add_argument("--noise", choices=("none", "force", "strain", "all"), default="strain")
    args = parser.parse_args()
    jax.config.update("jax_enable_x64", True)
    params, config, quirks = read_truth()[args.code]
    out = {}
    for seed in args.seeds:
        data = simulate_dataset(
            args.code, params, config=config, quirks=quirks, seed=seed, repeats=3, specimens=2, noise=_noise(args.noise)
        )
        out[seed] = friction_shift(args.code, data)
        print(f"seed {seed}: shift / sd {np.round(out[seed]['shift_over_sd'], 3).tolist()}", flush=True)
    print(json.dumps({"material": args.code, "noise": args.noise, "seeds": out}))


if __name__ == "__main__":
    main()

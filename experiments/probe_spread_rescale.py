"""Probe (not a study row; kept by git history): does the spread-rescale move (SpreadRescale in
peano_bayes/inference/kernels.py) speed up the slow recovery fit? The held TP 7101 fit of the drawn-constants
study, same data and seed, with the move added to the mix, run to 2158 steps; then emcee's integrated time per
parameter over the same number of post-warm-up steps of this run and of the saved held fit.

    python experiments/probe_spread_rescale.py OUT 2158
    python experiments/probe_spread_rescale.py OUT --compare
"""

import functools
import json
import sys
import time
from pathlib import Path

import emcee

import peano_bayes.app.pipeline as pipeline
from peano_bayes.inference.coordinates import spread_rescale
from peano_bayes.inference.kernels import EmceeEnsemble
from peano_bayes.inference.sample import load_state

HELD = Path("experiments/recovery-drawn-constants/fits/TP_7101_held/sampler_state.npz")


def run(out: Path, steps: int) -> None:
    real = pipeline.sample

    def patched(posterior, centre, covariance, **kw):
        move = spread_rescale(posterior, getattr(kw.get("coordinates"), "noncentred", ()))
        return real(posterior, centre, covariance, kernel=functools.partial(EmceeEnsemble, rescale=move), **kw)

    pipeline.sample = patched
    t0 = time.time()
    s = pipeline.infer(
        Path("experiments/recovery-drawn-constants/data/TP_7101.csv"),
        out,
        label="TP_7101_held",
        seed=7101,
        progress=False,
        figures=False,
        max_steps=steps,
        resume=(out / "TP_7101_held" / "sampler_state.npz").exists(),
        log=lambda m: print(f"{time.time() - t0:7.0f}s {m}", flush=True),
    )
    print(json.dumps(s["convergence"]))


def compare(out: Path, held_end: int = 700, probe_end: int = 1050) -> None:
    held, _, _, meta = load_state(HELD)
    probe, _, _, _ = load_state(out / "TP_7101_held" / "sampler_state.npz")
    n = probe.shape[0] - probe_end
    th = emcee.autocorr.integrated_time(held[held_end : held_end + n], tol=0)
    tp = emcee.autocorr.integrated_time(probe[probe_end : probe_end + n], tol=0)
    for name, a, b in zip(meta["names"], th, tp, strict=True):
        print(f"{name:50s} held {a:7.1f}  probe {b:7.1f}")
    print(json.dumps({"window": n, "held_tau_max": float(th.max()), "probe_tau_max": float(tp.max())}))


if __name__ == "__main__":
    if sys.argv[2] == "--compare":
        compare(Path(sys.argv[1]))
    else:
        run(Path(sys.argv[1]), int(sys.argv[2]))

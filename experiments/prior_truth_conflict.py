"""Where the bundled data's generating parameters sit in the bundled priors, in prior sd.

    python experiments/prior_truth_conflict.py --out experiments/prior-truth-conflict/after.json

For each of the eight bundled materials and each parameter its generating model (``true_parameters.toml``) and
its prior share: the standard-normal score of the prior's truncated CDF at the generating value
(:meth:`peano_bayes.inference.priors.Marginal.position`; 0 at the prior median, -2 where a normal prior has its
2.3 % quantile). A recovery study draws its data from these values, so a value far in a tail is a place where a
correct posterior follows its prior away from the truth wherever the data leave a direction open. Also, per
material, the share of the 0 kPa tangent stiffness at -1.5 % strain that the passive extension element carries
in the generating model (its own ``k exp(0.015 rate)`` over the whole muscle's, from
:func:`peano_bayes.analysis.metrics.zero_kpa_stiffness`): the figure the extension priors had been given is the
whole muscle's.

Prints one line per material and, last, one JSON object (also written to ``--out``): ``scores`` material ->
parameter -> score, ``beyond`` material -> the parameters beyond ``--sd`` (3) in a tail (a halfnormal's lower end
is its mode, not a tail), ``extension_share`` material -> the share above.
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

from free_strain_truth import generating

from peano_bayes.analysis.metrics import STIFFNESS_STRAIN, zero_kpa_stiffness
from peano_bayes.atomic import write_text
from peano_bayes.inference.prior_files import prior_for
from peano_bayes.materials import GEOMETRY, MATERIALS
from peano_bayes.rig import apply_quirks


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, help="where to write the JSON object too")
    parser.add_argument("--sd", type=float, default=3.0, help="prior sd beyond which a value counts as in a tail")
    args = parser.parse_args()
    scores, beyond, share = {}, {}, {}
    for code in MATERIALS:
        params, config, quirks = generating(code)
        prior = prior_for(code)
        mine = {n: float(prior.marginals[n].position(v)) for n, v in params.items() if n in prior.marginals}
        scores[code] = {n: round(z, 3) for n, z in mine.items()}
        beyond[code] = [n for n, z in mine.items() if prior.marginals[n].in_tail(z, args.sd)]
        if "extension_k_n_per_m" in params:
            rate = {**config.nominal_parameters(), **params}["extension_rate"]  # held at nominal where not listed
            element = params["extension_k_n_per_m"] * math.exp(-STIFFNESS_STRAIN * rate)
            whole = zero_kpa_stiffness(params, apply_quirks(config, quirks), GEOMETRY)
            share[code] = round(element / whole, 4)
        z = scores[code].get("extension_k_n_per_m")
        print(f"{code}: extension_k_n_per_m {z:+.2f} prior sd, element {share.get(code)} of the 0 kPa stiffness; "
              f"beyond {args.sd:g}: {beyond[code]}", flush=True)  # fmt: skip
    out = {"sd": args.sd, "scores": scores, "beyond": beyond, "extension_share": share}
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        write_text(args.out, json.dumps(out, indent=1) + "\n")
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

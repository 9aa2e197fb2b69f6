"""Where each hideable effect shows: its noise-free signal per rig test at the benchmark's strength for SNR 2.

For every effect the discovery benchmark hides (``effects.hideable()``), the strength at which its largest
per-test SNR is 2 (``strength_for_snr``), then RMS(with - without) / sigma on each of the four tests
(``snr_by_test``; sigma the rig's per-sample noise). The registry scores an effect on the first test of its
``shows_in``, meant to be where the effect moves the signal most; this table says whether it is. The last line
printed is one JSON object.

    python experiments/snr_by_test.py [--snr 2.0]
"""

from __future__ import annotations

import argparse
import json

from peano_bayes.effects import LIBRARY, hideable
from peano_bayes.validation.discovery_benchmark import snr_by_test, strength_for_snr


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--snr", type=float, default=2.0)
    args = parser.parse_args()
    out = {}
    for effect in hideable():
        strength = strength_for_snr(effect, args.snr)
        by_test = snr_by_test(effect, strength)
        scored = LIBRARY[effect].scored_test
        largest = max(by_test, key=by_test.get)
        out[effect] = {"strength": strength, "snr": by_test, "scored_test": scored, "largest": largest}
        shown = ", ".join(f"{t} {v:.2f}" for t, v in sorted(by_test.items()))
        flag = "" if scored == largest else f"  (scored on {scored}: {by_test[scored]:.2f})"
        print(f"{effect}: {shown}; largest {largest}{flag}", flush=True)
    print(json.dumps(out))


if __name__ == "__main__":
    main()

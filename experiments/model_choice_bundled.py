"""Does the sampled model contain every generating element the fitted tests can see, on the eight bundled files?

The generating elements of each bundled file are its ``config_*`` entries and physics ``quirks`` in
``peano_bayes/bundled/data/true_parameters.toml``, read as library effects
(:func:`peano_bayes.discovery.choice.effects_in`); an effect is visible in the fitted tests when one of them is
among the tests its signature shows in (``Effect.shows_in``). The sampled model is read from each material's
``summary.json`` in RESULTS (``model.effects``, written by ``peano-bayes run``/``fit``; with ``--discover`` it
holds what discovery added) or, without RESULTS, is the configured model (the prior's ``[config]``), which
``run`` samples without ``--discover`` and which discovery only adds to.

    python experiments/model_choice_bundled.py [RESULTS]

Last line: one JSON object with per material the visible generating effects, the sampled ones, the missing
ones, discovery's verdict and named effects (when recorded), and ``all_contained``.
"""

from __future__ import annotations

import json
import sys
import tomllib
from importlib import resources
from pathlib import Path

from peano_bayes.defaults import DEFAULT_TESTS
from peano_bayes.discovery.choice import effects_in
from peano_bayes.discovery.effects import LIBRARY
from peano_bayes.inference.priors import load_prior
from peano_bayes.physics.model import ModelConfig


def generating_effects(entry: dict) -> set[str]:
    config = ModelConfig(**{k.removeprefix("config_"): v for k, v in entry.items() if k.startswith("config_")})
    return set(effects_in(config)) | {q for q in entry.get("quirks", ()) if q in LIBRARY}


def main(argv: list[str]) -> int:
    results = Path(argv[0]) if argv else None
    truth_text = resources.files("peano_bayes.bundled").joinpath("data/true_parameters.toml").read_text()
    truth = tomllib.loads(truth_text)
    out, all_contained = {}, True
    print(f"{'material':9s} {'visible generating effects':90s} missing  discovery")
    for code, entry in truth.items():
        discovery = None
        if results is not None:
            summary = json.loads((results / code / "summary.json").read_text())
            tests = summary["tests"]
            if "model" in summary:
                sampled, discovery = set(summary["model"]["effects"]), summary["model"]["discovery"]
            else:  # written before the model was recorded: the configured model was sampled
                sampled = set(effects_in(load_prior(code).config))
        else:
            tests, sampled = list(DEFAULT_TESTS), set(effects_in(load_prior(code).config))
        visible = {e for e in generating_effects(entry) if set(LIBRARY[e].shows_in) & set(tests)}
        missing = sorted(visible - sampled)
        all_contained &= not missing
        named = "not run" if discovery is None else f"{discovery['verdict']}: {', '.join(discovery['named'])}"
        print(f"{code:9s} {', '.join(sorted(visible)):90s} {', '.join(missing) or '-':8s} {named}")
        out[code] = {
            "tests": list(tests),
            "generating_visible": sorted(visible),
            "sampled": sorted(sampled),
            "missing": missing,
            "discovery": discovery,
        }
    source = str(results) if results is not None else "configured models (bundled priors)"
    print(json.dumps({"source": source, "materials": out, "all_contained": all_contained}))
    return 0 if all_contained else 1


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))

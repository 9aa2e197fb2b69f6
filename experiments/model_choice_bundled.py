"""Does the sampled model contain every generating element the fitted tests can see, on the eight bundled files?

The generating elements of each bundled file are its ``config_*`` entries and physics ``quirks`` in
``peano_bayes/bundled/data/true_parameters.toml``, read as library effects
(:func:`peano_bayes.effects.effects_in`); an effect is visible in the fitted tests when one of them is
among the tests its signature shows in (``Effect.shows_in``). The sampled model is read from each material's
``summary.json`` in RESULTS (``model.effects``, written by ``peano-bayes run``/``fit``; with discovery it
holds what discovery added) or, without RESULTS, is the configured model (the prior's ``[config]``), which
``run --no-discover`` samples and which discovery only adds to. With ``--discover OUT`` it runs the
model choice of ``run`` itself on each bundled file (discovery from the configured model on the
fitted tests, :func:`peano_bayes.discovery.choice.choose_model`, seed 0, its base fit started at the configured
model's inference least squares as ``run`` does; reports in ``OUT/<code>/``; a report
already there is read back instead of run again) and checks the model that choice would sample.

    python experiments/model_choice_bundled.py [RESULTS | --discover OUT]

Last line: one JSON object with per material the visible generating effects, the sampled ones, the missing
ones, discovery's verdict and named effects (when recorded), and ``all_contained``.
"""

from __future__ import annotations

import argparse
import json
import sys
import tomllib
from importlib import resources
from pathlib import Path

from peano_bayes.app.pipeline import prior_of, select_tests
from peano_bayes.bundled import dataset_path
from peano_bayes.data import load
from peano_bayes.defaults import DEFAULT_STARTS, DEFAULT_TESTS
from peano_bayes.discovery.choice import choice_from_report, choose_model
from peano_bayes.effects import LIBRARY, effects_in
from peano_bayes.inference.driver import least_squares
from peano_bayes.inference.posterior import DEFAULT_HELD, build_posterior
from peano_bayes.inference.prior_files import load_prior
from peano_bayes.inference.reduce import prepare
from peano_bayes.physics.model import ModelConfig


def generating_effects(entry: dict) -> set[str]:
    config = ModelConfig(**{k.removeprefix("config_"): v for k, v in entry.items() if k.startswith("config_")})
    return set(effects_in(config)) | {q for q in entry.get("quirks", ()) if q in LIBRARY}


def discovered(code: str, out: Path) -> tuple[list[str], set[str], dict]:
    """The fitted tests, the effects of the model ``run`` samples, and discovery's record, for the
    bundled file ``code`` (discovery run into ``out/code`` unless its report is there already)."""
    dataset = select_tests(load(dataset_path(code)), DEFAULT_TESTS)
    prior = load_prior(code)
    config = prior.config
    folder = out / code
    if (folder / "report.json").exists():
        choice = choice_from_report(config, json.loads((folder / "report.json").read_text()), folder)
    else:
        say = lambda m: print(f"{code}: {m}", flush=True)  # noqa: E731
        # as `run` does: the configured model's inference least squares on the fitted tests, discovery's base fit
        # started at its optimum
        whole = prior_of(dataset, None)
        part = whole.for_config(config)
        posterior = build_posterior(prepare(dataset), part, config=config, held=DEFAULT_HELD)
        fitted = least_squares(posterior, part, n_starts=DEFAULT_STARTS, seed=0)
        say(f"least squares {fitted.outcome()} in {fitted.seconds:.0f} s")
        choice = choose_model(dataset, config, folder, seed=0, log=say, start=fitted.params)
    record = {"verdict": choice.verdict, "named": list(choice.named), "adopted": list(choice.adopted)}
    return list(dataset.tests), set(effects_in(choice.config)), record


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(
        description="Does the sampled model contain every generating element the fitted tests can see, on the "
        "eight bundled files?"
    )
    source = parser.add_mutually_exclusive_group()
    source.add_argument(
        "results", nargs="?", type=Path, metavar="RESULTS", help="a main job's results (RESULTS/<code>/summary.json)"
    )
    source.add_argument(
        "--discover", type=Path, metavar="OUT", help="run `run`'s model choice on each bundled file, reports into OUT"
    )
    args = parser.parse_args(argv)
    discover_out, results = args.discover, args.results
    truth_text = resources.files("peano_bayes.bundled").joinpath("data/true_parameters.toml").read_text()
    truth = tomllib.loads(truth_text)
    out, all_contained = {}, True
    print(f"{'material':9s} {'visible generating effects':90s} missing  discovery")
    for code, entry in truth.items():
        discovery = None
        if discover_out is not None:
            tests, sampled, discovery = discovered(code, discover_out)
        elif results is not None:
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
    if discover_out is not None:
        source = f"run's model choice (reports in {discover_out})"
    else:
        source = str(results) if results is not None else "configured models (bundled priors)"
    print(json.dumps({"source": source, "materials": out, "all_contained": all_contained}))
    return 0 if all_contained else 1


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))

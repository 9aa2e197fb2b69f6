"""Discovery on the paper's eight muscles (the bundled datasets).

For each material: ``discover`` on specimen A's load cycles, blocking and stroke tests (the 1 kHz step
response is left out: its 801-sample backward-Euler simulation makes each refit minutes long, so
``flow_restriction`` and ``nonlinear_damping`` are not assessed here), up to four effects, from the default base
(ideal geometry + tensile + bending stiffness). Writes ``OUT/<CODE>/report.{json,md}`` and figures, and
``OUT/SUMMARY.md``: what was found, beside the elements the synthetic data were generated with (their
provenance records them) and beside what the paper says. Resumable: a material with a report is skipped.

    python experiments/discover_bundled.py
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from peano_bayes import bundled, enable_compilation_cache
from peano_bayes.app.pipeline import BUNDLED_MATERIALS
from peano_bayes.atomic import write_text
from peano_bayes.data import load
from peano_bayes.discovery import Gates, discover, discovery_data, write_report
from peano_bayes.effects import physics_effects

HERE = Path(__file__).resolve().parent
TESTS = ("load_cycle", "blocking", "stroke")
#: ModelConfig switches of the generating model -> the effect they are (those visible without the step).
GENERATING = {
    "friction": "hysteresis",
    "extension": "strain_stiffening",
    "mount": "series_compliance",
    "parallel_maxwell": "viscoelastic_relaxation",
    "series_kelvin": "series_viscoelastic",
    "threshold": "threshold_pressure",
}
#: Generating switches whose effect shows only in the step response, which is not used here.
STEP_ONLY = {"damping": "nonlinear_damping"}


def generating_effects(dataset, switches: dict = GENERATING) -> list[str]:
    """The effects of ``switches`` that the dataset's generating model (its provenance) had on."""
    config = json.loads(dict(dataset.provenance)["config"])
    return [effect for key, effect in switches.items() if config.get(key) not in (False, 0, "none", None)]


def _verdict(row: dict) -> str:
    return row["verdict"] + (f" ({'; '.join(row['ambiguous'])})" if row["ambiguous"] else "")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default=str(HERE / "discovery"))
    parser.add_argument("--materials", nargs="+", default=list(BUNDLED_MATERIALS))
    args = parser.parse_args(argv)
    enable_compilation_cache()
    out = Path(args.out)
    rows = []
    for code in args.materials:
        dataset = load(bundled.dataset_path(code))
        target = out / code
        if (target / "report.json").exists():
            report = json.loads((target / "report.json").read_text())
        else:
            print(f"{code}: discovering ...", flush=True)
            result = discover(
                discovery_data(dataset, specimen="A", tests=TESTS), gates=Gates(max_effects=4), progress=print
            )
            write_report(result, target)
            report = result.report
        truth = generating_effects(dataset)
        # Physics only: a noise-side winner of an ambiguous step (a sensor gain against a mount) is in noise_model.
        rivals = [e for a in report["ambiguous"] for e in a["effects"] if e in physics_effects()]
        found = report["named"] + [e for e in rivals if e not in report["named"]]
        rows.append(
            {
                "material": code,
                "pressure_kpa": dataset.conditions.test_pressure_pa / 1e3,
                "verdict": report["verdict"],
                "ambiguous": [" or ".join(a["effects"]) for a in report["ambiguous"]],
                "found": found,
                "noise_model": report["noise_model"],
                "generated_with": truth,
                "generated_step_only": generating_effects(dataset, STEP_ONLY),
                "missed": [e for e in truth if e not in found],
                "extra": [e for e in found if e not in truth],
                "seconds": report["seconds"],
            }
        )
        print(json.dumps(rows[-1]), flush=True)
    lines = [
        "# Discovery on the eight bundled muscles",
        "",
        f"Specimen A, tests {', '.join(TESTS)}, base model tensile + bending stiffness, up to 4 effects. "
        "The bundled data are synthetic (see README), so the elements they were generated with are known; "
        "the step response is not used, so inlet restriction and load damping are not assessed (the last column "
        "lists what the data hold that only the step response shows).",
        "",
        "| material | test pressure [kPa] | verdict | effects found (in order) | noise model | generated with | "
        "missed | extra | time [s] | generated, step only |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['material']} | {r['pressure_kpa']:.0f} | {_verdict(r)} | {', '.join(r['found']) or '-'} | "
            f"{', '.join(r['noise_model']) or '-'} | {', '.join(r['generated_with'])} | "
            f"{', '.join(r['missed']) or '-'} | {', '.join(r['extra']) or '-'} | {r['seconds']:.0f} | "
            f"{', '.join(r['generated_step_only']) or '-'} |"
        )
    write_text(out / "SUMMARY.md", "\n".join(lines) + "\n")
    print("\n".join(lines))
    print(json.dumps({"materials": rows}))
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""The discovery benchmark's existing cases make the data they made before the other-physics and drawn-condition
cases were added (issue 80, item 5): ``experiments/discrepancy_rerun.py`` re-runs recorded rows of old final runs,
so a default :class:`Case` must give the same bits.

The expected values were computed from commit 93e3fbc (before the change), by the same code as below, and pasted
here; they are not produced by the code under test. ``digest``: SHA-256 of every run's key, signal names and
float64 bytes (bit-for-bit; the same under the suite's XLA optimization level 1 and the default level on the
machine they were made on, JAX as pinned in constraints.txt). ``compact``: per signal, the sum over runs (weighted
by their 1-based position) of ``sum(w x^2)`` with ``w`` linear from 1 to 2 over the run (NaN as 0), a portable
check to 1e-10 relative that says which signal moved if the digest ever differs.
"""

import hashlib

import numpy as np
import pytest

from peano_bayes.data.dataset import SIGNALS
from peano_bayes.validation.discovery_benchmark import TWO_MOUNTS, Case, hidden_dataset, run_key, snr_by_test

#: name -> (case, seed, strengths, quiet).
CASES = {
    "none": (Case(), 100, None, False),
    "none-quiet": (Case(), 100, None, True),
    "veale": (Case(physics="veale"), 100, None, False),
    "hysteresis": (Case(("hysteresis",), 2.0), 101, {"hysteresis": 0.7}, False),
    "drift": (Case(drift=True), 102, None, False),
    "mount2": (Case(("series_compliance",), 2.0, mounts=TWO_MOUNTS), 103, {"series_compliance": 0.5}, False),
    "softening": (Case(("cyclic_softening",), 2.0), 104, {"cyclic_softening": 0.5}, False),
}

#: name -> (label, run key, digest, compact), from commit 93e3fbc.
EXPECTED = {
    "none": ("none", "none|0|0.2|0|100", "36e96212d5820a9697d58c17929155cd211e2095d77bbaf73c85ab810d6cc3e3",
             {"time_s": 681226.176, "pressure_pa": 420720389417522.0, "strain": 113.358518042569,
              "force_n": 92583974.651604, "supply_pa": 167949181713717.0, "flow_m3_per_s": 5.89548212772903e-05,
              "load_n": 7782087.375}),
    "none-quiet": ("none", "none|0|0.2|0|100", "e6aa2c2fa79ab5d2f7bc1e77eb393cf04d0f19c13b1d549ef9a9325c9302a9ea",
                   {"time_s": 681226.176, "pressure_pa": 420639669470498.0, "strain": 113.389465689127,
                    "force_n": 92586552.7798061, "supply_pa": 167932800000000.0,
                    "flow_m3_per_s": 5.89590743743153e-05, "load_n": 7782087.375}),
    "veale": ("none-veale", "none-veale|0|0.2|0|100",
              "a5d973951101de6cdcd70bf04943e79446f39c1877b77ed3adc03bff2ee3c8c6",
              {"time_s": 681057.0, "pressure_pa": 253545375468935.0, "strain": 53.6645765126265,
               "force_n": 80305925.9616965, "load_n": 121287.375}),
    "hysteresis": ("hysteresis", "hysteresis|2|0.2|0|101",
                   "045efaa0a9580a87f6ffddbb8a84aa8da2544957b6721618c76fd8f52daf0427",
                   {"time_s": 681226.176, "pressure_pa": 420805822965447.0, "strain": 110.627963640562,
                    "force_n": 90750860.5090485, "supply_pa": 167996919242719.0,
                    "flow_m3_per_s": 5.60657693533622e-05, "load_n": 7782087.375}),
    "drift": ("drift", "drift|0|0.2|1|102", "79911bbb7d0370680cb0bc7f88680fbf06438f88ac398ffcfa81968627f61d11",
              {"time_s": 681226.176, "pressure_pa": 420416616924363.0, "strain": 112.36350754028,
               "force_n": 92893165.6161882, "supply_pa": 167977071054732.0, "flow_m3_per_s": 5.88988843691783e-05,
               "load_n": 7782087.375}),
    "mount2": ("series_compliance@2mounts", "series_compliance@2mounts|2|0.2|0|103",
               "3679461e1f8cbcce02d9fac097ceaf5ea40bad80b62ef624d9d015427821fce5",
               {"time_s": 3810723.612, "pressure_pa": 1625981149247850.0, "strain": 350.276525819476,
                "force_n": 239590076.318361, "supply_pa": 515867284220246.0, "flow_m3_per_s": 0.00023710557507638,
                "load_n": 23937566.625, "added_compliance_m_per_n": 2.1834e-05}),
    "softening": ("cyclic_softening", "cyclic_softening|2|0.2|0|104",
                  "22340bb69f7df0ae3a1c4ddc718515cdc31839fddb132e9f1422de08ddb7515e",
                  {"time_s": 681226.176, "pressure_pa": 420635532632894.0, "strain": 115.851713354144,
                   "force_n": 92894587.855153, "supply_pa": 167875515509173.0,
                   "flow_m3_per_s": 5.93798750239519e-05, "load_n": 7782087.375}),
}  # fmt: skip

#: ``snr_by_test("hysteresis", 0.7)`` at commit 93e3fbc: the calibration of the fixed-protocol cases.
EXPECTED_SNR = {"blocking": 13.0165694009213, "load_cycle": 11.1417521082432, "step": 26.6919577093677,
                "stroke": 7.32069193749438}  # fmt: skip


def digest(dataset) -> str:
    h = hashlib.sha256()
    for run in dataset.runs:
        h.update(repr(run.key).encode())
        for name in SIGNALS:
            values = getattr(run, name)
            h.update(name.encode())
            if values is not None:
                h.update(np.ascontiguousarray(values).tobytes())
    return h.hexdigest()


def compact(dataset) -> dict[str, float]:
    out = {}
    for position, run in enumerate(dataset.runs, start=1):
        w = np.linspace(1.0, 2.0, len(run))
        for name in SIGNALS:
            values = getattr(run, name)
            if values is not None:
                x = np.nan_to_num(values, nan=0.0)
                out[name] = out.get(name, 0.0) + position * float(np.sum(w * x * x))
    return out


@pytest.mark.parametrize("name", list(CASES))
def test_an_old_default_case_makes_the_same_data_as_before(name):
    case, seed, strengths, quiet = CASES[name]
    label, key, expected_digest, expected_compact = EXPECTED[name]
    assert (case.label, run_key(case, seed)) == (label, key)
    dataset = hidden_dataset(case, seed, strengths, quiet=quiet)
    got = compact(dataset)
    assert set(got) == set(expected_compact)
    for signal, value in expected_compact.items():
        assert got[signal] == pytest.approx(value, rel=1e-10), signal
    assert digest(dataset) == expected_digest


def test_the_fixed_protocol_calibration_is_unchanged():
    got = snr_by_test("hysteresis", 0.7)
    assert got == pytest.approx(EXPECTED_SNR, rel=1e-10)

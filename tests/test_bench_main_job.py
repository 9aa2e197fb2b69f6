"""The main-job benchmark's wall time over a run stopped and continued: the parts its ``run.log`` records."""

import calendar
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parents[1] / "experiments"))

from bench_main_job import wall_parts  # noqa: E402


def test_a_run_stopped_and_continued_counts_each_part_from_its_start_to_its_last_line(tmp_path):
    log = tmp_path / "run.log"
    log.write_text(
        "2026-12-08T01:00:00Z running 8 dataset(s) on 2 local worker processes\n"
        "2026-12-08T01:00:04Z TP: least squares from up to 16 starts ...\n"
        "  a continuation line without a timestamp\n"
        "2026-12-08T02:30:00Z TP: sampling step 900 (warm-up 450): ...\n"
        "2026-12-08T09:00:00Z TP: not converged at 900 steps; resuming with a larger step limit\n"
        "2026-12-08T09:00:01Z running 6 dataset(s) on 2 local worker processes\n"
        "2026-12-08T09:40:01Z FC: done in 2400 s\n"
    )
    parts = wall_parts(log)
    # the first part ends at its own last line (02:30), not at the next invocation's resuming line (09:00)
    assert [p["start_utc"] for p in parts] == ["2026-12-08T01:00:00Z", "2026-12-08T09:00:01Z"]
    assert [p["wall_s"] for p in parts] == [90 * 60, 40 * 60]


def test_only_lines_before_a_resumed_invocation_count_towards_the_earlier_parts(tmp_path):
    log = tmp_path / "run.log"
    log.write_text(
        "2026-12-08T01:00:00Z running 8 dataset(s) on 2 local worker processes\n"
        "2026-12-08T02:00:00Z FC: warm-up step 700: ...\n"
        "2026-12-08T09:00:00Z TP: results/TP/summary.json exists, skipped\n"
        "2026-12-08T09:10:00Z FC: sampling step 900 (one material left: no running line)\n"
    )
    before = calendar.timegm((2026, 12, 8, 9, 0, 0, 0, 0, 0))
    assert [p["wall_s"] for p in wall_parts(log, before=before)] == [3600]

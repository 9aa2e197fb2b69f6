"""``peano-bayes fit`` and ``run`` refuse bad input with exit status 2, one line on stderr, nothing written."""

import pytest

from peano_bayes.app.cli import main


@pytest.mark.parametrize(
    "argv, expected",
    [
        (["fit", "no/such/file.csv", "--out", "{out}"], "no/such/file"),
        (["fit", "tests/malformed/valid.csv", "--out", "{out}", "--chunk", "0"], "--chunk must be >= 1"),
        (["fit", "tests/malformed/valid.csv", "--out", "{out}", "--walkers", "2"], "--walkers must be >= 4"),
        (["fit", "tests/malformed/valid.csv", "--out", "{out}", "--walkers", "4"], "fewer than twice the"),
        (["run", "--out", "{out}", "--materials", "XX"], "unknown material(s) XX"),
        (["run", "--out", "{out}", "--jobs", "0"], "--jobs must be >= 1"),
    ],
)
def test_bad_input_exits_2_without_writing(tmp_path, capsys, argv, expected):
    out = tmp_path / "out"
    code = main([a.format(out=out) for a in argv])
    captured = capsys.readouterr()
    assert code == 2
    assert expected in captured.err
    assert "Traceback" not in captured.err
    assert not out.exists()

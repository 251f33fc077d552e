"""A mistyped option is named by the (sub)command it was given to, with the option it most likely meant.

argparse alone reports an unknown option of `bench run` as `bench: error: unrecognized arguments` with the top
level's usage, which does not list `bench run`'s options; a newcomer then has to guess where the typo was.
"""

from __future__ import annotations

import pytest

from bench.cli import main


def error_line(capsys: pytest.CaptureFixture[str], argv: list[str]) -> str:
    with pytest.raises(SystemExit) as stop:
        main(argv)
    assert stop.value.code == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err
    return err.strip().splitlines()[-1]


@pytest.mark.parametrize(("argv", "prog", "typo", "meant"), [
    (["run", "--interfce", "virtual"], "bench run", "--interfce", "--interface"),
    (["run", "--chanel=vcan0"], "bench run", "--chanel=vcan0", "--channel"),
    (["run", "--dutt", "VCU"], "bench run", "--dutt", "--dut"),
    (["log", "info", "--stats", "x.mcap"], "bench log info", "--stats", None),
    (["plant", "--vehicel", "EV4WIS"], "bench plant", "--vehicel", "--vehicle"),
])
def test_unknown_option_names_its_command_and_the_close_option(capsys: pytest.CaptureFixture[str], argv: list[str],
                                                               prog: str, typo: str, meant: str | None) -> None:
    line = error_line(capsys, argv)
    assert line.startswith(f"{prog}: error: unrecognized arguments: {typo}"), line
    if meant is None:
        assert "did you mean" not in line, line
    else:
        assert f"{typo} (did you mean {meant}?)" in line, line


def test_an_option_like_no_other_gets_no_guess(capsys: pytest.CaptureFixture[str]) -> None:
    line = error_line(capsys, ["run", "--bogus"])
    assert line == "bench run: error: unrecognized arguments: --bogus", line

"""The bench's errors: each names the input and what is wrong, so the CLI can print it without a traceback."""

from __future__ import annotations

import difflib
from collections.abc import Iterable


class BenchError(Exception):
    """Base of every error the bench reports to a user as a one-line message."""


class Inconclusive(BenchError):
    """The bench cannot stand behind the verdict of the case in progress, through no fault of the DUT: the case
    ends with the outcome "inconclusive" and this message, never "failed" (bench.pytest.plugin). Raised by the
    watchdog (bench time fell behind wall time, bench.sim.clock.Scheduler) and by a limit of the bench itself
    (BenchLimit)."""


class BenchLimit(Inconclusive):
    """A limit of the bench itself was reached (e.g. the history a case asked for outgrew what the monitor keeps):
    the bench's error, named as such, never the DUT's."""


class ConfigError(BenchError):
    """A bad command-line value or configuration file."""


class InputProblems(ConfigError):
    """Several bad inputs found by one check: `bench.cli.main` prints each on its own line."""

    def __init__(self, problems: list[str]) -> None:
        super().__init__("; ".join(problems))
        self.problems = problems


class DatabaseError(BenchError):
    """A DBC file that cannot be loaded or does not meet the bench's needs."""


class SignalError(BenchError):
    """A signal value that cannot be encoded (unknown name, NaN, out of range)."""


class LogError(BenchError):
    """A run log (MCAP) that cannot be written or read: missing, not MCAP, or bad data given to the recorder."""


def did_you_mean(name: str, known: Iterable[str]) -> str:
    """' (did you mean X?)' when one known name is close to a mistyped one, else ''. Case and a leading '-'
    are ignored in the comparison ('--chanel' -> '--channel', 'Voltge' -> 'Voltage')."""
    by_key = {k.lstrip("-").lower(): k for k in known}
    close = difflib.get_close_matches(name.lstrip("-").lower(), by_key, n=1, cutoff=0.6)
    return f" (did you mean {by_key[close[0]]}?)" if close else ""


def unknown_names(what: str, names: Iterable[str], known: Iterable[str], also: str = "") -> str:
    """'WHAT: unknown node(s) A (did you mean B?), C (nodes: ...)': one line for names not in `known`, each with the
    name most likely meant; `also` ends the list of the known ones (e.g. ", or 'all'")."""
    choices = list(known)
    named = ", ".join(f"{n}{did_you_mean(n, choices)}" for n in names)
    return f"{what}: unknown node(s) {named} (nodes: {', '.join(choices)}{also})"

"""Every run option declared once: one table from which `bench run`'s argparse options and the pytest
plugin's `--bench-*` options are both built, and which hands the one to the other.

Why: the command line and a plain `pytest` run must accept the same settings with the same help, types and
error messages; written twice they drift. A spec names the option as the command line spells it
(`--interface`); the plugin spells it `--bench-interface`. Some options belong to one side only (`--force`,
`-n`): `plugin=False`, and `passthrough` names the pytest option the command line hands them to.
"""

from __future__ import annotations

import argparse
import re
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Literal

from bench.faults import kinds as fault_kinds

Kind = Literal["value", "list", "flag", "switch"]
#: value: one value; list: repeatable (the command line also takes several after one flag when `many`);
#: flag: on when given; switch: --x / --no-x, None when neither is given.


@dataclass(frozen=True)
class OptionSpec:
    """One option, as both the command line and pytest declare it."""

    name: str                                    # long name without dashes, e.g. "data-bitrate"
    help: str                                    # may hold {default}
    kind: Kind = "value"
    type: Callable[[str], Any] | None = None     # parses and checks the text (argparse.ArgumentTypeError)
    default: Any = None
    choices: tuple[str, ...] | None = None
    metavar: str | None = None
    group: str = "run"                           # "bus", "nodes", "run": the help's sections
    short: str | None = None                     # command line only, e.g. "-i"
    aliases: tuple[str, ...] = ()                # further command-line spellings, e.g. "--overwrite"
    many: bool = False                           # list: several values after one flag on the command line
    plugin: bool = True                          # the pytest plugin declares --bench-NAME
    passthrough: str | None = None               # plugin=False: the pytest option `bench run` hands it to
    plugin_help: str | None = None               # the plugin's help where the command line's would mislead

    @property
    def dest(self) -> str:
        """The attribute on the command line's namespace (`args.data_bitrate`)."""
        return self.name.replace("-", "_")

    @property
    def pytest_name(self) -> str:
        return f"--bench-{self.name}"

    @property
    def pytest_dest(self) -> str:
        """The attribute on pytest's `config.option` (`bench_data_bitrate`)."""
        return f"bench_{self.dest}"


def positive_bitrate(text: str) -> int:
    """A bitrate as typed: a positive whole number of bit/s."""
    try:
        value = int(text, 10)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number of bit/s") from None
    if value <= 0:
        raise argparse.ArgumentTypeError(f"{text!r} is not a positive number of bit/s")
    return value


def shard(text: str) -> tuple[int, int]:
    """`K/N` -> (K, N): part K of N, 1 <= K <= N."""
    head, slash, tail = text.partition("/")
    try:
        if not slash:
            raise ValueError
        k, n = int(head, 10), int(tail, 10)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not K/N (e.g. 2/3: the second of three shards)") from None
    if n < 1 or not 1 <= k <= n:
        raise argparse.ArgumentTypeError(f"{text!r}: K/N needs 1 <= K <= N (shards are numbered from 1)")
    return k, n


#: --fault's help: the spec pattern, and the kinds as the fault registry lists them (bench.faults.kinds).
FAULT_HELP = ("inject a fault: KIND:TARGET[:PARAM]@[case+]START[-END] in s from the run's start, or with case+ from "
              "each case's start (an open END lasts to the end of the run or case); e.g. drop:MESSAGE@2-3, "
              f"drop:MESSAGE@case+1-2, silence:NODE@case+0.5-; {fault_kinds.help_text()} (docs/reliability.md)")

OPTIONS: tuple[OptionSpec, ...] = (
    # -- bus ---------------------------------------------------------------------------------------------
    OptionSpec("interface", "'embedded' for the bench's own bus (in process, virtual time), or a python-can "
                            "interface (pcan, kvaser, vector, socketcan, udp_multicast, virtual: python-can's "
                            "in-process bus, real time, ...) (default: {default})",
               default="embedded", group="bus", short="-i"),
    OptionSpec("channel", "channel (e.g. PCAN_USBBUS1, 0, can0, a multicast group); not for the embedded bus",
               group="bus", short="-c"),
    OptionSpec("bitrate", "nominal bitrate (default: [bus] bitrate of bench.toml, else the databases' Baudrate "
                          "attribute, the contract's bus); the embedded bus ignores it",
               type=positive_bitrate, metavar="BIT/S", group="bus"),
    OptionSpec("fd", "CAN FD (default: [bus] fd, else on when the databases' BusType is CAN FD); "
                     "the no- form: classic CAN even where [bus] or the databases say CAN FD",
               kind="switch", group="bus"),
    OptionSpec("data-bitrate", "CAN FD data-phase bitrate (needs --fd)", type=positive_bitrate, metavar="BIT/S",
               group="bus"),
    OptionSpec("config", "the project's bench.toml ([bus] table: further python-can arguments; default: found "
                         "from here)", group="bus"),
    # -- nodes -------------------------------------------------------------------------------------------
    OptionSpec("external", "nodes that are real, not simulated ('all' = every node but the stimulus)",
               kind="list", many=True, metavar="NODE", group="nodes"),
    OptionSpec("fault", FAULT_HELP, kind="list", metavar="SPEC", group="nodes"),
    # -- run ---------------------------------------------------------------------------------------------
    OptionSpec("dut", "only the cases that judge NODE (@pytest.mark.dut); the report's conformance section lists "
                      "the others as deselected", kind="list", many=True, metavar="NODE"),
    OptionSpec("shard", "run part K of N of the campaign (pytest-split, balanced by the recorded case durations "
                        "of --durations); `bench report merge` joins the N report folders. Combines with -n: "
                        "the shard's cases are then shared by the workers",
               type=shard, metavar="K/N"),
    OptionSpec("durations", "the recorded case durations the shards are balanced by (pytest-split's JSON; "
                            "default: .test_durations next to bench.toml; docs/ci.md says how to refresh it)",
               metavar="FILE"),
    OptionSpec("out", "output folder (default: a new folder under reports/); an existing non-empty one only "
                      "with --force", plugin_help="folder for report.html, run.mcap, junit.xml (default: a new "
                                                  "folder under reports/)"),
    OptionSpec("force", "write into an existing --out folder that is not empty (its reports are replaced)",
               kind="flag", aliases=("--overwrite",), plugin=False),
    OptionSpec("workers", "run the cases in N processes (pytest-xdist; 'auto' = one per core), each with its own "
                          "embedded bus and MCAP log; one merged report",
               short="-n", metavar="N", plugin=False, passthrough="-n"),
    OptionSpec("keyword", "only cases matching this pytest -k expression", short="-k", plugin=False,
               passthrough="-k"),
)

BY_NAME: Mapping[str, OptionSpec] = {o.name: o for o in OPTIONS}


def _help(spec: OptionSpec, default: Any, text: str | None) -> str:
    return (text or spec.help).replace("{default}", str(default))


def _value_kwargs(spec: OptionSpec) -> dict[str, Any]:
    """type, choices and metavar of an option that takes values (both sides alike)."""
    if spec.kind not in ("value", "list"):
        return {}
    out: dict[str, Any] = {}
    if spec.type is not None:
        out["type"] = spec.type
    if spec.choices:
        out["choices"] = list(spec.choices)
    if spec.metavar:
        out["metavar"] = spec.metavar
    return out


# -- the command line ----------------------------------------------------------------------------------
def add_cli_options(parser: argparse.ArgumentParser, names: Iterable[str], *,
                    defaults: Mapping[str, Any] | None = None, helps: Mapping[str, str] | None = None) -> None:
    """Declare the named options on an argparse parser (bus options in a "bus" section). `defaults` and
    `helps` adapt an option to a command (e.g. `plant` defaults to udp_multicast)."""
    bus: Any = None
    for name in names:
        spec = BY_NAME[name]
        default = (defaults or {}).get(name, spec.default)
        target: Any = parser
        if spec.group == "bus":
            bus = target = bus or parser.add_argument_group("bus")
        if spec.passthrough and spec.short:       # pytest's own spelling (-k, -n) is the command line's too
            flags = [spec.short]
        else:
            flags = [f"--{spec.name}", *([spec.short] if spec.short else []), *spec.aliases]
        kwargs: dict[str, Any] = {"dest": spec.dest, "help": _help(spec, default, (helps or {}).get(name))}
        if spec.kind == "flag":
            kwargs["action"] = "store_true"
        elif spec.kind == "switch":
            kwargs.update(action=argparse.BooleanOptionalAction, default=default)
        elif spec.kind == "list":
            kwargs.update(action="extend" if spec.many else "append", default=list(default or []))
            if spec.many:
                kwargs["nargs"] = "+"
        else:
            kwargs["default"] = default
        target.add_argument(*flags, **kwargs, **_value_kwargs(spec))


def pytest_args(args: argparse.Namespace, names: Iterable[str]) -> list[str]:
    """The command line's values as pytest arguments: `--bench-NAME value` (or the passthrough option) for
    every option that was given; what was not given is left to the plugin's default."""
    out: list[str] = []
    for name in names:
        spec = BY_NAME[name]
        value = getattr(args, spec.dest, None)
        flag = spec.pytest_name if spec.plugin else spec.passthrough
        if flag is None or value is None or value == [] or (spec.kind == "flag" and not value):
            continue
        if spec.kind == "switch":
            out.append(spec.pytest_name if value else f"--bench-no-{spec.name}")
        elif spec.kind == "flag":
            out.append(flag)
        elif spec.kind == "list":
            for item in value:
                out += [flag, _text(spec, item)]
        else:
            out += [flag, _text(spec, value)]
    return out


def _text(spec: OptionSpec, value: Any) -> str:
    if spec.type is shard:
        return f"{value[0]}/{value[1]}"
    return str(value)


#: A command-line spelling in a help text, for the plugin's help: --fd -> --bench-fd.
_PLUGIN_NAMES = re.compile(r"(?<![\w-])--(" + "|".join(re.escape(o.name) for o in OPTIONS if o.plugin) + r")\b(?!-)")


# -- pytest --------------------------------------------------------------------------------------------
def add_pytest_options(group: Any, specs: Sequence[OptionSpec] = OPTIONS) -> None:
    """Declare every plugin option on pytest's option group as `--bench-NAME` (help and types as above)."""
    for spec in specs:
        if not spec.plugin:
            continue
        help_text = _PLUGIN_NAMES.sub(lambda m: f"--bench-{m.group(1)}", _help(spec, spec.default, spec.plugin_help))
        if spec.kind == "switch":
            group.addoption(spec.pytest_name, action="store_true", default=None, dest=spec.pytest_dest,
                            help=help_text)
            group.addoption(f"--bench-no-{spec.name}", action="store_false", default=None, dest=spec.pytest_dest,
                            help=f"the opposite of {spec.pytest_name}")
            continue
        kwargs: dict[str, Any] = {"dest": spec.pytest_dest, "help": help_text}
        if spec.kind == "flag":
            kwargs["action"] = "store_true"
        elif spec.kind == "list":
            kwargs.update(action="append", default=list(spec.default or []))
            kwargs["help"] = help_text + "; repeatable"
        else:
            kwargs["default"] = spec.default
        group.addoption(spec.pytest_name, **kwargs, **_value_kwargs(spec))


def get(config: Any, name: str) -> Any:
    """An option's value in a pytest run (`config.getoption` by the table's name)."""
    return config.getoption(BY_NAME[name].pytest_dest)

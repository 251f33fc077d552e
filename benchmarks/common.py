"""What every benchmark of benchmarks/ shares: the machine, figures with their baseline and target, JSON out.

Each benchmark is a script (`python benchmarks/bench_<name>.py [--quick] [--json PATH]`) that measures one
target of issue 9 and a baseline in the same run, prints its figures and writes them as JSON;
`benchmarks/run_all.py` runs them all, each in its own process (a benchmark never inherits another's
imports, threads or heap), and prints every figure next to its baseline. Only the project's dependencies
are used here (the profilers named in docs/performance.md are for people, not for these scripts).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import random
import resource
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
BENCHMARKS = ROOT / "benchmarks"
CASES = BENCHMARKS / "cases"
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from bench.checks.steps import percentile  # noqa: E402 - the bench's own, after the repository is on sys.path
from bench.e2e import Protection  # noqa: E402


def protection_of(frame_id: int) -> Protection:
    """The E2E protection of an identifier: the project databases' declaration, else the contract's for a raw
    identifier of a benchmark (docs/spec/e2e.md: Profile 11, the identifier as its Data ID, the header at bit 48)."""
    from bench.config import load_config
    from bench.database.codec import load_codebook

    global _CODEBOOK
    if _CODEBOOK is None:
        _CODEBOOK = load_codebook(load_config(ROOT / "bench.toml").databases)
    codec = _CODEBOOK.by_id.get(frame_id)
    if codec is not None and codec.protection is not None:
        return codec.protection
    return Protection("P11", data_id=frame_id, offset=48)


def counter_gap(protection: Protection, previous: int, counter: int) -> int:
    """Frames lost between two received counters of one message (0: in sequence)."""
    return (counter - previous - 1) % protection.counter_modulo


_CODEBOOK: Any = None

PACKAGES = ("chassis-hil-bench", "python-can", "cantools", "mcap", "zstandard", "msgpack", "numpy", "pytest",
            "pytest-xdist", "matplotlib", "jinja2", "rich")


# -- the machine ---------------------------------------------------------------------------------------------
def cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def load_average() -> list[float]:
    try:
        return [round(x, 2) for x in os.getloadavg()]
    except OSError:
        return []


def source_version() -> str:
    """The repository's commit and whether the tree had changes (figures belong to a version of the code)."""
    import subprocess

    try:
        head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True,
                              timeout=10).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=ROOT,
                               capture_output=True, text=True, timeout=10).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    return f"{head or 'unknown'}{' + uncommitted changes' if dirty else ''}"


def machine() -> dict[str, Any]:
    """What a figure depends on: CPU, cores, Python, packages, kernel, load at the time of measuring."""
    packages = {}
    for name in PACKAGES:
        try:
            packages[name] = version(name)
        except PackageNotFoundError:
            packages[name] = None
    try:
        usable = len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not Linux
        usable = os.cpu_count()
    return {
        "cpu": cpu_model(), "cores": os.cpu_count(), "usable_cores": usable,
        "python": f"{platform.python_implementation()} {platform.python_version()}",
        "os": f"{platform.system()} {platform.release()}", "arch": platform.machine(),
        "packages": packages, "load_average": load_average(),
        "date": time.strftime("%Y-%m-%d %H:%M:%S %z"), "source": source_version(),
    }


def machine_line(m: dict[str, Any]) -> str:
    pk = m["packages"]
    return (f"{m['cpu']}, {m['cores']} cores ({m['usable_cores']} usable), {m['python']}, {m['os']}; "
            f"python-can {pk.get('python-can')}, cantools {pk.get('cantools')}, mcap {pk.get('mcap')}, "
            f"numpy {pk.get('numpy')}, pytest-xdist {pk.get('pytest-xdist')}; code {m.get('source', '?')}; "
            "load average "
            f"{' / '.join(str(x) for x in m['load_average'])} (1/5/15 min)")


# -- figures -------------------------------------------------------------------------------------------------
@dataclass
class Figure:
    """One measured figure, the baseline measured in the same run, and the issue's target (if any)."""

    name: str
    value: float | None
    unit: str
    baseline: float | None = None
    baseline_name: str = ""
    target: float | None = None
    target_op: str = ""          # ">=" or "<=" (value against target)
    note: str = ""

    @property
    def met(self) -> bool | None:
        if self.target is None or self.value is None or not math.isfinite(self.value):
            return None if self.target is None else False
        return self.value >= self.target if self.target_op == ">=" else self.value <= self.target


@dataclass
class Result:
    """What one benchmark hands to run_all: figures, details (tables, per-message data) and how long it took."""

    benchmark: str
    title: str
    figures: list[Figure] = field(default_factory=list)
    details: dict[str, Any] = field(default_factory=dict)
    machine: dict[str, Any] = field(default_factory=machine)
    seconds: float = 0.0
    quick: bool = False
    error: str = ""

    def add(self, *args: Any, **kwargs: Any) -> Figure:
        fig = Figure(*args, **kwargs)
        self.figures.append(fig)
        return fig

    def to_json(self) -> dict[str, Any]:
        out = asdict(self)
        for fig, raw in zip(self.figures, out["figures"]):
            raw["met"] = fig.met
        return _finite(out)


def _finite(obj: Any) -> Any:
    """JSON without NaN/inf (they become null)."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {str(k): _finite(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_finite(v) for v in obj]
    return obj


def fmt(value: float | None, unit: str = "") -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "–"
    a = abs(value)
    if a >= 1000:
        text = f"{value:,.0f}"
    elif a >= 100:
        text = f"{value:.0f}"
    elif a >= 10:
        text = f"{value:.1f}"
    elif a >= 0.1 or a == 0:
        text = f"{value:.2f}"
    else:
        text = f"{value:.3g}"
    return f"{text} {unit}".rstrip()


def verdict(fig: Figure) -> str:
    return {None: "", True: "met", False: "NOT met"}[fig.met]


def print_result(result: Result) -> None:
    print(f"\n== {result.title} ({result.seconds:.0f} s{', quick' if result.quick else ''})")
    if result.error:
        print(f"   ERROR: {result.error}")
    for fig in result.figures:
        target = f"target {fig.target_op} {fmt(fig.target, fig.unit)}" if fig.target is not None else ""
        base = f"baseline {fmt(fig.baseline, fig.unit)} ({fig.baseline_name})" if fig.baseline_name else ""
        print(f"   {fig.name:<52} {fmt(fig.value, fig.unit):>16}   {base}  {target} {verdict(fig)}".rstrip())
        if fig.note:
            print(f"   {'':<52} {fig.note}")


# -- statistics (percentile: the bench's own, bench/checks/steps.py) ---------------------------------------------------
def summary(values: Sequence[float], scale: float = 1.0) -> dict[str, float | int]:
    """n, p50, p99, max (and mean) of values, times scale (e.g. 1000 for ms)."""
    return {"n": len(values), "p50": percentile(values, 50) * scale, "p99": percentile(values, 99) * scale,
            "max": (max(values) if values else math.nan) * scale,
            "mean": (sum(values) / len(values) if values else math.nan) * scale}


# -- processes and time --------------------------------------------------------------------------------------
def cpu_seconds() -> float:
    """CPU time (user + system) of this process and of its children that have been waited for."""
    me, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return me.ru_utime + me.ru_stime + kids.ru_utime + kids.ru_stime


class ProcessCpu:
    """CPU seconds of a process tree by role, sampled from /proc while it runs (a finished process's last sample
    stands: sample often). Roles by command line: the log process, xdist workers, the main process."""

    def __init__(self, root: int) -> None:
        self.root = root
        self.last: dict[int, tuple[str, float]] = {}

    @staticmethod
    def _role(cmd: str, pid: int, root: int) -> str:
        if "bench.log.logproc" in cmd:
            return "log process(es)"
        if pid == root:
            return "bench run (pytest, bus, plant, monitors)"
        if "execnet" in cmd or "xdist" in cmd or "-c" in cmd.split()[:3]:
            return "xdist workers (bus, plant, monitors)"
        return "other children"

    def sample(self) -> None:
        tick = os.sysconf("SC_CLK_TCK")
        for pid in _descendants(self.root):
            try:
                fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
                cmd = Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
            except (OSError, IndexError):
                continue
            cpu = (int(fields[11]) + int(fields[12])) / tick
            self.last[pid] = (self._role(cmd, pid, self.root), cpu)

    def by_role(self) -> dict[str, float]:
        out: dict[str, float] = {}
        for role, cpu in self.last.values():
            out[role] = round(out.get(role, 0.0) + cpu, 2)
        return {role: cpu for role, cpu in out.items() if cpu >= 0.05}


class Proc:
    """A child whose merged output is collected by a thread, so that the script can wait for its ready line."""

    def __init__(self, argv: list[str]) -> None:
        self.process = subprocess.Popen(argv, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        self.lines: list[str] = []
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        assert self.process.stdout is not None
        for line in self.process.stdout:
            self.lines.append(line)

    def wait_for(self, marker: str, seconds: float) -> None:
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline:
            if any(marker in line for line in self.lines):
                return
            if self.process.poll() is not None:
                break
            time.sleep(0.05)
        raise SystemExit(f"no {marker!r} from {self.process.args!r}:\n{''.join(self.lines)}")

    def stop(self) -> None:
        if self.process.poll() is None:
            self.process.send_signal(2)
            try:
                self.process.wait(15)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()


def random_group() -> str:
    """A multicast group of its own (administratively scoped, hop limit 0 keeps it on this host)."""
    rng = random.SystemRandom()
    return f"239.255.{rng.randint(1, 254)}.{rng.randint(1, 254)}"


UDP_MULTICAST_PORT = 43113   # python-can's udp_multicast port, the same for every group


def _udp_inodes(port: int) -> set[str]:
    suffix = f":{port:04X}"
    inodes = set()
    for table in ("/proc/net/udp", "/proc/net/udp6"):
        try:
            lines = Path(table).read_text().splitlines()[1:]
        except OSError:
            continue
        for line in lines:
            fields = line.split()
            if len(fields) > 9 and fields[1].endswith(suffix):
                inodes.add(fields[9])
    return inodes


def _descendants(root: int) -> set[int]:
    children: dict[int, list[int]] = {}
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
            children.setdefault(int(fields[1]), []).append(int(stat.parent.name))
        except (OSError, IndexError, ValueError):
            continue
    out, todo = {root}, [root]
    while todo:
        for child in children.get(todo.pop(), []):
            if child not in out:
                out.add(child)
                todo.append(child)
    return out


def udp_multicast_users(port: int = UDP_MULTICAST_PORT) -> list[str]:
    """Processes other than this one and its descendants with a socket on python-can's udp_multicast port.

    Why it matters: python-can binds every udp_multicast bus to 0.0.0.0:43113, and Linux delivers a group's
    datagrams to every socket so bound whose process joined any group (IP_MULTICAST_ALL is on by default),
    so two runs on different groups of one host received each other's frames until bench.transport.udp turned
    IP_MULTICAST_ALL off. A real-time benchmark still records who else ran meanwhile: they share the CPU."""
    inodes = _udp_inodes(port)
    if not inodes:
        return []
    mine = _descendants(os.getpid())
    users = []
    for fd_dir in Path("/proc").glob("[0-9]*/fd"):
        pid = int(fd_dir.parent.name)
        if pid in mine:
            continue
        try:
            links = {os.readlink(fd) for fd in fd_dir.iterdir()}
        except OSError:
            continue
        if any(link.startswith("socket:[") and link[8:-1] in inodes for link in links):
            try:
                cmd = (fd_dir.parent / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace").strip()
            except OSError:
                cmd = "?"
            users.append(f"{pid} {cmd[:120]}")
    return users


class UdpWatch:
    """Samples, in a thread, which other processes use the udp_multicast port while a benchmark runs."""

    def __init__(self, every: float = 3.0) -> None:
        import threading

        self.seen: dict[str, float] = {}
        self._stop = threading.Event()
        self._every = every
        self._t0 = time.monotonic()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            for user in udp_multicast_users():
                self.seen.setdefault(user, round(time.monotonic() - self._t0, 1))
            self._stop.wait(self._every)

    def stop(self) -> dict[str, float]:
        """{process: seconds into the benchmark it was first seen}."""
        self._stop.set()
        self._thread.join(timeout=10)
        return dict(self.seen)


def udp_users_at_start() -> dict[str, Any]:
    """Who else uses the udp_multicast port as a real-time benchmark starts (see note_udp_users)."""
    return {"other_users_when_started": udp_multicast_users()}


def note_udp_users(result: Result, quiet: dict[str, Any], seen: dict[str, float]) -> None:
    """Record who else used the udp_multicast port during the measurement. Since bench.transport.udp sets
    IP_MULTICAST_ALL = 0 their frames no longer reach our buses (nor ours theirs), but they share the CPU."""
    others = sorted(set(quiet.get("other_users_when_started", [])) | set(seen))
    result.details["other_udp_multicast_users"] = {"wait": quiet, "seen_during_run": seen}
    result.add("other real-time benches on this host during the run", float(len(others)), "processes",
               note="none" if not others else "they share the CPU (not the frames): " + "; ".join(others)[:300])


def isolate_group(bus: Any) -> bool:
    """Make a python-can udp_multicast bus receive only its own group, IPv4 or IPv6 (Linux; bench.transport.udp does it
    for the bench's own buses: IP_MULTICAST_ALL = 0, and IPV6_MULTICAST_ALL = 0 on an IPv6 socket)."""
    import socket

    from bench.transport.udp import IP_MULTICAST_ALL, IPV6_MULTICAST_ALL

    sock = getattr(getattr(bus, "_multicast", None), "_socket", None)
    if sock is None or sock.family not in (socket.AF_INET, socket.AF_INET6):
        return False
    try:
        if sock.family == socket.AF_INET6:
            sock.setsockopt(socket.IPPROTO_IPV6, IPV6_MULTICAST_ALL, 0)
        sock.setsockopt(socket.IPPROTO_IP, IP_MULTICAST_ALL, 0)
    except OSError:
        return False
    return True


def bench_inprocess(argv: list[str]) -> tuple[int, Any, float, float]:
    """Run `bench <argv>` in this process (bench.cli.main); returns (exit code, the run's RunResult from
    bench.pytest.plugin.finished_run(), wall s, CPU s of this process and its waited-for children)."""
    from bench.cli import main
    from bench.pytest.plugin import finished_run

    before = finished_run()
    wall0, cpu0 = time.perf_counter(), cpu_seconds()
    code = main(argv)
    wall, cpu = time.perf_counter() - wall0, cpu_seconds() - cpu0
    result = finished_run()
    return code, (None if result is before else result), wall, cpu


def table_rows(result: Any, title_start: str) -> tuple[list[str], list[list[str]]] | None:
    """Columns and rows of the first table of a RunResult whose title starts with title_start."""
    for table in getattr(result, "tables", []):
        if table.title.startswith(title_start):
            return list(table.columns), [list(r) for r in table.rows]
    return None


# -- command line --------------------------------------------------------------------------------------------
def main(name: str, title: str, measure: Callable[[Result, argparse.Namespace], None],
         configure: Callable[[argparse.ArgumentParser], None] | None = None, doc: str | None = None) -> int:
    """The command line every benchmark shares: --quick, --json PATH; prints the figures."""
    parser = argparse.ArgumentParser(description=doc, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="a short smoke run (figures less reliable)")
    parser.add_argument("--json", type=Path, default=None, help="write the figures as JSON to this file")
    parser.add_argument("--work", type=Path, default=None, help="folder for reports and logs (default: a temp dir)")
    if configure:
        configure(parser)
    args = parser.parse_args()
    if args.work is None:
        import tempfile
        args.work = Path(tempfile.mkdtemp(prefix=f"bench-{name}-"))
    args.work.mkdir(parents=True, exist_ok=True)
    result = Result(name, title, quick=args.quick)
    t0 = time.perf_counter()
    try:
        measure(result, args)
    except Exception as exc:  # noqa: BLE001 - a benchmark that breaks still reports what it has
        import traceback
        traceback.print_exc()
        result.error = f"{type(exc).__name__}: {exc}"
    result.seconds = time.perf_counter() - t0
    result.machine["load_average_end"] = load_average()
    print_result(result)
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(result.to_json(), indent=1, ensure_ascii=False))
    return 1 if result.error else 0

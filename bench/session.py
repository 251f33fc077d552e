"""One bench: the databases, the bus handles, the stations, the clock and the log of a run.

The test runner's station plays the stimulus nodes (bench.toml `stimulus`). Every other node is
simulated by an in-process plant station unless declared external; with every node external
(`--external all`), the plant is another process (`bench plant`) or real ECUs.
"""

from __future__ import annotations

import functools
import itertools
import math
from collections.abc import Callable, Sequence

from bench import canid
from bench.checks.monitor import FrameSink, Monitor
from bench.checks.timing import SelfTiming
from bench.config import ProjectConfig, RunSettings
from bench.database.codec import Codebook, load_codebook
from bench.diag.declaration import Declaration, Did, NodeDiagnostics, load_declaration
from bench.diag.declaration import Protocol as DiagnosticProtocol
from bench.diag.isotp import IsoTpParams
from bench.diag.server import UdsServer
from bench.errors import BenchError, ConfigError, InputProblems, unknown_names
from bench.faults.plan import FaultPlan
from bench.plugins import load_plant, prepare_plant
from bench.sim.clock import Clock, Scheduler, VirtualClock, WallClock
from bench.sim.node import Behaviour
from bench.sim.restbus import Restbus
from bench.sim.station import Station
from bench.transport import in_process, open_bus
from bench.transport.busopts import BusOptions, contract_options

ALL = "all"
_virtual_channels = itertools.count(1)


def resolve_external(codebook: Codebook, stimulus: Sequence[str], external: Sequence[str]) -> set[str]:
    """The external nodes named on the command line, checked against the databases."""
    nodes = codebook.nodes
    names: set[str] = set()
    for item in external:
        names.update(n for n in item.replace(",", " ").split() if n)
    if ALL in names:
        return set(nodes) - set(stimulus)
    unknown = names - set(nodes)
    if unknown:
        raise ConfigError(unknown_names("--external", sorted(unknown), nodes, also=", or 'all'"))
    return names


def simulated_nodes(codebook: Codebook, stimulus: Sequence[str], external: set[str], role: str) -> frozenset[str]:
    """The nodes a process of `role` simulates: the plant's (every node neither stimulus nor external) and, in
    the runner's process (`bench run`), the stimulus nodes, which it sends even when named external."""
    plant = set(codebook.nodes) - set(stimulus) - external
    return frozenset(plant | set(stimulus) if role == "runner" else plant)


def serve_diagnostics(station: Station, node: NodeDiagnostics, protocol: DiagnosticProtocol,
                      now: Callable[[], float], server: type[UdsServer] = UdsServer) -> UdsServer:
    """A simulated node's diagnostic side on the station that plays it: its UDS server, listening to its request and
    the functional identifier, with every DID the bench can serve itself (`_live_value`); the node's behaviour finds
    it with `NodeIO.diagnostics` and feeds the rest."""
    side = server(node, protocol, station.send_now)
    for did in node.dids:
        source = _live_value(station, did, now)
        if source is not None:
            side.provide(did.name, source)
    station.listen(side)
    station.diagnostics[node.node] = side
    return side


def _live_value(station: Station, did: Did, now: Callable[[], float]) -> Callable[[], float] | None:
    """Where a simulated node's DID gets its value when the declaration says (else its behaviour provides it): a
    signal it sends (what its restbus sends), one it reads (its monitor's latest valid value; NaN when timed out:
    the node has no value, NRC 0x22), or the bench's clock (its operating time since power-up, bench time 0)."""
    if did.source == "operating_time":
        return now
    if did.signal:
        message, _, signal = did.signal.partition(".")
        if message in station.restbus.slots:
            return functools.partial(station.restbus.value, message, signal)
    if did.input:
        message, _, signal = did.input.partition(".")
        monitor = station.monitor

        def latest() -> float:
            values = monitor.latest(message, station.t)
            return math.nan if values is None else float(values.get(signal, math.nan))

        return latest
    return None


def resolve_bus_options(project: ProjectConfig, given: BusOptions, codebook: Codebook) -> BusOptions:
    """The bus settings of a run: the command line's over bench.toml's [bus] over the databases' (the contract)."""
    options = given.over(project.bus).over(contract_options(codebook.databases))
    options.check()
    fd = [codec for codec in codebook.by_id.values() if codec.frame_id & canid.FD]
    if fd and not options.fd:
        names = ", ".join(f"{c.name} ({c.database})" for c in fd[:3])
        if len(fd) > 3:
            names += f" and {len(fd) - 3} more"
        raise ConfigError(f"CAN FD messages on a bus opened as classical CAN: {names}; open it with CAN FD "
                          "(fd = true in bench.toml's [bus], or --fd; a DBC says it with BA_ \"BusType\" \"CAN FD\")"
                          + (" (--no-fd was given)" if given.fd is False else ""))
    return options


class BenchSession:
    """Everything one process needs to take part in a bench run."""

    def __init__(self, project: ProjectConfig, settings: RunSettings, *, role: str = "runner",
                 sink: FrameSink | None = None, keep_history: bool = True) -> None:
        self.project = project
        self.settings = settings
        self.codebook = load_codebook(project.databases, project.e2e, project.messages)
        problems = project.problems(self.codebook)
        self.declaration: Declaration | None = None
        if project.diagnostics is not None:
            self.declaration = load_declaration(project.diagnostics)
            problems += self.declaration.problems(self.codebook)
        if problems:
            raise InputProblems(problems)
        self.external = resolve_external(self.codebook, project.stimulus, settings.external)
        self.clock: Clock = VirtualClock() if settings.virtual_time else WallClock()
        channel = settings.channel
        if in_process(settings.interface) and not channel:
            channel = f"bench-{next(_virtual_channels)}"   # sessions in one process never mix
        self.channel = channel
        self.bus_options = resolve_bus_options(project, settings.bus, self.codebook)
        self.stations: list[Station] = []
        self.runner: Station | None = None
        self.plant: Station | None = None
        plant_nodes = set(simulated_nodes(self.codebook, project.stimulus, self.external, "plant"))
        if plant_nodes:
            behaviours: Sequence[Behaviour] = ()   # no plant: each node is its messages' start values (a restbus)
            if project.plant is not None:
                factory = load_plant(project.plant)
                try:
                    behaviours = factory(self.external | set(project.stimulus), settings.vehicle)
                except ValueError as exc:
                    raise ConfigError(f"plant {project.plant!r}: {exc}") from None
            self.plant = self._station("plant", plant_nodes, Monitor(self.codebook, keep_intervals=False), behaviours)
            self.stations.append(self.plant)
        if role in ("runner", "tester"):   # a tester (bench diag) sends only its requests: no stimulus restbus
            monitor = Monitor(self.codebook, keep_history=keep_history, sink=sink)
            nodes = set(project.stimulus) if role == "runner" else set()
            self.runner = self._station("runner", nodes, monitor, (), every_tick=False)
            self.stations.append(self.runner)
        if not self.stations:
            raise ConfigError("nothing to simulate: every node is external")
        if self.declaration is not None:
            self._diagnostics(self.declaration, plant_nodes)
        self.faults = FaultPlan(self.codebook, simulated_nodes(self.codebook, project.stimulus, self.external, role))
        for station in self.stations:
            station.faults = self.faults
        self.stations[-1].babbles = True
        self.scheduler = Scheduler(self.stations, self.clock)
        # Real time: the bench's own timing (bench.checks.timing.SelfTiming): frames it sends stamped when they
        # went out and timed against their schedule, the tick loop's lateness, the receive path's waiting.
        self.self_timing: SelfTiming | None = None
        if self.clock.realtime:
            self.self_timing = self.scheduler.self_timing = SelfTiming()
            for station in self.stations:
                station.self_timing = self.self_timing
                station.send_clock = self.clock.now
                station.recent = self.clock.recent
                station.timing_label = "stimulus" if station is self.runner else "simulated"
            if self.declaration is not None and self.runner is not None:
                # the tester's modules (udsoncan, can-isotp: 0.4 s of import) now, not in the first case that reads
                # a DTC: there the import stalled the tick loop by 29 and 31 ms, in two runs of the campaign
                import bench.diag.tester  # noqa: F401
            if project.plant is not None and self.runner is not None:
                # what the cases ask of the plant (its vehicles' stimulus) imports it: now, not in the first case
                # (with the plant in another process that import stalled the first case's tick loop 0.17-0.29 s)
                prepare_plant(project.plant)

    def _diagnostics(self, declaration: Declaration, plant_nodes: set[str]) -> None:
        """The diagnostic side of every simulated node the declaration describes (its UDS server on the plant's
        station), and the ISO-TP framing check of every node's connection on the runner's monitor."""
        protocol = declaration.protocol
        if self.plant is not None:
            plant = self.plant
            for name, node in declaration.nodes.items():
                if name in plant_nodes:
                    serve_diagnostics(plant, node, protocol, self.now)
        if self.runner is not None:
            params = IsoTpParams(padding=protocol.padding, n_bs=protocol.n_bs, n_cr=protocol.n_cr)
            for node in declaration.nodes.values():
                self.runner.monitor.watch_framing(node.request, node.response, params)

    def _station(self, name: str, nodes: set[str], monitor: Monitor, behaviours: Sequence[Behaviour], *,
                 every_tick: bool = True) -> Station:
        bus = open_bus(self.settings.interface, self.channel, self.bus_options)
        stamp = getattr(self.clock, "stamp", None)   # real time: frames get their receive timestamps
        return Station(name, bus, Restbus(self.codebook, nodes), monitor, self.now, behaviours, stamp,
                       every_tick=every_tick, recent_monotonic=getattr(self.clock, "recent_monotonic", None),
                       frozen_now=not self.clock.realtime)

    def now(self) -> float:
        return self.scheduler.now if not self.clock.realtime else self.clock.now()

    def recent(self) -> float:
        """Bench time of the clock's latest read (real time: at most a tick's work old; no new read, which
        in a UML guest is a costly system call)."""
        return self.scheduler.now if not self.clock.realtime else self.clock.recent()

    @property
    def monitor(self) -> Monitor:
        station = self.runner or self.plant
        assert station is not None
        return station.monitor

    def start(self) -> None:
        self.clock.start()

    def run_until(self, t_end: float, stop: Callable[[], bool] | None = None) -> bool:
        return self.scheduler.run_until(t_end, stop)

    def close(self) -> None:
        for station in self.stations:
            try:
                station.transport.shutdown()
            except Exception as exc:  # a bus that fails to close must not hide the run's result
                raise BenchError(f"closing the {station.name} bus failed: {exc}") from None

"""The bench's diagnostic tester: udsoncan's client on the bench's own ISO-TP, on the bench's clock.

A case (`bench.diag("NODE")`) and `bench diag` get a `udsoncan.client.Client`, the client test engineers already
script, whose connection sends through the runner's station and waits in bench time: while it waits the bench
runs (plant, restbus, monitors), so in virtual time every ISO-TP and UDS timer counts bench time, the exchange is
deterministic and takes no wall time. can-isotp reads the wall clock and runs a thread of its own, which would
make virtual-time runs nondeterministic; the bench's ISO-TP (bench/diag/isotp.py) is tested against it instead.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from typing import Any, Protocol, cast

import udsoncan
from udsoncan.client import Client
from udsoncan.common.DidCodec import DidCodec
from udsoncan.connections import BaseConnection
from udsoncan.exceptions import (
    InvalidResponseException,
    NegativeResponseException,
    TimeoutException,
    UnexpectedResponseException,
)
from udsoncan.Request import Request
from udsoncan.Response import Response
from udsoncan.typing import ClientConfig

from bench import canid
from bench.diag.declaration import Declaration, Did, NodeDiagnostics
from bench.diag.describe import describe
from bench.diag.isotp import IsoTpEndpoint, IsoTpParams
from bench.diag.kernel_isotp import KernelIsoTpEndpoint, kernel_isotp_available
from bench.diag.security import documented_key
from bench.errors import BenchError
from bench.transport.socketcan import SocketcanTransport

#: How much longer than the server's P2 / P2* the tester waits (ISO 14229-2's P2client: the server's limit plus the
#: network's delays both ways).
P2_MARGIN = 0.050
P2_STAR_MARGIN = 0.500
#: Bench time the tester waits for the rest of a multi-frame response once its first frame came (N_Cr per frame).
RESPONSE_LIMIT = 30.0
#: Bench time a request may wait for its final response, responsePending (NRC 0x78) included: the contract's
#: longest routine is 2.5 s, and an ECU that answers 0x78 for ever must not hold the bench.
REQUEST_LIMIT = 60.0


class Bench(Protocol):
    """What the tester needs of a session: its clock and its tick loop."""

    def now(self) -> float: ...

    def run_until(self, t_end: float, stop: Callable[[], bool] | None = None) -> bool: ...


class Station(Protocol):
    """Where the tester's frames go and come from: the runner's station (bench.sim.station.Station)."""

    def listen(self, listener: Any) -> None: ...

    def unlisten(self, listener: Any) -> None: ...

    def send_now(self, frame_id: int, data: bytes) -> None: ...


class DidValue(DidCodec):
    """udsoncan's codec of one declared DID: physical values (and enumeration names) both ways."""

    def __init__(self, did: Did) -> None:
        super().__init__()
        self.did = did

    def encode(self, *did_value: Any) -> bytes:
        return self.did.encode(did_value[0])

    def decode(self, did_payload: bytes) -> Any:
        return self.did.decode(did_payload)

    def __len__(self) -> int:
        return self.did.length


class TesterPort:
    """The tester's ISO-TP endpoint for one node (its physical request and response identifiers), listening on the
    runner's station while a connection uses it. One per node and case: two endpoints on one response identifier
    would both answer a multi-frame response with a flow control. The endpoint is the bench's own ISO-TP, or on
    SocketCAN the kernel's (bench.diag.kernel_isotp), which receives the node's frames itself and is polled every
    tick while open."""

    def __init__(self, station: Station, tx_id: int, rx_id: int, params: IsoTpParams,
                 channel: str | None = None) -> None:
        self.station = station
        self.channel = channel   # the kernel ISO-TP's interface, or None: the bench's own
        self.endpoint: IsoTpEndpoint | KernelIsoTpEndpoint = \
            KernelIsoTpEndpoint(channel, tx_id, rx_id, params) if channel is not None \
            else IsoTpEndpoint(tx_id, rx_id, station.send_now, params)
        self.frame_ids = () if channel is not None else (rx_id,)
        self.users = 0

    @property
    def busy(self) -> bool:
        return self.channel is not None or self.endpoint.busy

    def on_frame(self, t: float, frame_id: int, data: bytes) -> None:
        self.endpoint.on_frame(t, data)

    def poll(self, t: float) -> None:
        self.endpoint.poll(t)

    def acquire(self) -> None:
        if not self.users:
            if isinstance(self.endpoint, KernelIsoTpEndpoint):
                self.endpoint.open()
            self.station.listen(self)
        self.users += 1

    def release(self) -> None:
        self.users -= 1
        if not self.users:
            self.station.unlisten(self)
            if isinstance(self.endpoint, KernelIsoTpEndpoint):
                self.endpoint.close()


class BenchConnection(BaseConnection):
    """A udsoncan connection whose waits run the bench for their time, in bench time. With `functional_id` its
    requests go out on the functional identifier, as single frames; the answers come through the node's port."""

    def __init__(self, bench: Bench, port: TesterPort, name: str, functional_id: int | None = None) -> None:
        super().__init__(name)
        self.bench, self.port, self.functional_id = bench, port, functional_id
        self.endpoint = port.endpoint
        self.opened = False
        #: (bench time, "request" or "response", payload) of every exchange, for the report and the log
        self.exchanges: list[tuple[float, str, bytes]] = []
        self._problems_from = 0   # the endpoint's ISO-TP problems from this index on came after the last request
        self._asked_at = 0.0      # bench time of the last request: no request waits longer than REQUEST_LIMIT
        #: why the last wait ended without a response although frames came ("": nothing came in time)
        self.unanswered = ""

    def open(self) -> BenchConnection:
        if not self.opened:
            self.port.acquire()
            self.opened = True
        return self

    def close(self) -> None:
        if self.opened:
            self.port.release()
            self.opened = False

    def is_open(self) -> bool:
        return self.opened

    def empty_rxqueue(self) -> None:
        self.endpoint.received.clear()

    def specific_send(self, payload: bytes, timeout: float | None = None) -> None:
        t = self.bench.now()
        self.exchanges.append((t, "request", bytes(payload)))
        self.unanswered = ""
        self._asked_at = t
        if self.functional_id is None:
            self.endpoint.transmit(t, bytes(payload))
            self._problems_from = len(self.endpoint.problems)   # (transmit first records an earlier one's timeouts)
            return
        self._problems_from = len(self.endpoint.problems)
        if not 0 < len(payload) <= 7:
            raise BenchError(f"a functional request is one single frame (1 to 7 bytes), not {len(payload)} bytes")
        padding = self.endpoint.params.padding
        frame = bytes([len(payload)]) + bytes(payload)
        self.port.station.send_now(self.functional_id, frame if padding is None else frame.ljust(8, bytes([padding])))

    def specific_wait_frame(self, timeout: float | None = None) -> bytes | None:
        received = self.endpoint.received
        if not received:
            limit = RESPONSE_LIMIT if timeout is None else float(timeout)
            bench, endpoint = self.bench, self.endpoint
            if bench.now() - self._asked_at > REQUEST_LIMIT:   # a node answering responsePending for ever
                self.unanswered = (f"still responsePending (NRC 0x78) {bench.now() - self._asked_at:.1f} s after the "
                                   f"request, over the tester's limit of {REQUEST_LIMIT:g} s")
                raise TimeoutException(self.unanswered)  # type: ignore[no-untyped-call]
            bench.run_until(bench.now() + limit, lambda: bool(received))
            extra = bench.now() + RESPONSE_LIMIT
            while not received and endpoint.busy and bench.now() < extra:
                # the first frame came in time: the rest of a multi-frame response, each frame within N_Cr
                bench.run_until(bench.now() + endpoint.params.n_cr, lambda: bool(received) or not endpoint.busy)
            if not received:
                self.unanswered = self._why_unanswered(endpoint.busy)
                raise TimeoutException(f"no response within {limit:.3f} s of bench time")  # type: ignore[no-untyped-call]
        t, payload = received.popleft()
        self.exchanges.append((t, "response", payload))
        return payload

    def _why_unanswered(self, busy: bool) -> str:
        """The ISO-TP problems of the exchange since the request (a response that began and was dropped: its
        frame and the rule it broke), or a multi-frame message still in progress at RESPONSE_LIMIT; "" when
        nothing of a response came."""
        problems = self.endpoint.problems[self._problems_from:]
        if problems:
            first = problems[0]
            more = f" (and {len(problems) - 1} more ISO-TP problem(s))" if len(problems) > 1 else ""
            return f"ISO-TP {first.rule}: {first.text}{more}"
        if busy:
            return f"a multi-frame message still incomplete after {RESPONSE_LIMIT:g} s of bench time"
        return ""


class DiagnosticError(BenchError):
    """A request the node did not answer as asked: one line naming the node, the request and what came instead.
    Each kind is also udsoncan's own exception, so a case catches it as test engineers do."""


class NoResponse(DiagnosticError, TimeoutException):
    def __init__(self, text: str) -> None:
        Exception.__init__(self, text)


class Refused(DiagnosticError, NegativeResponseException):
    def __init__(self, response: Response, text: str) -> None:
        NegativeResponseException.__init__(self, response)
        self.args = (text,)


class BadResponse(DiagnosticError, InvalidResponseException):
    def __init__(self, response: Response, text: str) -> None:
        InvalidResponseException.__init__(self, response)  # type: ignore[no-untyped-call]
        self.args = (text,)


class BenchClient(Client):
    """udsoncan's client whose failures name the node and the request (bench.diag.tester.DiagnosticError)."""

    node = ""
    response_name = ""
    external = False

    def send_request(self, request: Request, timeout: int = -1) -> Response | None:
        try:
            return super().send_request(request, timeout)
        except (TimeoutException, NegativeResponseException, InvalidResponseException,
                UnexpectedResponseException) as exc:
            if isinstance(exc, DiagnosticError):
                raise
            asked = describe(request.get_payload())
            who = f"{'the external ' if self.external else ''}{self.node}"
            if isinstance(exc, TimeoutException):
                why = self.conn.unanswered if isinstance(self.conn, BenchConnection) else ""
                if why:   # frames came, but no whole response: the frame and the ISO-TP rule it broke
                    raise NoResponse(f"no complete {self.response_name} from {who}: {asked}: {why}") from None
                waited = float(self.config["p2_timeout"] or 0.0)   # (plus P2* after a responsePending)
                raise NoResponse(f"no {self.response_name} from {who} in {waited:.1f} s: {asked}") from None
            response: Response = exc.response
            got = describe(response.get_payload()) if response is not None else "nothing"
            if isinstance(exc, NegativeResponseException):
                raise Refused(response, f"{who} refused {asked}: {got}") from None
            raise BadResponse(response, f"{who} answered {asked} with {got}: {exc}") from None


def did_codecs(node: NodeDiagnostics) -> dict[int, DidCodec]:
    return {did.id: DidValue(did) for did in node.dids}


def key_function(node: NodeDiagnostics, security: dict[str, str], external: bool) -> Callable[..., bytes]:
    """udsoncan's `security_algo` for a node: an external node's "module:function" from bench.toml [diagnostics]
    security (udsoncan's signature: level, seed, params -> key), else the documented algorithm (DIAG-SEC-01)."""
    spec = security.get(node.node) if external else None
    if spec is None:
        constant = node.security_constant

        def documented(level: int, seed: bytes, params: Any = None) -> bytes:
            return documented_key(seed, constant)

        return documented
    module_name, _, function_name = spec.partition(":")
    where = f"bench.toml [diagnostics] security {node.node} = {spec!r}"
    try:
        function = getattr(importlib.import_module(module_name), function_name)
    except Exception as exc:   # any import-time error of the user's module
        raise BenchError(f"{where}: cannot load: {type(exc).__name__}: {exc}") from None
    if not callable(function):
        raise BenchError(f"{where}: not a function")

    def secret(level: int, seed: bytes, params: Any = None) -> bytes:
        try:
            key = function(level, seed, params)
        except Exception as exc:   # the user's algorithm failed: one line naming it, never a traceback
            raise BenchError(f"{where} raised {type(exc).__name__}: {exc} (seed {seed.hex()})") from None
        if not isinstance(key, (bytes, bytearray)):
            raise BenchError(f"{where} returned {type(key).__name__}, not bytes (seed {seed.hex()})")
        return bytes(key)

    return secret


def tester_port(station: Station, declaration: Declaration, node_name: str) -> TesterPort:
    """The tester's ISO-TP endpoint for one node of the declaration (BenchError for a node it does not have)."""
    try:
        node = declaration.node(node_name)
    except KeyError as exc:
        raise BenchError(str(exc.args[0])) from None
    protocol = declaration.protocol
    params = IsoTpParams(padding=protocol.padding, block_size=0, stmin=0.0, n_bs=protocol.n_bs, n_cr=protocol.n_cr)
    return TesterPort(station, node.request, node.response, params, kernel_isotp_channel(station))


def kernel_isotp_channel(station: Station) -> str | None:
    """The SocketCAN interface whose kernel ISO-TP the tester uses (bench.diag.kernel_isotp), or None: another bus,
    a kernel without CAN_ISOTP, or BENCH_KERNEL_ISOTP=0."""
    transport = getattr(station, "transport", None)
    if not isinstance(transport, SocketcanTransport) or not transport.stamped_batches or not kernel_isotp_available():
        return None   # (not stamped_batches: a test's stand-in for a socket, no kernel behind it)
    return transport.channel


def open_client(bench: Bench, port: TesterPort, declaration: Declaration, node_name: str, *,
                functional: bool = False, security: dict[str, str] | None = None,
                external: bool = False, response_name: str = "") -> BenchClient:
    """An opened udsoncan client to one node through its port: physical (or functional) requests, the node's DIDs as
    codecs, its key algorithm, P2/P2* from the declaration plus the tester's margins."""
    node = declaration.node(node_name)
    protocol = declaration.protocol
    connection = BenchConnection(bench, port, node_name, protocol.functional_request if functional else None)
    config: dict[str, Any] = dict(udsoncan.configs.default_client_config)
    config.update({
        "data_identifiers": did_codecs(node),
        "security_algo": key_function(node, security or {}, external),
        "request_timeout": None,      # the per-wait limits below count bench time; udsoncan's would count wall time
        "p2_timeout": protocol.p2 + P2_MARGIN,
        "p2_star_timeout": protocol.p2_star + P2_STAR_MARGIN,
        "use_server_timing": False,   # the declaration is the contract; a server's own figures are judged, not used
        "standard_version": 2013,
        "dtc_snapshot_did_size": 2,
        "extended_data_size": {dtc.number: 1 for dtc in node.dtcs},
    })
    client = BenchClient(connection, config=cast(ClientConfig, config))
    client.node, client.external = node_name, external
    client.response_name = response_name or f"response {canid.text(node.response)}"
    client.open()
    return client

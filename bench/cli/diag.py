"""`bench diag`: a node's diagnostics at the rig: read and clear DTCs, read and write a DID, start a routine.

The same bus options as `bench run`. On the embedded default the bench simulates every node (a try-out of the
declaration); on a real bus name the nodes that are real with --external (`all`: every node but the stimulus).
The requests go out with udsoncan's client on the bench's ISO-TP (bench.diag.tester); writing a DID or starting
a routine first enters the extended session and unlocks security level 1, as a tester at the rig does.
"""

from __future__ import annotations

import argparse
import logging
import math
from pathlib import Path
from typing import Any

from rich.console import Console
from udsoncan.client import Client
from udsoncan.exceptions import (
    InvalidResponseException,
    NegativeResponseException,
    TimeoutException,
    UnexpectedResponseException,
)
from udsoncan.services.ReadDTCInformation import ReadDTCInformation

from bench import canid
from bench.cli.common import add_bus_options, add_node_options, given_bus_options
from bench.config import RunSettings, load_config
from bench.diag.declaration import Did, NodeDiagnostics, dtc_code, dtc_number
from bench.diag.tester import open_client, tester_port
from bench.errors import BenchError, ConfigError
from bench.faults.plan import CASE, CASE_PREFIX, Fault, parse_fault
from bench.session import BenchSession

#: ISO 14229-1 Annex D's status bits, bit 0 first
STATUS_BITS = ("testFailed", "testFailedThisOperationCycle", "pendingDTC", "confirmedDTC",
               "testNotCompletedSinceLastClear", "testFailedSinceLastClear", "testNotCompletedThisOperationCycle",
               "warningIndicatorRequested")
#: bench time the bus runs before the first request (the simulated nodes start up, E2E receivers settle)
SETTLE = 0.2
ACTIONS = ("dtc", "clear", "read", "write", "routine", "snapshot")
#: --fault's help here: bench diag runs no cases, so its windows count from its own start only
FAULT_HELP = ("inject a fault into the frames the bench's simulated nodes send: KIND:TARGET[:PARAM]@START[-END], "
              f"START and END in s from bench diag's start (the bus runs {SETTLE:g} s before the request), e.g. "
              f"drop:SOME_MESSAGE@0-; not {CASE_PREFIX}: bench diag runs no cases and refuses it "
              "(docs/reliability.md)")


def register(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    parser = sub.add_parser("diag", help="read/clear DTCs, read/write DIDs, start routines of a node (UDS)",
                            description="A node's diagnostics over UDS on ISO-TP (docs/contract/diagnostics.md).")
    parser.add_argument("node", help="the node, as the databases name it")
    parser.add_argument("action", choices=ACTIONS,
                        help="dtc: list DTCs by status mask; clear: ClearDiagnosticInformation; read DID...; "
                             "write DID VALUE; routine ID; snapshot DTC")
    parser.add_argument("args", nargs="*", help="DIDs (id like 0xF187 or name), a value, a routine or a DTC")
    parser.add_argument("--mask", default="0xFF", help="status mask of `dtc` (default 0xFF: every DTC with any bit)")
    add_bus_options(parser, "embedded")
    add_node_options(parser, helps={"fault": FAULT_HELP})
    parser.set_defaults(handler=run)


def shown(did: Did, value: Any) -> Any:
    """An enumeration DID's value by its name (the raw number beside it), any other as it is."""
    if did.values and isinstance(value, (int, float)):
        names = [name for name, raw in did.values.items() if raw == value]
        return f"{names[0]} ({value:g})" if names else f"{value:g} (none of {', '.join(did.values)})"
    return value


def status_text(status: int) -> str:
    names = [name for bit, name in enumerate(STATUS_BITS) if status >> bit & 1]
    return f"0x{status:02X} " + (" ".join(names) if names else "(no bit set)")


def _number(text: str, what: str) -> int:
    try:
        return int(text, 0)
    except ValueError:
        raise ConfigError(f"{what} {text!r}: not a number (e.g. 0xF187)") from None


def _did(node: NodeDiagnostics, text: str) -> int:
    key: int | str = _number(text, "DID") if text[:1].isdigit() else text
    try:
        return node.did(key).id
    except KeyError as exc:
        raise ConfigError(str(exc.args[0])) from None


def run(args: argparse.Namespace) -> int:
    console = Console(soft_wrap=True, highlight=False)
    project = load_config(Path(args.config) if args.config else None)
    if project.diagnostics is None:
        raise ConfigError(f"{project.path}: no [diagnostics] file: the bench knows no node's diagnostics")
    faults = _faults(args.fault)
    mask = _number(args.mask, "--mask")
    if not 0 <= mask <= 0xFF:
        raise ConfigError(f"--mask {args.mask!r}: a status mask is one byte, 0x00 to 0xFF")
    settings = RunSettings(interface=args.interface, channel=args.channel, external=args.external,
                           bus=given_bus_options(args))
    session = BenchSession(project, settings, role="tester")
    declaration = session.declaration
    assert declaration is not None and session.runner is not None
    try:
        node = declaration.node(args.node)
    except KeyError as exc:
        session.close()
        raise ConfigError(str(exc.args[0])) from None
    try:
        session.faults.extend(faults)   # one line for a fault on frames this process does not send
        _check_arguments(args, node)
        session.start()
        session.run_until(session.now() + SETTLE)
        port = tester_port(session.runner, declaration, node.node)
        client = open_client(session, port, declaration, node.node, security=project.security,
                             external=node.node in session.external)
        if not client.logger.handlers:
            # udsoncan logs every failed request at ERROR; with no handler configured Python's last resort printed
            # it on stderr as a second line beside the error line below
            client.logger.addHandler(logging.NullHandler())
        try:
            _act(console, client, node, args, mask)
        except TimeoutException as exc:
            raise BenchError(f"{node.node} (request {canid.text(node.request)}, response "
                             f"{canid.text(node.response)}) did not "
                             f"answer: {exc}") from None
        except NegativeResponseException as exc:
            code = exc.response.code
            raise BenchError(f"{node.node} refused: {exc.response.code_name} (NRC 0x{code:02X})") from None
        except (InvalidResponseException, UnexpectedResponseException) as exc:
            raise BenchError(f"{node.node} answered a malformed or unexpected response: {exc}") from None
        finally:
            client.close()
    finally:
        session.close()
    return 0


def _faults(specs: list[str]) -> list[Fault]:
    """The --fault specs; a case+ window is refused (bench diag runs no cases: it would never act)."""
    faults = [parse_fault(spec) for spec in specs]
    for spec, fault in zip(specs, faults, strict=True):
        if fault.relative == CASE:
            raise ConfigError(f"--fault {spec!r}: {CASE_PREFIX} counts from each case's start; bench diag runs no "
                              f"cases, so the fault would never act: give the window in s from its start")
    return faults


def _check_arguments(args: argparse.Namespace, node: NodeDiagnostics) -> None:
    wanted = {"dtc": (0, 0), "clear": (0, 1), "read": (1, 99), "write": (2, 2), "routine": (1, 1),
              "snapshot": (1, 1)}[args.action]
    if not wanted[0] <= len(args.args) <= wanted[1]:
        raise ConfigError(f"bench diag {node.node} {args.action}: {len(args.args)} argument(s), expected "
                          f"{wanted[0]}" + (f" to {wanted[1]}" if wanted[1] != wanted[0] else ""))
    if args.action in ("read", "write"):
        for text in args.args[:1 if args.action == "write" else None]:
            _did(node, text)
    if args.action == "write":
        did = node.did(_did(node, args.args[0]))
        try:
            did.encode(_written(did, args.args[1]))
        except ValueError as exc:
            raise ConfigError(str(exc)) from None
    if args.action == "routine":
        key: int | str = _number(args.args[0], "routine") if args.args[0][:1].isdigit() else args.args[0]
        try:
            node.routine(key)
        except KeyError as exc:
            raise ConfigError(str(exc.args[0])) from None
    if args.action == "snapshot":
        _dtc(node, args.args[0])


def _dtc(node: NodeDiagnostics, text: str) -> int:
    try:
        return node.dtc(text).number
    except KeyError:
        pass
    try:
        number = dtc_number(text) if "-" in text else _number(text, "DTC")
        return node.dtc(number).number
    except (KeyError, ValueError) as exc:
        raise ConfigError(str(exc.args[0])) from None


def _written(did: Did, text: str) -> float | str:
    """The value to write: text, an enumeration's name, or a number (an enumeration's: an integer, its raw
    value; the node judges whether it is one of `values`)."""
    if did.type == "ascii" or text in did.values:
        return text
    try:
        value = float(text)
    except ValueError:
        raise ConfigError(f"{did.name}: {text!r} is not a number"
                          + (f" or one of {', '.join(did.values)}" if did.values else "")) from None
    if did.values and not (math.isfinite(value) and value == int(value)):
        raise ConfigError(f"{did.name}: {text!r} is none of {', '.join(did.values)} and not an integer (a raw value)")
    return value


def _unlock(client: Client) -> None:
    client.change_session(3)
    client.unlock_security_access(1)


def _act(console: Console, client: Client, node: NodeDiagnostics, args: argparse.Namespace, mask: int) -> None:
    action = args.action
    if action == "dtc":
        response = client.read_dtc_information(ReadDTCInformation.Subfunction.reportDTCByStatusMask, status_mask=mask)
        assert response is not None and response.service_data is not None
        dtcs = response.service_data.dtcs
        console.print(f"{node.node}: {len(dtcs)} DTC(s) with status & 0x{mask:02X}")
        for dtc in dtcs:
            try:
                known = node.dtc(dtc.id)
                name = f"{known.name}: {known.text}"
            except KeyError:
                name = "(not in the declaration)"
            status = status_text(dtc.status.get_byte_as_int())
            console.print(f"  {dtc_code(dtc.id)} 0x{dtc.id:06X} {name}  status {status}")
    elif action == "clear":
        group = _dtc(node, args.args[0]) if args.args else 0xFFFFFF
        client.clear_dtc(group)
        console.print(f"{node.node}: cleared DTC group 0x{group:06X}")
    elif action == "read":
        for text in args.args:
            did = node.did(_did(node, text))
            value: Any = shown(did, client.read_data_by_identifier_first(did.id))
            console.print(f"{node.node}: 0x{did.id:04X} {did.name} = {value}{' ' + did.unit if did.unit else ''}")
    elif action == "write":
        did = node.did(_did(node, args.args[0]))
        text = args.args[1]
        written = _written(did, text)
        _unlock(client)
        client.write_data_by_identifier(did.id, written)
        console.print(f"{node.node}: wrote 0x{did.id:04X} {did.name} = {text}")
    elif action == "routine":
        key: int | str = _number(args.args[0], "routine") if args.args[0][:1].isdigit() else args.args[0]
        routine = node.routine(key)
        _unlock(client)
        client.start_routine(routine.id)
        console.print(f"{node.node}: routine 0x{routine.id:04X} {routine.name} done")
    elif action == "snapshot":
        number = _dtc(node, args.args[0])
        response = client.get_dtc_snapshot_by_dtc_number(number, record_number=0xFF)
        assert response is not None and response.service_data is not None
        for dtc in response.service_data.dtcs:
            console.print(f"{node.node}: {dtc_code(dtc.id)} status {status_text(dtc.status.get_byte_as_int())}")
            for snapshot in dtc.snapshots:
                did = node.did(snapshot.did)
                console.print(f"  record 0x{snapshot.record_number:02X} 0x{did.id:04X} {did.name} = "
                              f"{shown(did, snapshot.data)}"
                              f"{' ' + did.unit if did.unit else ''}")

"""Coding a node as a tester at the rig does (docs/contract/diagnostics.md DIAG-COD-01): the extended session,
SecurityAccess level 1, WriteDataByIdentifier of each coding DID, back to the default session.

The coding outlives the case (it is non-volatile), so every case that depends on one writes it at its start. A node
under test that refuses a value with requestOutOfRange does not implement the function the value selects (e.g. the
SBW's yaw-rate feedback, optional for a real SBW: docs/contract/sbw.md SBW-CTL-05): the case is skipped, naming it.
"""

from __future__ import annotations

import pytest
from udsoncan.exceptions import NegativeResponseException

from bench.case import Case

EXTENDED, DEFAULT = 0x03, 0x01
REQUEST_OUT_OF_RANGE = 0x31


def code(bench: Case, node: str, otherwise: dict[str, float | str] | None = None, **values: float | str) -> None:
    """Write `values` (coding DID name -> physical value or enumeration name) into `node`. When the node under test
    refuses one (NRC 0x31) and `otherwise` is given, write those instead (a case that also judges a node without the
    optional function), else skip the case."""
    declared = bench.diagnostics(node)
    client = bench.diag(node)
    client.change_session(EXTENDED)
    client.unlock_security_access(1)
    for name, value in values.items():
        did = declared.did(name)
        try:
            client.write_data_by_identifier(did.id, value)
        except NegativeResponseException as exc:
            if exc.response.code == REQUEST_OUT_OF_RANGE and node in bench.external:
                if otherwise is not None:
                    bench.note(f"{node} refuses the coding {name} = {value} (NRC 0x31, an optional function it "
                               f"does not have): coded {otherwise} instead")
                    client.change_session(DEFAULT)
                    code(bench, node, **otherwise)
                    return
                pytest.skip(f"{node} refuses the coding {name} = {value} (NRC 0x31): it does not implement the "
                            f"function this case judges")
            raise
    client.change_session(DEFAULT)

"""The example ECUs of examples/ (a VCU, an SBW and an ABS written from README, docs/ and the DBCs alone), each
judged as the real ECU would be (tests/external_ecu.py says what a passing example shows): `bench plant
--external NODE` simulates everything else (the SBW and the ABS reach the car through the bench I/O,
docs/contract/plant.md "Bench I/O"), and `bench run --external all --dut NODE` runs every case that judges NODE.
The VCU's own unit tests (its kinematics against the rigid-body definition) are in test_example_vcu.py."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.external_ecu import judge_example, third_party_imports
from tests.repo import ROOT

#: node -> cases that must run: every case of the node but its reference-only ones (docs/contract/README.md:
#: the VCU's 4WIS and 4WS cases at speed and fault cases; SBW 4 of 11 reference-only; ABS none of 13)
EXAMPLES = {"VCU": 110, "SBW": 7, "ABS": 13}


def _example(node: str) -> Path:
    return ROOT / "examples" / f"{node.lower()}_ecu.py"


@pytest.mark.realtime
@pytest.mark.parametrize("node", list(EXAMPLES))
def test_campaign_passes_against_the_example(node: str, tmp_path: Path) -> None:
    judge_example(_example(node), node, tmp_path, min_ran=EXAMPLES[node])


@pytest.mark.parametrize("node", list(EXAMPLES))
def test_example_needs_nothing_of_the_bench(node: str) -> None:
    """What a supplier writes from the documents: python-can, cantools, autosar-e2e (`e2e`), can-isotp (`isotp`)
    for its diagnostics in the examples' one shared module (`uds_server`) and the standard library, nothing of
    bench or plant."""
    assert third_party_imports(_example(node)) == {"can", "cantools", "e2e", "uds_server"}
    assert third_party_imports(_example(node).with_name("uds_server.py")) == {"can", "isotp"}

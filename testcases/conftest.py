"""Every case carries the campaign of its package (`CAMPAIGN` in testcases/<campaign>/__init__.py) as
`@pytest.mark.campaign(name=...)`, so that `pytest -m "campaign(name='4WIS')"` selects a campaign without a list of
cases; `bench run testcases/ev4wis` selects the same cases by path. tests/integration/test_campaigns.py checks that
every case has exactly one campaign."""

from __future__ import annotations

import sys

import pytest


def pytest_itemcollected(item: pytest.Item) -> None:
    """Marks the case while it is collected, before -m and --bench-dut deselect."""
    module = getattr(item, "module", None)
    package = sys.modules.get(module.__package__ or "") if module is not None else None
    campaign = getattr(package, "CAMPAIGN", None)
    if isinstance(campaign, str):
        item.add_marker(pytest.mark.campaign(name=campaign))
